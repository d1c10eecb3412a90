"""The logarithmic machine: the log blocks behind the stochastic machine's ports (``MachineSignature``).

A pixel's energy codes come in on the load stream as the stochastic machine's words do (``words_per_beat``
per beat, ``beats_per_pixel`` beats, a code in the low :data:`~bayesmachine.columns.energy.LOG_CODE_BITS`
bits of each W + 1-bit word; with a neighbour prior ``line_start`` on its beats) into a pixel buffer,
whose loaded codes the row adders sum per row (one pixel per clock, ``line_start`` carried along);
each pixel's sums are then *issued* into the argmin tree, with its feedback column formed (a neighbour
prior: from the previous result, :func:`~bayesmachine.sim.model.fill_feedback`'s rule with the flat
code 0) and added to the sums in the tree's first level, and on to the weights stage (``RowAdders`` →
``ArgminTree(feedback=True)`` → ``WeightStage``, streams between). The result stream carries ``map``,
``nomatch``, ``timeout`` (every row excluded), ``cycles`` and ``counts`` (the rows' weights):
``sim.log_model.LogMachineModel``'s results, bit for bit.

The feedback loop is the argmin tree alone: as a MAP reaches the tree's output buffer it is registered
(the tree's ``latest`` result, a copy per :data:`FEEDBACK_GROUP` rows), and a pixel with a left
neighbour issues the clock after, its feedback codes formed from those registers on the way into the
tree's first level, so such pixels issue every ``ArgminTree.latency`` clocks at most
(``bayesmachine.integrators.log.pixel_clocks``); a line's first pixel and every pixel without a
neighbour prior issue as soon as their sums are ready. ``cycles`` is that issue interval by the rule
(1, or the loop's clocks), which the loading may exceed (the wall cycles count it).
"""

from __future__ import annotations

import dataclasses

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import fifo, wiring

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

from .adders import RowAdders
from .argmin import ArgminTree
from .weights import WeightStage

__all__ = ["FEEDBACK_GROUP", "LogMachine"]

FEEDBACK_GROUP = 8  # rows whose feedback codes read one copy of the latest MAP (a net's fanout)


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

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p, lp = self._params, self._log
        fb = bool(p.feedback_columns)
        # The loaded columns' codes are summed before the issue point, outside the loop through the
        # previous MAP: the loop is the argmin tree alone, with the feedback codes' adders as its first level.
        loaded = dataclasses.replace(lp, codes=p.loaded_columns)
        m.submodules.adders = adders = RowAdders(params=loaded, levels_per_stage=ADDER_LEVELS_PER_STAGE,
                                                 carried=int(fb))
        copies = -(-lp.rows // FEEDBACK_GROUP) if fb else 0
        m.submodules.argmin = argmin = ArgminTree(params=lp, levels_per_stage=ARGMIN_LEVELS_PER_STAGE,
                                                  pass_sums=True, feedback=fb, latest_copies=copies)
        m.submodules.weights = weights = WeightStage(params=lp)
        wiring.connect(m, argmin.best, weights.best)
        # pixel_clocks is the loop's latency (tests/hdl/log/test_machine.py holds it too).
        assert not fb or argmin.latency == self.loop
        # Pixels issued and not yet out, their line_start in order, for their cycles (at most every
        # stage's plus the two output buffers' entries).
        depth = argmin.latency + weights.latency + 4
        m.submodules.starts = starts = fifo.SyncFIFO(width=1, depth=depth)
        self._fill(m, adders)
        self._issue(m, adders, argmin, starts)
        self._result(m, weights, starts)
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

    def _fill(self, m: Module, adders: RowAdders) -> None:
        """A full pixel buffer passes its codes (and its line_start) to the row adders when they take it,
        and takes the next pixel's first beat in that clock."""
        codes, full, start, last_taken = self._load(m)
        taken = Signal()
        payload = adders.codes.payload
        m.d.comb += [adders.codes.valid.eq(full), taken.eq(full & adders.codes.ready),
                     self.load.ready.eq(~full | taken)]
        with m.If(taken & ~last_taken):
            m.d.sync += full.eq(0)
        if self._params.feedback_columns:
            m.d.comb += payload.carried.eq(start)
            payload = payload.codes
        m.d.comb += Cat(*(payload[r].as_value() for r in range(self._log.rows))).eq(Cat(*codes))

    def _issue(self, m: Module, adders: RowAdders, argmin: ArgminTree, starts: fifo.SyncFIFO) -> None:
        """The next pixel's loaded sums wait in the issue register (so the loop's first stage starts at
        registers, not at the row adders' output buffer) and issue into the argmin tree when it takes them
        and (a neighbour prior) its feedback codes are known: a line start, or no pixel in the argmin tree
        (``pending``: the last one's MAP has reached its output buffer and is its latest result)."""
        p = self._params
        sums, into = adders.sums, argmin.sums
        held = Signal(sums.payload.shape(), name="issue_sums", reset_less=True)
        held_valid = Signal(name="issue_valid")
        view = sums.payload.shape()(held)
        issue = Signal()
        m.d.comb += sums.ready.eq(~held_valid | issue)
        with m.If(sums.ready):
            m.d.sync += [held.eq(sums.payload), held_valid.eq(sums.valid)]
        start = view.carried if p.feedback_columns else Const(0, 1)
        if p.feedback_columns:
            pending = Signal(range(argmin.latency + 8))
            m.d.sync += pending.eq(pending + issue - argmin.arriving)
            known = start | (pending == 0)
            fb = self._feedback(m, argmin, start)
            m.d.comb += [into.payload.feedback[r].eq(fb[r]) for r in range(p.rows)]
        else:
            known = 1
        m.d.comb += [
            issue.eq(held_valid & into.ready & starts.w_rdy & known),
            into.valid.eq(held_valid & starts.w_rdy & known),
            starts.w_en.eq(issue),
            starts.w_data.eq(start),
            into.payload.excluded.eq(view.excluded),
            *(into.payload.sums[r].eq(view.sums[r]) for r in range(p.rows)),
        ]

    def _feedback(self, m: Module, argmin: ArgminTree, start: Signal) -> list[Value]:
        """Each row's feedback code from the argmin tree's latest MAP (the copy of the row's group): the
        table at |r − MAP| clamped, the no-match code in the no-match row; 0 when that pixel's answer is
        no match or every row was excluded (0 from reset), or at a line start."""
        p = self._params
        last = len(p.feedback_words) - 1
        out = []
        for r in range(p.rows):
            latest = argmin.latest[r // FEEDBACK_GROUP]
            hit = ~latest.nomatch & ~latest.all_excluded
            code = Signal(LOG_CODE_BITS, name=f"feedback{r}")
            if p.nomatch_row and r == p.rows - 1:
                value = Const(p.feedback_nomatch_word, LOG_CODE_BITS)
            else:
                # The row's code at each MAP, a lookup of the MAP's bits (no distance arithmetic, no
                # carry chain in the loop); every index of the MAP's width (a complete case: verilator
                # -Wall CASEINCOMPLETE), the ones past the rows never read (hit is 0 there).
                at = [p.feedback_words[min(abs(i - r), last)] for i in range(1 << p.map_width)]
                value = Array(Const(c, LOG_CODE_BITS) for c in at)[latest.map]
            m.d.comb += code.eq(Mux(hit & ~start, value, 0))
            out.append(code)
        return out

    def _result(self, m: Module, weights: WeightStage, starts: fifo.SyncFIFO) -> None:
        p = self._params
        got = weights.result.payload
        free, bound = pixel_clocks(p)
        m.d.comb += [
            self.result.valid.eq(weights.result.valid),
            weights.result.ready.eq(self.result.ready),
            starts.r_en.eq(weights.result.valid & self.result.ready),
            self.result.payload.map.eq(got.map),
            self.result.payload.nomatch.eq(got.nomatch),
            self.result.payload.timeout.eq(got.all_excluded),
            self.result.payload.cycles.eq(Mux(starts.r_data | (bound == free), free, bound)),
        ]
        for r in range(p.rows):
            m.d.comb += self.result.payload.counts[r].eq(got.weights[r])
