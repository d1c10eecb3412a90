"""A neighbour prior's feedback column (``prior = "neighbour"``): operator column 0, formed on chip from
the machine's previous result.

Its Python twin is the model's per-pixel rule, ``sim.model.fill_feedback`` (the column from the
previous result) after ``sim.model.feedback_result`` (which results are a hypothesis);
``tests/hdl/machine/test_feedback.py`` holds the component to it.
"""

from __future__ import annotations

from amaranth.hdl import Array, Const, Module, Mux, Signal, unsigned
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.params import MachineParams, ParameterError

from .nets import row_groups

__all__ = ["FeedbackPrior"]


class FeedbackPrior(wiring.Component):
    """The feedback column of a neighbour prior, formed at each swap from the previous result.

    The bubble's hand-over (``leave``) registers the winning row (``previous_rows``, a copy per group
    of rows: one register would fan out to every row's distance logic, and the flow keeps the
    ``_rep`` copies apart) and whether it is a hypothesis row (``previous_valid``: the encoder found a
    row, the run did not time out, not the no-match row). The next cycle (``settle``) registers each
    row's word (``registered_words``): ``feedback_words[min(|r - previous row|, last)]``, the no-match
    row's ``feedback_nomatch_word``, or 1.0 everywhere without a previous hypothesis (after reset too).
    The swap, a cycle later still, takes ``words``: those, or 1.0 everywhere when the pixel starts a
    line. So the swap's path is the same as a loaded word's (a register, a comparator), and the
    subtraction, clamp and table per row have a cycle of their own.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters; its prior must be ``"neighbour"`` (``feedback_columns`` 1).

    Attributes
    ----------
    leave : ``In(1)``
        The bubble hands its result over (``map``, ``valid`` and ``timed_out`` are that result's).
    map : ``In(params.map_width)``
        The winning row.
    valid : ``In(1)``
        The MAP encoder found a row (a run that timed out without an answer: 0).
    timed_out : ``In(1)``
        The run timed out though the encoder found a row (``timeout_answer = "leading"``: its answer,
        the leading row, is no hypothesis); 0 otherwise.
    line_start : ``In(1)``
        The shadow's pixel starts a line (no left neighbour).
    words : ``Out(unsigned(params.memory_word_width)).array(params.rows)``
        The feedback column the swap takes, one word per row.
    settle : ``Out(1)``
        The feedback words are being registered (the cycle after ``leave``): no swap.
    previous_rows, previous_valid, registered_words : list of Signal
        The registers above, read-only (in the nets ``BayesianMachine.build`` returns: a proof relates
        them to its reference).
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"FeedbackPrior takes a MachineParams, not {type(params).__name__}")
        if not params.feedback_columns:
            raise ParameterError(f"FeedbackPrior needs a neighbour prior, not prior {params.prior!r}",
                                 "prior")
        self._params = params
        _, groups = row_groups(params)
        self._previous_rows = [Signal(params.map_width, name=f"prev_row_rep{g}") for g in range(groups)]
        self._previous_valid = [Signal(name=f"prev_valid_rep{g}") for g in range(groups)]
        self._registered = [Signal(params.memory_word_width, name=f"feedback_q_{r}", init=params.word_one)
                            for r in range(params.rows)]
        super().__init__({
            "leave": In(1), "map": In(params.map_width), "valid": In(1), "timed_out": In(1),
            "line_start": In(1),
            "words": Out(unsigned(params.memory_word_width)).array(params.rows),
            "settle": Out(1),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def previous_rows(self) -> list[Signal]:
        return list(self._previous_rows)

    @property
    def previous_valid(self) -> list[Signal]:
        return list(self._previous_valid)

    @property
    def registered_words(self) -> list[Signal]:
        return list(self._registered)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p = self._params
        rows_per_group, _ = row_groups(p)
        with m.If(self.leave):
            # A timeout's leading row is its answer, not information.
            hypothesis = self.valid & ~self.timed_out
            if p.nomatch_row:
                hypothesis = hypothesis & (self.map != p.rows - 1)
            m.d.sync += ([c.eq(self.map) for c in self._previous_rows]
                         + [c.eq(hypothesis) for c in self._previous_valid])
        m.d.sync += self.settle.eq(self.leave)
        one = Const(p.word_one, p.memory_word_width)
        table = p.feedback_words
        last = len(table) - 1
        for r, word_q in enumerate(self._registered):
            prev_row = self._previous_rows[r // rows_per_group]
            prev_valid = self._previous_valid[r // rows_per_group]
            if p.nomatch_row and r == p.rows - 1:
                m.d.sync += word_q.eq(Mux(prev_valid, p.feedback_nomatch_word, one))
            else:
                dist = Signal(p.map_width, name=f"feedback_dist_{r}")
                m.d.comb += dist.eq(Mux(prev_row > r, prev_row - r, r - prev_row))
                # The table clamped by padding it with its last word to every distance the index can
                # take: the same words as min(dist, last), and a complete case (verilator -Wall).
                entries = Array(Const(table[min(i, last)], p.memory_word_width)
                                for i in range(1 << p.map_width))
                m.d.sync += word_q.eq(Mux(prev_valid, entries[dist], one))
            m.d.comb += self.words[r].eq(Mux(self.line_start, one, word_q))
        return m
