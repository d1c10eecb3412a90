"""How often rows tie in the MAP encoder, and what the tie rule changes (model with ideal random numbers)."""

from __future__ import annotations

import numpy as np

from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.results import check_words

__all__ = ["measure_ties"]


class _RecordedNumbers:
    """Ideal random numbers drawn on demand, kept so other machines can be run on the same ones."""

    def __init__(self, params: MachineParams, rng: np.random.Generator) -> None:
        self.operators = params.operators
        self._top = 1 << params.word_bits
        self._rng = rng
        self.rows: list[np.ndarray] = []

    def take(self, count: int) -> np.ndarray:
        block = self._rng.integers(0, self._top, size=(count, self.operators), dtype=np.uint16)
        self.rows.append(block)
        return block


def measure_ties(
    params: MachineParams, words: np.ndarray, rng: np.random.Generator, *, chunk: int = 100
) -> dict[str, float]:
    """How often several rows overflow in the same cycle, and what the tie rule changes.

    Runs the model with ideal random numbers (``rng = "external"``) three ways on the same
    numbers: lowest-index, nomatch-first, and lowest-index on the row-reversed machine (which
    picks the *highest* overflowing row). A tie is a pixel where lowest and highest differ; a
    no-match tie is one where the two rules differ (the no-match row overflowed together with a
    lower row). Returns counts and fractions over the pixels.
    """
    base = dict(params.to_dict(), rng="external")
    rows, cols = params.rows, params.operator_columns
    low = MachineModel(MachineParams(**{**base, "tie_break": "lowest-index"}))
    nmf = MachineModel(MachineParams(**{**base, "tie_break": "nomatch-first"}))
    rev = MachineModel(MachineParams(**{**base, "tie_break": "lowest-index", "nomatch_row": False}))
    q = check_words(params, words).reshape(-1, rows, cols)
    ties = nm_ties = nomatch_low = nomatch_nmf = timeouts = 0
    for start in range(0, len(q), chunk):
        part = q[start : start + chunk]
        source = _RecordedNumbers(params, rng)  # a fresh stream per chunk: numbers drawn as needed
        r_low = low.run(part, source)
        used = int(r_low.cycles.sum())
        numbers = np.concatenate(source.rows)[:used]
        r_nmf = nmf.run(part, numbers)
        rev_numbers = numbers.reshape(used, rows, cols)[:, ::-1, :].reshape(used, -1)
        r_rev = rev.run(part[:, ::-1, :], rev_numbers)
        ok = ~r_low.timeout
        highest = rows - 1 - r_rev.map
        ties += int((ok & (highest != r_low.map)).sum())
        nm_ties += int((ok & (r_nmf.map != r_low.map)).sum())
        nomatch_low += int(r_low.nomatch.sum())
        nomatch_nmf += int(r_nmf.nomatch.sum())
        timeouts += int(r_low.timeout.sum())
    n = len(q)
    return {
        "pixels": n,
        "ties": ties,
        "tie_fraction": ties / n,
        "nomatch_ties": nm_ties,
        "nomatch_tie_fraction": nm_ties / n,
        "nomatch_lowest_index": nomatch_low,
        "nomatch_nomatch_first": nomatch_nmf,
        "timeouts": timeouts,
    }
