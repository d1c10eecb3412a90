"""The left-right consistency column, fed by another pass's MAPs (census-lr).

A right pass (the census model with the right image as reference: lane d pairs right map column
x_r with left map column x_r + d) gives the right MAPs d_R. Row d of left map column x gets 1 when
lane d is consistent, ``|d_R(x - d) - d| <= lr_tolerance``, and ``lr_beta`` otherwise (its cost is 0 or
1, its table [1, beta]); with ``lr_neutral`` a lane whose right pixel x - d has no right MAP (the right
pass's no match or its watchdog) is neutral: factor 1, no information either way; x - d outside the
right pass's columns gets beta. The no-match row gets ``lr_gamma`` when any lane is consistent (a
neutral lane does not count), 1 when none is, and 0 with ``lr_nomatch`` off (no no-match row at all).

Where its words come from is a parameter of its kind: :func:`consistency` makes the kind reading the
MAPs of the pass of a given name (census-lr's ``consistency("right")``), as :func:`~.fused.fused` makes a
fused kind of its members. What the pass itself is (its model, its no-match row, its watchdog) is the
model's :class:`~bayesmachine.modeldef.PassDef`'s, not the column's. :func:`lr_consistent`,
:func:`lr_unknown` and :meth:`Consistency.loaded` are the one definition the host, the references and
the runs read.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .base import Column, Option, PassContext, Source, Table, check_int, check_probability, check_switch

__all__ = ["Consistency", "consistency", "lr_consistent", "lr_unknown", "right_lanes_valid"]


def _factor(name: str, value: object, values: Mapping[str, Any]) -> None:
    # beta 0 with no consistent lane (and no no-match row) would leave a pixel 0/0.
    check_probability(name, value, positive="it keeps every pixel's posterior defined")


def _tolerance(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_int(name, value, 0, 4094)


def _maps(right_map: np.ndarray) -> np.ndarray:
    hat = np.asarray(right_map)
    if hat.dtype.kind not in "iu":
        raise ValueError(f"right MAPs must be integers (-1: none), got {hat.dtype}")
    return hat


def _lanes(right_map: np.ndarray, right_first: int, columns: np.ndarray, dmax: int):
    """(inside, right MAP) of lane d of left map column ``columns[i]``: its right pixel x - d."""
    hat = _maps(right_map)
    cols = np.asarray(columns, dtype=np.int64)
    j = cols[:, None] - np.arange(dmax + 1)[None, :] - int(right_first)  # (Wo, Dmax+1) into right_map
    inside = (j >= 0) & (j < hat.shape[-1])
    return inside, hat[..., np.clip(j, 0, max(0, hat.shape[-1] - 1))].astype(np.int64)


def lr_consistent(right_map: np.ndarray, right_first: int, columns: np.ndarray, dmax: int,
                  tolerance: int) -> np.ndarray:
    """The left-right test: (..., Wo, Dmax+1) bool, lane d of left map column ``columns[i]`` consistent.

    ``right_map`` (..., Wr): the right pass's MAPs of right map columns ``right_first ..``, -1 for none
    (no MAP, a timeout). Lane d is consistent when ``|d_R(x - d) - d| <= tolerance``; a column
    x - d outside ``right_map``'s columns or without a MAP is not.
    """
    inside, got = _lanes(right_map, right_first, columns, dmax)
    return inside & (got >= 0) & (np.abs(got - np.arange(dmax + 1)) <= tolerance)


def lr_unknown(right_map: np.ndarray, right_first: int, columns: np.ndarray, dmax: int) -> np.ndarray:
    """(..., Wo, Dmax+1) bool: lane d of left map column ``columns[i]`` reads a right pixel x - d inside
    ``right_map``'s columns that has no right MAP (-1: the right pass's no match or a timeout); a lane
    whose x - d lies outside the right columns is not unknown (it stays inconsistent)."""
    inside, got = _lanes(right_map, right_first, columns, dmax)
    return inside & (got < 0)


def right_lanes_valid(right_columns: np.ndarray, dmax: int, last: int) -> np.ndarray:
    """(Wr, Dmax+1) bool: lane d of right map column x_r pairs it with left map column x_r + d, which
    must not lie right of ``last``, the last output column (a lane past it is loaded with word 0)."""
    xr = np.asarray(right_columns, dtype=np.int64)
    return (xr[:, None] + np.arange(dmax + 1)[None, :]) <= last


class Consistency(Column):
    """The consistency column (source PASS: the MAPs of the pass ``feeds_from``). A kind reads one pass:
    :func:`consistency` makes it (this class reads none and is in no model)."""

    name = "lr"
    source = Source.PASS
    table_parameter = "lr_beta"
    options = (
        Option("lr_beta", "float", 0.1, _factor,
               "the consistency column's factor beta of an inconsistent lane, |d_R(x - d) - d| > tolerance"),
        Option("lr_gamma", "float", 0.01, _factor, "the consistency column's no-match factor gamma when any "
               "lane is consistent (1 when none is)"),
        Option("lr_tolerance", "int", 1, _tolerance, "the left-right test's tolerance in disparities"),
        Option("lr_nomatch", "bool", True, check_switch,
               "the left pass's no-match row (off: no no-match row at all)"),
        Option("lr_neutral", "bool", True, check_switch, "a lane whose right pixel has no right MAP (the "
               "right pass's no match or a timeout) gets factor 1, no information (off: beta)"),
    )

    @property
    def tolerance(self) -> int:
        return int(self.values["lr_tolerance"])

    @property
    def neutral(self) -> bool:
        return bool(self.values["lr_neutral"])

    @property
    def has_nomatch(self) -> bool:
        return bool(self.values["lr_nomatch"])

    @property
    def zeroes_nomatch(self) -> bool:
        return not self.has_nomatch

    def costs(self) -> np.ndarray:
        return np.arange(2)  # 0: consistent (or neutral), 1: not

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        return np.where(np.asarray(cost) == 0, 1.0, float(self.values["lr_beta"]))

    def nomatch_values(self) -> tuple[float, ...]:
        return (float(self.values["lr_gamma"]),)

    def values_of(self, table: Table, consistent: np.ndarray,
                  unknown: np.ndarray | None = None) -> np.ndarray:
        """The column (..., Dmax+2) of the test (..., Dmax+1) in ``table``'s domain (float64 or uint16).

        Row d: 1 when consistent, beta otherwise; with ``lr_neutral`` also 1 where ``unknown``
        (:func:`lr_unknown`; required then). The no-match row: gamma when any lane is consistent, 1
        when none is, 0 without a no-match row."""
        c = np.asarray(consistent, dtype=bool)
        dtype = np.float64 if table.word_bits is None else np.uint16
        out = np.empty((*c.shape[:-1], c.shape[-1] + 1), dtype=dtype)
        one, beta = table.values[0], table.values[1]
        if self.neutral:
            if unknown is None or np.shape(unknown) != c.shape:
                got = None if unknown is None else np.shape(unknown)
                raise ValueError(f"lr_neutral: the consistency column needs the unknown lanes (lr_unknown), "
                                 f"shape {c.shape}, got {got}")
            out[..., :-1] = np.where(c | np.asarray(unknown, dtype=bool), one, beta)
        else:
            out[..., :-1] = np.where(c, one, beta)
        if self.has_nomatch:
            out[..., -1] = np.where(c.any(axis=-1), table.nomatch[0], one)
        else:
            out[..., -1] = 0
        return out

    def loaded(self, table: Table, right_map: np.ndarray, right_first: int,
               columns: np.ndarray) -> np.ndarray:
        """The column (..., Wo, Dmax+2) of left map columns ``columns`` from the right MAPs ``right_map``
        (..., Wr) of right map columns ``right_first ..``, in ``table``'s domain."""
        consistent = lr_consistent(right_map, right_first, columns, self.dmax, self.tolerance)
        unknown = lr_unknown(right_map, right_first, columns, self.dmax) if self.neutral else None
        return self.values_of(table, consistent, unknown)

    def rejects(self, disp: np.ndarray, right_map: np.ndarray, right_first: int,
                columns: np.ndarray) -> np.ndarray:
        """(Ho, Wo) bool: the pixels with a disparity d (``disp`` (Ho, Wo) >= 0) whose lane d this column
        gives beta: inconsistent, and not neutral (``lr_neutral``: a right pixel without a right MAP is)."""
        d = np.asarray(disp)
        lanes = np.clip(d, 0, self.dmax).astype(np.int64)
        at = np.arange(d.shape[-1])
        out = np.zeros(d.shape, bool)
        for y in range(d.shape[0]):
            ok = lr_consistent(right_map[y], right_first, columns, self.dmax, self.tolerance)
            if self.neutral:
                ok |= lr_unknown(right_map[y], right_first, columns, self.dmax)
            out[y] = (d[y] >= 0) & ~ok[at, lanes[y]]
        return out

    def words(self, ctx: PassContext) -> np.ndarray:
        """From the MAPs of the pass :attr:`feeds_from` of the same map rows (``ctx.results``)."""
        got, first = ctx.results_of(self.feeds_from, self.name)
        words = self.loaded(self.table(ctx.word_bits), got, first, ctx.columns)
        return words.reshape(-1, words.shape[-1])

    def check_machine(self, machine: Any) -> None:
        for name in ("lr_beta", "lr_gamma"):
            self._nonzero_word(name, float(self.values[name]), machine, "a consistency factor of 0")


_KINDS: dict[tuple[str, str], type[Consistency]] = {}


def consistency(pass_name: str, *, name: str = "lr") -> type[Consistency]:
    """The consistency kind reading the MAPs of the pass named ``pass_name`` (one the model declares and
    runs before its own), as column ``name`` (two consistency columns of a model need two names); one
    kind per (pass, name). ``TypeError`` for a name that is not a string, ``ValueError`` for an empty
    one."""
    for what, value in (("pass_name", pass_name), ("name", name)):
        if not isinstance(value, str):
            raise TypeError(f"consistency: {what} must be a string, not {type(value).__name__}")
        if not value:
            raise ValueError(f"consistency: {what} must not be empty")
    key = (pass_name, name)
    if key not in _KINDS:
        kind = "Consistency_" + "".join(ch if ch.isalnum() else "_" for ch in f"{pass_name}_{name}")
        while kind in globals():  # (another pair spelt alike)
            kind += "_"
        doc = f"The consistency column {name}, fed by the MAPs of the pass {pass_name!r}."
        cls = type(kind, (Consistency,), {"name": name, "feeds_from": pass_name, "__module__": __name__,
                                          "__doc__": doc})
        globals()[kind] = cls  # pickled by name, as any column kind
        _KINDS[key] = cls
    return _KINDS[key]
