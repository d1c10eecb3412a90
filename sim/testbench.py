"""Testbench helpers: stream handshakes, packing of load beats and results, synthetic pixels.

The stream helpers follow the ``amaranth.lib.stream`` testbench idiom (as in Glasgow):
``await stream_put(ctx, dut.load, beat)`` / ``payload = await stream_get(ctx, dut.result)``.
Packing works on the raw bits of the ports (Python ints), which is much faster in the
simulator than going through the layouts field by field.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from amaranth.lib import stream
from amaranth.sim import SimulatorContext

from bayesmachine.params import MachineParams

__all__ = [
    "measure_ties",
    "pack_beats",
    "pack_numbers",
    "stream_get",
    "stream_put",
    "synthetic_disparity_words",
    "unpack_result",
]


async def stream_put(ctx: SimulatorContext, stream_: stream.Interface, payload: object) -> None:
    """Hold ``valid`` with ``payload`` until the sink takes it (one handshake)."""
    ctx.set(stream_.valid, 1)
    ctx.set(stream_.payload, payload)
    await ctx.tick().until(stream_.ready)
    ctx.set(stream_.valid, 0)


async def stream_get(ctx: SimulatorContext, stream_: stream.Interface) -> object:
    """Hold ``ready`` until the source offers a payload; returns it (one handshake)."""
    ctx.set(stream_.ready, 1)
    (payload,) = await ctx.tick().sample(stream_.payload).until(stream_.valid)
    ctx.set(stream_.ready, 0)
    return payload


def pack_beats(params: MachineParams, words: np.ndarray) -> list[int]:
    """One pixel's ``words_per_pixel`` words (operator order) as raw load-stream beats.

    Word o goes to lane ``o % lanes`` of beat ``o // lanes``; unused lanes of the last beat are 0.
    """
    flat = [int(x) for x in np.asarray(words).reshape(-1)]
    if len(flat) != params.words_per_pixel:
        raise ValueError(f"a pixel has {params.words_per_pixel} words, got {len(flat)}")
    ww = params.memory_word_width
    beats = []
    for b in range(params.beats_per_pixel):
        raw = 0
        for lane, word in enumerate(flat[b * params.lanes : (b + 1) * params.lanes]):
            raw |= word << (lane * ww)
        beats.append(raw)
    return beats


def pack_numbers(params: MachineParams, numbers: Sequence[int]) -> int:
    """One compute cycle's random numbers (one per operator) as the raw ``entropy`` port value."""
    raw = 0
    w = params.word_bits
    for o, n in enumerate(numbers):
        raw |= int(n) << (o * w)
    return raw


def unpack_result(params: MachineParams, raw: int) -> tuple[int, int, int, int, list[int]]:
    """A raw ``result`` payload as ``(map, nomatch, timeout, cycles, counts)`` (field order of
    :func:`bayesmachine.hdl.machine.result_layout`)."""
    pos = 0

    def take(width: int) -> int:
        nonlocal pos
        v = (raw >> pos) & ((1 << width) - 1)
        pos += width
        return v

    map_ = take(params.map_width)
    nomatch = take(1)
    timeout = take(1)
    cycles = take(params.cycle_width)
    counts = [take(params.counter_width) for _ in range(params.rows)]
    return map_, nomatch, timeout, cycles, counts


def synthetic_disparity_words(
    params: MachineParams,
    pixels: int,
    rng: np.random.Generator,
    *,
    p0: float = 0.02,
    p_nm0: float = 0.01,
    sigma: float = 10.0,
    sigma_nm: float = 8.0,
    occluded: float = 0.1,
) -> np.ndarray:
    """Likelihood memories shaped like the paper's (eqs. 2 and 6), without images.

    Per pixel a true disparity; each feature's matching cost is small at the true disparity
    (and by chance elsewhere), ``p = p0 + (1 - p0) exp(-delta^2 / (2 sigma^2))``; a fraction
    ``occluded`` of the pixels has no match (costs high everywhere). The no-match row holds
    ``[P(nomatch), 1, ...]`` with ``P(nomatch) = p_nm0 + (1 - p_nm0) exp(-g^2 / (2 sigma_nm^2))``
    for a random vertical gradient g. For a machine without a no-match row every row is a
    hypothesis. With a loaded prior, column 0 is a uniform prior word (1.0). Returns
    (pixels, rows, operator_columns) int32 words.
    """
    rows, cols, one = params.rows, params.columns, params.word_one
    hyps = rows - 1 if params.nomatch_row else rows
    lik = np.empty((pixels, rows, cols))
    for i in range(pixels):
        # Feature differences: wide for wrong disparities, narrow at the true one.
        delta = rng.normal(0.0, 40.0, size=(hyps, cols))
        if rng.random() >= occluded:
            d = rng.integers(hyps)
            delta[d] = rng.normal(0.0, 4.0, size=cols)
        lik[i, :hyps] = p0 + (1 - p0) * np.exp(-(delta**2) / (2 * sigma**2))
        if params.nomatch_row:
            g = rng.normal(0.0, 30.0)
            lik[i, hyps] = 1.0
            lik[i, hyps, 0] = p_nm0 + (1 - p_nm0) * np.exp(-(g**2) / (2 * sigma_nm**2))
    words = np.clip(np.rint(lik * one), 0, one).astype(np.int32)
    if params.prior == "loaded":
        words = np.concatenate([np.full((pixels, rows, 1), one, np.int32), words], axis=2)
    return words


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
    from bayesmachine.sim.model import MachineModel, check_words

    base = dict(params.to_dict(), rng="external")
    rows, cols = params.rows, params.operator_columns
    low = MachineModel(MachineParams(**{**base, "tie_break": "lowest-index"}))
    nmf = MachineModel(MachineParams(**{**base, "tie_break": "nomatch-first"}))
    rev = MachineModel(MachineParams(**{**base, "tie_break": "lowest-index", "nomatch_row": False}))
    q = check_words(params, words).reshape(-1, rows, cols)
    ties = nm_ties = nomatch_low = nomatch_nmf = timeouts = 0
    for start in range(0, len(q), chunk):
        part = q[start : start + chunk]
        numbers = np.zeros((0, params.operators), np.int32)
        while True:
            # Too few numbers: append more and rerun (the consumed prefix, hence the result, of a
            # run that fits is the same, so this does not bias towards short runs).
            more = max(len(numbers), 300 * len(part))
            fresh = rng.integers(0, 1 << params.word_bits, size=(more, params.operators), dtype=np.int32)
            numbers = np.concatenate([numbers, fresh])
            try:
                r_low = low.run(part, numbers)
                break
            except ValueError:
                continue
        used = int(r_low.cycles.sum())
        numbers = numbers[:used]
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
