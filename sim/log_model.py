"""The logarithmic machine's model: the ``model`` engine of a machine with ``integrator = "log"``, and the
log integrator's rule in NumPy, THE definition the log blocks (``hdl.log``) are held to, as
``sim.model`` is the stochastic machine's. Its parameters, pixel clocks and timing formulas are
``bayesmachine.integrators.log``'s.

The rule. A pixel has M rows; row r has N energy codes ``E[r][c]`` (``code_bits`` unsigned bits each, the
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

The engine. What is loaded per pixel are energy codes, not words: each loaded column's
(:func:`bayesmachine.columns.energy.log_codes` of its factors; the host builds them in
``host.likelihoods.pass_words``), (P, rows × loaded columns) as for the stochastic machine. Per pixel, in
order: with a neighbour prior the feedback column is formed first from the previous result (the
stochastic model's :func:`~bayesmachine.sim.model.fill_feedback` with the flat code 0 and the machine's
``feedback_words``, which hold the left prior's codes), then the rule
(:func:`integrate_pixel`, the definition :func:`log_integrate` runs). The result:
``counts`` the rows' weights (``exp_table(word_bits)`` at each sum's distance from the least, up to
``MachineParams.readout_max``: the distribution the host reads as it reads the counters), ``map``,
``nomatch``, ``timeout`` where every row is excluded (no answer, as the stochastic machine whose every
row has a zero word runs into its watchdog), ``cycles`` the clocks per pixel by
:func:`bayesmachine.integrators.log.pixel_clocks`. ``hdl.log.machine.LogMachine`` is its RTL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bayesmachine.columns.energy import INFINITE_CODE
from bayesmachine.integrators.log import LOG, LogParams, check_params, log_params, pixel_clocks
from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import EngineBase
from bayesmachine.sim.model import feedback_result, fill_feedback
from bayesmachine.sim.results import MachineResult, NumberFeed

__all__ = ["LogMachineModel", "LogResult", "argmin_rows", "integrate_pixel", "log_integrate", "row_sums",
           "row_weights"]

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


@numba.njit(cache=True)
def _run_log(codes, rows, opcols, nm_first, none_index, table, line_start, fb, fb_nm, nm_row, prev,
             out_weights, out_map, out_none):
    """Pixel by pixel in order (the feedback column is formed from the previous result first)."""
    sums = np.empty(rows, np.int32)
    excluded = np.empty(rows, np.bool_)
    feedback = line_start.shape[0] > 0
    for p in range(codes.shape[0]):
        qp = codes[p]
        if feedback:
            fill_feedback(qp, prev[0], line_start[p], fb, fb_nm, rows, opcols, nm_row, 0)
        m, none, _ = integrate_pixel(qp.reshape((rows, opcols)), INFINITE_CODE, nm_first, none_index, table,
                                     sums, excluded, out_weights[p])
        out_map[p] = m
        out_none[p] = none
        prev[0] = feedback_result(m, none, nm_row)


class LogMachineModel(EngineBase):
    """The logarithmic machine's ``model`` engine (module text); the engines' contract, its input
    energy codes in [0, :data:`INFINITE_CODE`] (``MachineParams.load_max``), no random numbers."""

    name = "model"
    FEEDBACK = True

    def __init__(self, params: MachineParams) -> None:
        if not isinstance(params, MachineParams) or params.kind is not LOG:
            raise ValueError("LogMachineModel runs a machine with integrator = 'log'")
        super().__init__(params)
        self._log = log_params(params)
        self._table = np.asarray(self._log.weights, np.int32)
        self._fb = np.array(params.feedback_words or (0,), np.int32)
        self._fb_nm = int(params.feedback_nomatch_word or 0)
        self._nm_row = params.rows - 1 if params.nomatch_row else -1
        self._prev = np.full(1, -1, np.int64)

    def _reset(self) -> None:
        self._prev[0] = -1

    def _run(self, words: np.ndarray, feed: NumberFeed | None) -> MachineResult:
        return self._integrate(words, np.zeros(0, np.uint8))

    def _run_feedback(self, words: np.ndarray, feed: NumberFeed | None,
                      line_start: np.ndarray) -> MachineResult:
        return self._integrate(words, np.ascontiguousarray(line_start, np.uint8))

    def _integrate(self, codes: np.ndarray, line_start: np.ndarray) -> MachineResult:
        p = self._params
        full = np.zeros((codes.shape[0], p.rows, p.operator_columns), np.int32)
        full[:, :, p.feedback_columns:] = codes.reshape(codes.shape[0], p.rows, p.loaded_columns)
        out = MachineResult.zeros(codes.shape[0], p.rows)
        lp = self._log
        _run_log(full.reshape(codes.shape[0], p.operators), p.rows, p.operator_columns, lp.nomatch_first,
                 lp.none_index, self._table, line_start, self._fb, self._fb_nm, self._nm_row, self._prev,
                 out.counts, out.map, out.timeout)
        out.nomatch[:] = (out.map == p.rows - 1) & p.nomatch_row
        free, bound = pixel_clocks(p)
        out.cycles[:] = free
        if line_start.size:
            out.cycles[~line_start.astype(bool)] = bound
        return out
