"""The logarithmic machine's model: the ``model`` engine of a machine with ``integrator = "log"``.

What is loaded per pixel are energy codes, not words: each loaded column's
(:func:`bayesmachine.columns.energy.log_codes` of its factors; the host builds them in
``host.likelihoods.pass_words``), (P, rows × loaded columns) as for the stochastic machine. Per pixel, in
order: with a neighbour prior the feedback column is formed first from the previous result (the
stochastic model's :func:`~bayesmachine.sim.model.fill_feedback` with the flat code 0 and the machine's
``feedback_words``, which hold the left prior's codes), then the rule
(:func:`bayesmachine.hdl.log.rule.integrate_pixel`, the definition ``log_integrate`` runs). The result:
``counts`` the rows' weights (``exp_table(word_bits)`` at each sum's distance from the least, up to
``MachineParams.readout_max``: the distribution the host reads as it reads the counters), ``map``,
``nomatch``, ``timeout`` where every row is excluded (no answer, as the stochastic machine whose every
row has a zero word runs into its watchdog), ``cycles`` the clocks per pixel by
:func:`bayesmachine.integrators.log.pixel_clocks`. ``hdl.log.machine.LogMachine`` is its RTL.
"""

from __future__ import annotations

import numba
import numpy as np

from bayesmachine.columns.energy import INFINITE_CODE
from bayesmachine.hdl.log.rule import integrate_pixel
from bayesmachine.integrators.log import LOG, log_params, pixel_clocks
from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import EngineBase
from bayesmachine.sim.model import feedback_result, fill_feedback
from bayesmachine.sim.results import MachineResult, NumberFeed

__all__ = ["LogMachineModel"]

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
