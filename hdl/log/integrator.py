"""The logarithmic integrator: a pixel's energy codes in, its MAP and each row's weight out, the log machine's
assembly of the blocks (``machine.LogMachine`` is this behind the machine's ports).

The row adders sum a pixel's codes per row (``RowAdders``, its ``line_start`` carried along); the sums wait
in the *issue register* and are *issued* into the argmin tree (``ArgminTree``), and on to the weights stage
(``WeightStage``), streams between. With a neighbour prior (``feedback_words``) each row also has a
feedback code, formed at the issue from the previous result (:func:`~bayesmachine.sim.model.fill_feedback`'s
rule with the flat code 0) and added to the sums in the tree's first level (``ArgminTree(feedback=True)``).

The feedback loop is the argmin tree alone: as a MAP reaches the tree's output buffer it is registered
(the tree's ``latest`` result, a copy per :data:`FEEDBACK_GROUP` rows), and a pixel with a left
neighbour issues the clock after, its feedback codes formed from those registers on the way into the
tree's first level, so such pixels issue every ``ArgminTree.latency`` clocks at most (:attr:`loop`;
``bayesmachine.integrators.log.pixel_clocks``); a line's first pixel and every pixel without a
feedback column issue as soon as their sums are ready, one per clock. The definition:
``sim.log_model.log_integrate`` of the codes (with the feedback column first), pixel by pixel in order.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from amaranth.hdl import Array, Const, Module, Mux, Signal, Value, unsigned
from amaranth.lib import data, fifo, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError
from bayesmachine.integrators.log import (
    ADDER_LEVELS_PER_STAGE,
    ARGMIN_LEVELS_PER_STAGE,
    LogParams,
    check_params,
)

from .adders import RowAdders, adder_stages
from .argmin import ArgminTree, argmin_stages
from .layouts import codes_layout, log_result_layout
from .weights import WEIGHT_STAGES, WeightStage

__all__ = ["FEEDBACK_GROUP", "LogIntegrator", "integrator_codes_layout"]

FEEDBACK_GROUP = 8  # rows whose feedback codes read one copy of the latest MAP (a net's fanout)


def integrator_codes_layout(params: LogParams, feedback: bool) -> data.Layout:
    """A pixel's loaded codes (``codes_layout`` of ``params.codes`` codes per row, one fewer with
    ``feedback``), with ``feedback`` in a struct with its ``line_start`` bit on top."""
    if not feedback:
        return codes_layout(params)
    loaded = dataclasses.replace(params, codes=params.codes - 1)
    return data.StructLayout({"codes": codes_layout(loaded), "line_start": unsigned(1)})


def _feedback_table(params: LogParams, words: object,
                    nomatch_word: object) -> tuple[tuple[int, ...], int | None]:
    """``feedback_words`` and ``feedback_nomatch_word`` checked against ``params``."""
    if isinstance(words, (str, bytes)) or not isinstance(words, Sequence):
        raise TypeError(f"feedback_words must be a sequence of codes, not {type(words).__name__}")
    table = tuple(as_int(f"feedback_words[{i}]", w, 0, params.infinite) for i, w in enumerate(words))
    if not table:
        if nomatch_word is not None:
            raise ParameterError("feedback_nomatch_word needs feedback_words", "feedback_nomatch_word")
        return table, None
    if params.codes < 2:
        raise ParameterError("a feedback column needs codes >= 2 (itself and a loaded code per row)", "codes")
    if params.nomatch_row:
        if nomatch_word is None:
            raise ParameterError("feedback_words with a no-match row need feedback_nomatch_word",
                                 "feedback_nomatch_word")
        return table, as_int("feedback_nomatch_word", nomatch_word, 0, params.infinite)
    if nomatch_word is not None:
        raise ParameterError("feedback_nomatch_word needs a no-match row (nomatch_row=True)",
                             "feedback_nomatch_word")
    return table, None


class LogIntegrator(wiring.Component):
    """The log integrator (module text): a pixel taken per clock, results in order.

    Parameters
    ----------
    params : LogParams
        The rule's parameters; ``codes`` counts the feedback column too (``params.codes - 1`` codes per
        row are loaded with ``feedback_words``).
    feedback_words : sequence of int
        A neighbour prior's feedback column: the code of a row at distance d from the previous MAP is
        ``feedback_words[min(d, len - 1)]`` (codes of ``code_bits``); empty (default): no feedback column.
    feedback_nomatch_word : int or None
        With ``feedback_words`` and a no-match row: the no-match row's feedback code; else None.
    levels_per_stage : int
        Argmin-tree levels (the feedback codes' adders one of them) between two registers (1 ... 64);
        default the log machine's, ``ARGMIN_LEVELS_PER_STAGE``.
    adder_levels_per_stage : int
        Adder-tree levels between two registers (1 ... 64); default ``ADDER_LEVELS_PER_STAGE``.

    Attributes
    ----------
    codes : ``In(stream.Signature(integrator_codes_layout(params, feedback)))``
        A pixel's loaded codes (with feedback: ``codes`` and ``line_start``, the pixel starts a line).
    result : ``Out(stream.Signature(log_result_layout(params)))``
        ``map``, ``nomatch``, ``all_excluded``, ``s_min`` and each row's ``weights``.
    line_start : ``Out(1)``
        With feedback: the ``line_start`` of the pixel whose result is offered.
    feedback : bool
        Whether there is a feedback column.
    loop : int
        Clocks between the issues of two pixels the second of which has a feedback column (the argmin
        tree's latency; 1 without feedback).
    latency : int
        Clocks from a pixel taken to its result offered, when nothing waits: the row adders', the issue
        register's 1, the argmin tree's and the weights stage's 3.
    """

    # The blocks (a proof's mutant overrides one).
    adders_block: type[RowAdders] = RowAdders
    argmin_block: type[ArgminTree] = ArgminTree
    weights_block: type[WeightStage] = WeightStage

    def __init__(self, *, params: LogParams, feedback_words: Sequence[int] = (),
                 feedback_nomatch_word: int | None = None, levels_per_stage: int = ARGMIN_LEVELS_PER_STAGE,
                 adder_levels_per_stage: int = ADDER_LEVELS_PER_STAGE) -> None:
        self._params = p = check_params(params)
        self._levels = as_int("levels_per_stage", levels_per_stage, 1, 64)
        self._adder_levels = as_int("adder_levels_per_stage", adder_levels_per_stage, 1, 64)
        self._fb_words, self._fb_nomatch = _feedback_table(p, feedback_words, feedback_nomatch_word)
        fb = self.feedback
        # The blocks' latencies, from their stage functions (elaborate builds the blocks).
        self._adder_latency = len(adder_stages(self._loaded(), self._adder_levels, int(fb)))
        self._argmin_latency = len(argmin_stages(p, self._levels, True, feedback=fb))
        members = {"codes": In(stream.Signature(integrator_codes_layout(p, fb))),
                   "result": Out(stream.Signature(log_result_layout(p)))}
        if fb:
            members["line_start"] = Out(1)
        super().__init__(members)

    @property
    def params(self) -> LogParams:
        return self._params

    def _loaded(self) -> LogParams:
        """The row adders' parameters: the loaded codes per row."""
        return dataclasses.replace(self._params, codes=self._params.codes - self.feedback)

    @property
    def feedback_words(self) -> tuple[int, ...]:
        return self._fb_words

    @property
    def feedback_nomatch_word(self) -> int | None:
        return self._fb_nomatch

    @property
    def feedback(self) -> bool:
        return bool(self._fb_words)

    @property
    def levels_per_stage(self) -> int:
        return self._levels

    @property
    def adder_levels_per_stage(self) -> int:
        return self._adder_levels

    @property
    def loop(self) -> int:
        return self._argmin_latency if self.feedback else 1

    @property
    def latency(self) -> int:
        return self._adder_latency + 1 + self._argmin_latency + WEIGHT_STAGES

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p, fb = self._params, self.feedback
        m.submodules.adders = adders = self.adders_block(params=self._loaded(), carried=int(fb),
                                                         levels_per_stage=self._adder_levels)
        copies = -(-p.rows // FEEDBACK_GROUP) if fb else 0
        m.submodules.argmin = argmin = self.argmin_block(params=p, levels_per_stage=self._levels,
                                                         pass_sums=True, feedback=fb, latest_copies=copies)
        m.submodules.weights = weights = self.weights_block(params=p)
        assert (adders.latency, argmin.latency) == (self._adder_latency, self._argmin_latency)
        wiring.connect(m, argmin.best, weights.best)
        # Pixels issued and not yet out, their line_start in order (at most every stage's plus the two
        # output buffers' entries: never full).
        depth = argmin.latency + weights.latency + 4
        m.submodules.starts = starts = fifo.SyncFIFO(width=1, depth=depth)
        m.d.comb += [adders.codes.valid.eq(self.codes.valid), self.codes.ready.eq(adders.codes.ready),
                     adders.codes.payload.eq(self.codes.payload)]
        self._issue(m, adders, argmin, starts)
        wiring.connect(m, weights.result, wiring.flipped(self.result))
        m.d.comb += starts.r_en.eq(weights.result.valid & self.result.ready)
        if self.feedback:
            m.d.comb += self.line_start.eq(starts.r_data)
        return m

    def issue_known(self, start: Value, pending: Value) -> Value:
        """Whether the next pixel's feedback codes are known: it starts a line, or no pixel is in the
        argmin tree (the last one's MAP has reached its output buffer and is its latest result)."""
        return start | (pending == 0)

    def _issue(self, m: Module, adders: RowAdders, argmin: ArgminTree, starts: fifo.SyncFIFO) -> None:
        """The next pixel's loaded sums wait in the issue register (so the loop's first stage starts at
        registers, not at the row adders' output buffer) and issue into the argmin tree when it takes them
        and (with feedback) its feedback codes are known (:meth:`issue_known`)."""
        p = self._params
        sums, into = adders.sums, argmin.sums
        held = Signal(sums.payload.shape(), name="issue_sums", reset_less=True)
        held_valid = Signal(name="issue_valid")
        view = sums.payload.shape()(held)
        issue = Signal()
        m.d.comb += sums.ready.eq(~held_valid | issue)
        with m.If(sums.ready):
            m.d.sync += [held.eq(sums.payload), held_valid.eq(sums.valid)]
        start = view.carried if self.feedback else Const(0, 1)
        if self.feedback:
            pending = Signal(range(argmin.latency + 8))
            m.d.sync += pending.eq(pending + issue - argmin.arriving)
            known = self.issue_known(start, pending)
            fb = self._feedback_codes(m, argmin, start)
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

    def _feedback_codes(self, m: Module, argmin: ArgminTree, start: Value) -> list[Value]:
        """Each row's feedback code from the argmin tree's latest MAP (the copy of the row's group): the
        table at |r − MAP| clamped, the no-match code in the no-match row; 0 when that pixel's answer is
        no match or every row was excluded (0 from reset), or at a line start."""
        p, words = self._params, self._fb_words
        last = len(words) - 1
        out = []
        for r in range(p.rows):
            latest = argmin.latest[r // FEEDBACK_GROUP]
            hit = ~latest.nomatch & ~latest.all_excluded
            code = Signal(p.code_bits, name=f"feedback{r}")
            if p.nomatch_row and r == p.rows - 1:
                value = Const(self._fb_nomatch, p.code_bits)
            else:
                # The row's code at each MAP, a lookup of the MAP's bits (no distance arithmetic, no
                # carry chain in the loop); every index of the MAP's width (a complete case: verilator
                # -Wall CASEINCOMPLETE), the ones past the rows never read (hit is 0 there).
                at = [words[min(abs(i - r), last)] for i in range(1 << p.map_width)]
                value = Array(Const(c, p.code_bits) for c in at)[latest.map]
            m.d.comb += code.eq(Mux(hit & ~start, value, 0))
            out.append(code)
        return out
