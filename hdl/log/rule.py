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

from bayesmachine.integrators.log import LogParams, check_params

__all__ = ["LogParams", "LogResult", "argmin_rows", "check_params", "integrate_pixel", "log_integrate",
           "row_sums", "row_weights"]

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
