"""The raster-order neighbour prior: a left (feedback) column and an above (loaded) column.

The prior of pixel (y, x) is ``pi(d) = prod_n f(|d - d_n|)`` over its left (y, x-1) and above (y-1, x)
neighbours' MAPs d_n, ``f(k) = prior_eps + (1-prior_eps) exp(-k^2 / (2 prior_s^2))`` (a table indexed by
the cost k = |d - d_n| = 0..Dmax), a factor 1 for a neighbour called no match, timed out or outside the
output region; the no-match row gets ``prior_nomatch`` per matched neighbour. Each neighbour's factor is
a column of its own, so the AND gates multiply the two words exactly: the left factor is formed by the
machine from its own previous result (:class:`LeftPrior`, source FEEDBACK: its table clamped where it
stops changing is the machine's ``feedback_words``), the above factor is loaded (:class:`AbovePrior`,
source ABOVE: :meth:`AbovePrior.loaded` of the previous map row's results).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesmachine.errors import ParameterError

from .base import (
    Column,
    Option,
    PassContext,
    Source,
    Table,
    check_probability,
    check_sigma,
    check_switch,
    likelihood_formula,
)

__all__ = ["NEIGHBOUR_PRIOR", "NeighbourPrior", "LeftPrior", "AbovePrior", "neighbour_words"]


def _probability(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_probability(name, value)


def _sigma(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_sigma(name, value)


def _nomatch(name: str, value: object, values: Mapping[str, Any]) -> None:
    # With both neighbours matched and every disparity's likelihood ~0, a no-match prior of 0 would
    # leave the pixel 0/0.
    check_probability(name, value, positive="it keeps every pixel's posterior defined")


def _f_at_s(values: Mapping[str, Any]) -> float:
    """The prior's value at one s, ``f(s) = eps + (1-eps) exp(-1/2)`` (0.626 at eps 0.05)."""
    return float(likelihood_formula(np.int64(1), 1, values["prior_eps"], 1.0))


# The switch of a model whose prior columns can be left out (census: --no-neighbour-prior; a model's
# switch, ModelDef.switches).
NEIGHBOUR_PRIOR = Option("neighbour_prior", "bool", True, check_switch,
                         "the raster-order neighbour prior: a feedback column (the left neighbour's factor) "
                         "and a loaded column (the above neighbour's)")


class NeighbourPrior(Column):
    """What the left and the above columns share: ``f(k)`` by k = |d - d_n| and the no-match factor."""

    table_parameter = "prior_s"
    options = (
        Option("prior_eps", "float", 0.05, _probability,
               "neighbour prior floor eps of f(k) = eps + (1 - eps) exp(-k^2 / (2 s^2)), "
               "k = |d - d_neighbour|"),
        Option("prior_s", "float", 4.0, _sigma, "neighbour prior width s"),
        Option("prior_nomatch", "float", None, _nomatch, "the no-match row's prior per matched neighbour",
               resolve=_f_at_s, default_text="f(s), 0.626"),
    )

    @property
    def nomatch_factor(self) -> float:
        return float(self.values["prior_nomatch"])

    def costs(self) -> np.ndarray:
        return np.arange(self.dmax + 1)

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        return likelihood_formula(cost, 1, float(self.values["prior_eps"]), float(self.values["prior_s"]))

    def nomatch_values(self) -> tuple[float, ...]:
        return (self.nomatch_factor,)

    def check_machine(self, machine: Any) -> None:
        self._nonzero_word("prior_nomatch", self.nomatch_factor, machine,
                           "the no-match row could never win next to a matched neighbour")


class LeftPrior(NeighbourPrior):
    """The left neighbour's factor: the machine's feedback column (operator column 0)."""

    name = "left-prior"
    source = Source.FEEDBACK

    def feedback(self, word_bits: int) -> tuple[tuple[int, ...], int]:
        """The machine's (``feedback_words``, ``feedback_nomatch_word``): the W-bit table clamped where it
        stops changing, and the no-match factor's word."""
        t = self.table(word_bits)
        return tuple(int(v) for v in t.values[: t.last_change() + 1]), int(t.nomatch[0])

    def feedback_codes(self) -> tuple[tuple[int, ...], int]:
        """The logarithmic machine's feedback table: the table's codes (``log_codes``, those of
        :meth:`energy`) clamped where they stop changing, and the no-match factor's code."""
        from .energy import log_codes

        t = self.table()
        codes = log_codes(t.values)
        changes = np.flatnonzero(codes[1:] != codes[:-1])
        last = int(changes[-1]) + 1 if changes.size else 0
        return tuple(int(c) for c in codes[: last + 1]), int(log_codes(t.nomatch[0]))

    def feedback_of(self, machine: Any) -> tuple[tuple[int, ...], int]:
        """``machine``'s feedback table in its integrator's domain (``IntegratorKind.feedback_table``):
        :meth:`feedback` (words) or :meth:`feedback_codes` (``integrator="log"``)."""
        return machine.kind.feedback_table(self, machine)

    def check_machine(self, machine: Any) -> None:
        super().check_machine(machine)
        words, nm = self.feedback_of(machine)
        if machine.feedback_words != words or machine.feedback_nomatch_word != nm:
            raise ParameterError(
                f"neighbour_prior: the machine's feedback table {machine.feedback_words} / "
                f"{machine.feedback_nomatch_word} is not the model's {machine.word_bits}-bit prior table "
                f"{words} / {nm}: build the machine with disparity_machine(model)", "neighbour_prior")


def neighbour_words(table: Table, dmax: int, hat: np.ndarray) -> np.ndarray:
    """One neighbour's factor (P, Dmax+2) of P pixels from that neighbour's MAPs ``hat`` (P,), in
    ``table``'s domain: -1 (no match, a timeout, outside the output region) gives 1 in every row; a MAP
    gives ``table[|d - hat|]`` in row d and the no-match factor in the no-match row."""
    hat = np.asarray(hat)
    if hat.ndim != 1 or hat.dtype.kind not in "iu":
        raise ValueError(f"neighbour MAPs must be a 1-D integer array, got {hat.dtype} {hat.shape}")
    if hat.size and hat.max() > dmax:
        raise ValueError(f"neighbour MAPs must be -1 (none) or disparities 0..{dmax}, got {int(hat.max())}")
    dtype = np.float64 if table.word_bits is None else np.uint16
    f = np.full((hat.shape[0], dmax + 2), table.one, dtype=dtype)
    matched = hat >= 0
    d = np.arange(dmax + 1)
    f[matched, : dmax + 1] = table.values[np.abs(d[None, :] - hat[matched, None].astype(np.int64))]
    f[matched, dmax + 1] = table.nomatch[0]
    return f


class AbovePrior(NeighbourPrior):
    """The above neighbour's factor: a loaded column (the machine's operator column 1)."""

    name = "above-prior"
    source = Source.ABOVE

    def loaded(self, table: Table, above: np.ndarray) -> np.ndarray:
        """The words (or float64 factors) of P pixels from the MAPs ``above`` (P,) of the pixels above."""
        return neighbour_words(table, self.dmax, above)

    def words(self, ctx: PassContext) -> np.ndarray:
        """From the pass's own MAPs of the map row above (``ctx.above``)."""
        return self.loaded(self.table(ctx.word_bits), ctx.above_row(self.name))
