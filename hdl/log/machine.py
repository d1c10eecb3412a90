"""The logarithmic machine: the log integrator (``integrator.LogIntegrator``) behind the stochastic machine's
ports (``MachineSignature``).

A pixel's energy codes come in on the load stream as the stochastic machine's words do (``words_per_beat``
per beat, ``beats_per_pixel`` beats, a code in the low :data:`~bayesmachine.columns.energy.LOG_CODE_BITS`
bits of each W + 1-bit word; with a neighbour prior ``line_start`` on its beats) into a pixel buffer,
whose codes (and line_start) go to the integrator, one pixel per clock: its row adders, issue register,
argmin tree (with a neighbour prior the feedback column, formed from the previous result:
:func:`~bayesmachine.sim.model.fill_feedback`'s rule with the flat code 0) and weights stage. The result
stream carries ``map``, ``nomatch``, ``timeout`` (every row excluded), ``cycles`` and ``counts`` (the
rows' weights): ``sim.log_model.LogMachineModel``'s results, bit for bit.

Pixels with a left neighbour issue every ``LogIntegrator.loop`` clocks at most (the argmin tree's
latency, ``bayesmachine.integrators.log.pixel_clocks``); a line's first pixel and every pixel without a
neighbour prior issue as soon as their sums are ready. ``cycles`` is that issue interval by the rule
(1, or the loop's clocks), which the loading may exceed (the wall cycles count it).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring

from bayesmachine.columns.energy import LOG_CODE_BITS
from bayesmachine.hdl.signatures import MachineSignature, beat_words
from bayesmachine.integrators.log import (
    ADDER_LEVELS_PER_STAGE,
    ARGMIN_LEVELS_PER_STAGE,
    LOG,
    log_params,
    pixel_clocks,
)
from bayesmachine.params import MachineParams

from .integrator import LogIntegrator

__all__ = ["LogMachine"]


class LogMachine(wiring.Component):
    """The logarithmic machine (module text).

    Parameters
    ----------
    params : MachineParams
        A machine with ``integrator = "log"`` and ``word_bits`` >= 8 (a code fits a word); an on-chip
        ``rng`` (it draws no random numbers).

    Attributes
    ----------
    load : ``In(load_stream(params))``
        A pixel's codes in operator order (the loaded columns).
    result : ``Out(result_stream(params))``
        One result per pixel, in order.
    params : MachineParams
    loop : int
        Clocks per pixel where the feedback column binds (1 without a neighbour prior).
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
        if params.kind is not LOG:
            raise ValueError("LogMachine builds a machine with integrator = 'log'")
        self._params = params
        self._log = log_params(params)
        super().__init__(MachineSignature(params))

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def loop(self) -> int:
        return pixel_clocks(self._params)[1]

    def integrator(self) -> LogIntegrator:
        """The machine's integrator: its rule's parameters, the feedback column's table (a neighbour
        prior), the machine's pipeline setting (``ARGMIN_LEVELS_PER_STAGE``, ``ADDER_LEVELS_PER_STAGE``)."""
        p = self._params
        return LogIntegrator(params=self._log, feedback_words=p.feedback_words,
                             feedback_nomatch_word=p.feedback_nomatch_word,
                             levels_per_stage=ARGMIN_LEVELS_PER_STAGE,
                             adder_levels_per_stage=ADDER_LEVELS_PER_STAGE)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.integrator = integrator = self.integrator()
        # pixel_clocks is the loop's latency (tests/hdl/log/test_machine.py holds it too).
        assert integrator.loop == self.loop
        self._fill(m, integrator)
        self._result(m, integrator)
        return m

    def _load(self, m: Module) -> tuple[list[Signal], Signal, Signal, Signal]:
        """The pixel buffer: a code per loaded word, filled beat by beat; ``full`` once the last beat is
        in, ``start`` its line_start; and whether a pixel's last beat is taken this clock."""
        p = self._params
        codes = [Signal(LOG_CODE_BITS, name=f"code{i}") for i in range(p.words_per_pixel)]
        full = Signal()
        start = Signal()
        beat = Signal(range(max(2, p.beats_per_pixel)))
        taking, last_taken = Signal(), Signal()
        last = beat == p.beats_per_pixel - 1
        m.d.comb += [taking.eq(self.load.valid & self.load.ready), last_taken.eq(taking & last)]
        words = beat_words(p, self.load.payload)
        lanes = p.words_per_beat
        with m.If(taking):
            for b in range(p.beats_per_pixel):
                with m.If(beat == b):
                    for lane in range(min(lanes, p.words_per_pixel - b * lanes)):
                        m.d.sync += codes[b * lanes + lane].eq(words[lane][:LOG_CODE_BITS])
            m.d.sync += beat.eq(Mux(last, 0, beat + 1))
        with m.If(last_taken):
            m.d.sync += full.eq(1)
            if p.feedback_columns:
                m.d.sync += start.eq(self.load.payload.line_start)
        return codes, full, start, last_taken

    def _fill(self, m: Module, integrator: LogIntegrator) -> None:
        """A full pixel buffer passes its codes (and its line_start) to the integrator when it takes them,
        and takes the next pixel's first beat in that clock."""
        codes, full, start, last_taken = self._load(m)
        taken = Signal()
        payload = integrator.codes.payload
        m.d.comb += [integrator.codes.valid.eq(full), taken.eq(full & integrator.codes.ready),
                     self.load.ready.eq(~full | taken)]
        with m.If(taken & ~last_taken):
            m.d.sync += full.eq(0)
        if integrator.feedback:
            m.d.comb += payload.line_start.eq(start)
            payload = payload.codes
        m.d.comb += Cat(*(payload[r].as_value() for r in range(self._log.rows))).eq(Cat(*codes))

    def _result(self, m: Module, integrator: LogIntegrator) -> None:
        p = self._params
        got = integrator.result.payload
        free, bound = pixel_clocks(p)
        start = integrator.line_start if integrator.feedback else 1
        m.d.comb += [
            self.result.valid.eq(integrator.result.valid),
            integrator.result.ready.eq(self.result.ready),
            self.result.payload.map.eq(got.map),
            self.result.payload.nomatch.eq(got.nomatch),
            self.result.payload.timeout.eq(got.all_excluded),
            self.result.payload.cycles.eq(Mux(start | (bound == free), free, bound)),
        ]
        for r in range(p.rows):
            m.d.comb += self.result.payload.counts[r].eq(got.weights[r])
