"""The logarithmic integrator's rule, in NumPy: THE definition the log blocks are held to.

A pixel has M rows; row r has N energy codes ``E[r][c]`` (``code_bits`` unsigned bits each, the
code of −ln of a likelihood in fixed steps). The all-ones code ``2**code_bits - 1`` is infinite
energy (likelihood 0). Per pixel (``docs/integrators.md``, "The logarithmic integrator: exact
rule"):

- ``sums[r] = Σ_c E[r][c]`` exactly, ``excluded[r]`` = some code of row r is infinite;
- ``map`` = the row of the lowest sum among the rows not excluded, ties by ``tie_break``
  (``nomatch-first``: the no-match row, the last one, wins a tie it is part of, else the lowest
  index; ``lowest-index``: the lowest index); when every row is excluded, ``all_excluded`` and
  ``map`` is the no-match row (row 0 without one);
- ``s_min`` = ``sums[map]`` (0 when every row is excluded);
- ``nomatch`` = the pixel has a no-match row and ``map`` is it;
- ``weights[r] = X[min(sums[r] - s_min, len(X) - 1)]`` for the exp table X (a row's sum is never
  below ``s_min`` unless it is excluded), 0 for an excluded row.

:func:`log_integrate` computes it for any number of pixels at once (numba-compiled, one pass over
each pixel's codes); :func:`row_sums`, :func:`argmin_rows` and :func:`row_weights` are its parts,
the twins of the row adders, the argmin tree and the weights stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError
from bayesmachine.params import DEFAULT_TIE_BREAK, TIE_BREAKS

__all__ = ["LogParams", "LogResult", "argmin_rows", "check_params", "integrate_pixel", "log_integrate",
           "row_sums", "row_weights"]

MAX_CODE_BITS = 16
MAX_WEIGHT_BITS = 16


def _table(weights: object) -> tuple[int, ...]:
    """The exp table as a tuple of ints, checked: nonincreasing, at least 2 entries, the first
    positive and below ``2**(MAX_WEIGHT_BITS + 1)``, the last 0."""
    if isinstance(weights, (str, bytes)) or not hasattr(weights, "__iter__"):
        raise TypeError(f"weights must be a sequence of integers, not {type(weights).__name__}")
    table = tuple(as_int("weights", w, 0, 1 << MAX_WEIGHT_BITS) for w in weights)  # type: ignore[union-attr]
    if len(table) < 2 or table[0] == 0 or table[-1] != 0:
        raise ParameterError(f"weights must have at least 2 entries, the first positive and the last 0, "
                             f"got {table[:4]}...{table[-2:]}", "weights")
    if any(b > a for a, b in zip(table, table[1:], strict=False)):
        raise ParameterError("weights must be nonincreasing", "weights")
    return table


@dataclass(frozen=True)
class LogParams:
    """Parameters of one logarithmic integrator (the rule, the blocks and the top share them).

    Parameters
    ----------
    rows : int
        M, the rows (hypotheses) of a pixel, 1 ... 4096 (>= 2 with a no-match row); Dmax + 2 in
        disparity use.
    codes : int
        N, the energy codes per row, 1 ... 64.
    code_bits : int
        Bits of a code, 1 ... 16; the all-ones code is infinite energy.
    weights : sequence of int
        The exp table X: nonincreasing, at least 2 entries, the first positive, the last 0
        (``bayesmachine.columns.energy.exp_table`` builds one).
    nomatch_row : bool
        Whether the last row is the no-match row.
    tie_break : str
        ``"nomatch-first"`` or ``"lowest-index"`` (``bayesmachine.params.TIE_BREAKS``).

    Attributes
    ----------
    sum_bits : int
        Bits of a row's sum: ``code_bits + ceil(log2 codes)``.
    map_width : int
        Bits of a row index: ``max(1, bit_length(rows - 1))``.
    weight_bits : int
        Bits of a weight: ``bit_length(weights[0])``.
    infinite : int
        The infinite code, ``2**code_bits - 1``.
    """

    rows: int
    codes: int
    code_bits: int
    weights: tuple[int, ...]
    nomatch_row: bool = True
    tie_break: str = DEFAULT_TIE_BREAK

    def __post_init__(self) -> None:
        object.__setattr__(self, "rows", as_int("rows", self.rows, 1, 4096))
        object.__setattr__(self, "codes", as_int("codes", self.codes, 1, 64))
        object.__setattr__(self, "code_bits", as_int("code_bits", self.code_bits, 1, MAX_CODE_BITS))
        object.__setattr__(self, "weights", _table(self.weights))
        if not isinstance(self.nomatch_row, (bool, np.bool_)):
            raise TypeError(f"nomatch_row must be a bool, not {type(self.nomatch_row).__name__}")
        object.__setattr__(self, "nomatch_row", bool(self.nomatch_row))
        if self.nomatch_row and self.rows < 2:
            raise ParameterError("rows: an integrator with a no-match row needs at least 2 rows", "rows")
        if not isinstance(self.tie_break, str):
            raise TypeError(f"tie_break must be a str, not {type(self.tie_break).__name__}")
        if self.tie_break not in TIE_BREAKS:
            raise ParameterError(f"tie_break must be one of {TIE_BREAKS}, got {self.tie_break!r}",
                                 "tie_break")

    @property
    def sum_bits(self) -> int:
        return self.code_bits + (self.codes - 1).bit_length()

    @property
    def map_width(self) -> int:
        return max(1, (self.rows - 1).bit_length())

    @property
    def weight_bits(self) -> int:
        return self.weights[0].bit_length()

    @property
    def infinite(self) -> int:
        return (1 << self.code_bits) - 1

    @property
    def nomatch_first(self) -> bool:
        """The no-match row wins the ties it is part of."""
        return self.nomatch_row and self.tie_break == "nomatch-first"

    @property
    def none_index(self) -> int:
        """The ``map`` of a pixel whose rows are all excluded: the no-match row, else row 0."""
        return self.rows - 1 if self.nomatch_row else 0


@dataclass(frozen=True)
class LogResult:
    """The rule's answer for pixels of any leading shape P (arrays of shape P, or P + (M,)).

    ``map``, ``s_min`` (int32), ``nomatch``, ``all_excluded`` (bool), ``sums`` (int32, per row),
    ``excluded`` (bool, per row), ``weights`` (int32, per row).
    """

    map: np.ndarray
    nomatch: np.ndarray
    all_excluded: np.ndarray
    s_min: np.ndarray
    sums: np.ndarray
    excluded: np.ndarray
    weights: np.ndarray


@numba.njit(cache=True, inline="always")
def _row(codes, infinite):
    """One row's sum and whether one of its codes is infinite."""
    total, inf = 0, False
    for c in range(codes.shape[0]):
        total += codes[c]
        inf |= codes[c] == infinite
    return total, inf


@numba.njit(cache=True, inline="always")
def _argmin(sums, excluded, nm_first):
    """The rule's MAP by a sequential scan: a row not excluded replaces the best so far when its sum
    is lower (the no-match row, the last, under nomatch-first: not higher). -1: every row excluded."""
    best = -1
    last = sums.shape[0] - 1
    for r in range(sums.shape[0]):
        if excluded[r]:
            continue
        if best < 0 or sums[r] < sums[best] or (nm_first and r == last and sums[r] == sums[best]):
            best = r
    return best


@numba.njit(cache=True, inline="always")
def _weights(sums, excluded, s_min, table, out):
    """Each row's weight: X at its distance from s_min, clamped to [0, len(X) - 1]; 0 if excluded."""
    last = table.shape[0] - 1
    for r in range(sums.shape[0]):
        d = min(max(sums[r] - s_min, 0), last)
        out[r] = 0 if excluded[r] else table[d]


@numba.njit(cache=True)
def _row_sums(codes, infinite, sums, excluded):
    for i in range(codes.shape[0]):
        for r in range(codes.shape[1]):
            sums[i, r], excluded[i, r] = _row(codes[i, r], infinite)


@numba.njit(cache=True)
def _argmin_rows(sums, excluded, nm_first, none_index, out_map, out_none, out_s_min):
    for i in range(sums.shape[0]):
        best = _argmin(sums[i], excluded[i], nm_first)
        out_none[i] = best < 0
        out_map[i] = none_index if best < 0 else best
        out_s_min[i] = 0 if best < 0 else sums[i, best]


@numba.njit(cache=True)
def _row_weights(sums, excluded, s_min, table, out):
    for i in range(sums.shape[0]):
        _weights(sums[i], excluded[i], s_min[i], table, out[i])


@numba.njit(cache=True, inline="always")
def integrate_pixel(codes, infinite, nm_first, none_index, table, sums, excluded, weights):
    """The whole rule for one pixel's ``codes`` (rows, codes), in one pass: fills its ``sums``,
    ``excluded`` and ``weights`` (per row) and returns ``(map, all_excluded, s_min)``. Compiled (numba):
    the kernel every caller of the rule per pixel shares (:func:`log_integrate`, the model engine)."""
    for r in range(codes.shape[0]):
        sums[r], excluded[r] = _row(codes[r], infinite)
    best = _argmin(sums, excluded, nm_first)
    s_min = 0 if best < 0 else sums[best]
    _weights(sums, excluded, s_min, table, weights)
    return (none_index if best < 0 else best), best < 0, s_min


@numba.njit(cache=True)
def _integrate(codes, infinite, nm_first, none_index, table, sums, excluded, out_map, out_none, out_s_min,
               weights):
    """The whole rule per pixel, in one pass over its codes."""
    for i in range(codes.shape[0]):
        out_map[i], out_none[i], out_s_min[i] = integrate_pixel(codes[i], infinite, nm_first, none_index,
                                                                table, sums[i], excluded[i], weights[i])


def _check_codes(codes: object, params: LogParams) -> np.ndarray:
    if not isinstance(codes, np.ndarray) or codes.dtype.kind not in "ui":
        raise TypeError("codes must be a NumPy integer array of shape (..., rows, codes)")
    if codes.ndim < 2 or codes.shape[-2:] != (params.rows, params.codes):
        raise ValueError(f"codes must have shape (..., {params.rows}, {params.codes}), got {codes.shape}")
    if codes.size and (codes.min() < 0 or codes.max() > params.infinite):
        raise ValueError(f"codes must be in [0, {params.infinite}] ({params.code_bits} bits)")
    return np.ascontiguousarray(codes.reshape(-1, params.rows, params.codes))


def check_params(params: object) -> LogParams:
    """``params`` if it is a :class:`LogParams`, else a TypeError."""
    if not isinstance(params, LogParams):
        raise TypeError(f"params must be a LogParams, not {type(params).__name__}")
    return params


def _rows_in(sums: np.ndarray, excluded: np.ndarray, params: LogParams) -> tuple[np.ndarray, np.ndarray]:
    sums, excluded = np.asarray(sums), np.asarray(excluded)
    if sums.shape != excluded.shape or sums.ndim < 1 or sums.shape[-1] != params.rows:
        raise ValueError(f"sums and excluded must have one shape (..., {params.rows}), got {sums.shape} "
                         f"and {excluded.shape}")
    return (np.ascontiguousarray(sums.reshape(-1, params.rows), dtype=np.int32),
            np.ascontiguousarray(excluded.reshape(-1, params.rows), dtype=np.bool_))


def row_sums(codes: np.ndarray, params: LogParams) -> tuple[np.ndarray, np.ndarray]:
    """The row adders' part: ``(sums, excluded)`` of ``codes`` (shape ``(..., rows, codes)``)."""
    flat = _check_codes(codes, check_params(params))
    sums, excluded = np.empty(flat.shape[:2], np.int32), np.empty(flat.shape[:2], np.bool_)
    _row_sums(flat, params.infinite, sums, excluded)
    return sums.reshape(codes.shape[:-1]), excluded.reshape(codes.shape[:-1])


def argmin_rows(sums: np.ndarray, excluded: np.ndarray, params: LogParams
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The argmin tree's part: ``(map, nomatch, all_excluded, s_min)`` of the rows' ``sums`` and
    ``excluded`` flags (shape ``(..., rows)``)."""
    p = check_params(params)
    flat_sums, flat_excluded = _rows_in(sums, excluded, p)
    n = len(flat_sums)
    map_, none, s_min = np.empty(n, np.int32), np.empty(n, np.bool_), np.empty(n, np.int32)
    _argmin_rows(flat_sums, flat_excluded, p.nomatch_first, p.none_index, map_, none, s_min)
    shape = np.shape(sums)[:-1]
    nomatch = (map_ == p.rows - 1) & p.nomatch_row
    return map_.reshape(shape), nomatch.reshape(shape), none.reshape(shape), s_min.reshape(shape)


def row_weights(sums: np.ndarray, excluded: np.ndarray, s_min: np.ndarray, params: LogParams) -> np.ndarray:
    """The weights stage's part: ``X[min(sums - s_min, len(X) - 1)]`` per row, 0 for an excluded row
    (a sum below ``s_min``, which the rule never gives a row not excluded, reads X[0])."""
    p = check_params(params)
    flat_sums, flat_excluded = _rows_in(sums, excluded, p)
    flat_s_min = np.ascontiguousarray(np.broadcast_to(s_min, np.shape(sums)[:-1]).reshape(-1), dtype=np.int32)
    out = np.empty(flat_sums.shape, np.int32)
    _row_weights(flat_sums, flat_excluded, flat_s_min, np.asarray(p.weights, np.int32), out)
    return out.reshape(np.shape(sums))


def log_integrate(codes: np.ndarray, params: LogParams) -> LogResult:
    """The rule (module docstring) on ``codes`` of shape ``(..., rows, codes)``, compiled (numba) and
    vectorized over the leading axes (pixels): one pass over each pixel's codes."""
    p = check_params(params)
    flat = _check_codes(codes, p)
    n, shape, rows_shape = len(flat), codes.shape[:-2], codes.shape[:-1]
    sums, excluded = np.empty((n, p.rows), np.int32), np.empty((n, p.rows), np.bool_)
    map_, none, s_min = np.empty(n, np.int32), np.empty(n, np.bool_), np.empty(n, np.int32)
    weights = np.empty((n, p.rows), np.int32)
    _integrate(flat, p.infinite, p.nomatch_first, p.none_index, np.asarray(p.weights, np.int32), sums,
               excluded, map_, none, s_min, weights)
    nomatch = (map_ == p.rows - 1) & p.nomatch_row
    return LogResult(map=map_.reshape(shape), nomatch=nomatch.reshape(shape),
                     all_excluded=none.reshape(shape), s_min=s_min.reshape(shape),
                     sums=sums.reshape(rows_shape), excluded=excluded.reshape(rows_shape),
                     weights=weights.reshape(rows_shape))
