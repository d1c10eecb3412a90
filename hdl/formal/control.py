# amaranth: UnusedElaboratable=no
"""The machine's control, checked against a reference run beside it (a scoreboard), from its ports only.

``ControlProperties`` puts a small ``BayesianMachine`` (numbers on the ``entropy`` port, free) next
to a reference written here from the machine's definition alone: it assembles the pixels from the
load stream's handshakes, starts a run on each burst of ``entropy_ready`` (the machine's compute
cycles) with the next pixel it assembled, and runs it one sample at a time: B samples per compute
cycle (``samples_per_clock``), sample i comparing the port's i-th number of each operator with the
pixel's word, each row's 1s counted, the run stopping at the first sample where a row overflows (the
tie rule among the rows overflowing there) or at sample ``max_cycles``, the counts those at that
sample. It queues the result the machine must give: its map (a timeout's: 0, or with
``timeout_answer = "leading"`` the row of the largest count by the tie rule), flags, counts and
compute cycles (clocks). Every property is stated on ports (load, entropy, result), none on the
machine's internal registers, so it holds for any implementation of the same timing contract
(``docs/architecture.md``, "Timing"); the strengthening invariants that let k-induction close read
the machine's internal registers through the nets its builder returns
(:meth:`~bayesmachine.hdl.machine.BayesianMachine.build`).

With a neighbour prior (``prior = "neighbour"``) the reference forms the feedback column itself
from its own previous result (``feedback_words[min(|r - map|, last)]``, the no-match row's
``feedback_nomatch_word``, 1.0 after a timeout (answered or not), a no-match result, a reset, or on a
pixel whose last beat has ``line_start``): a result that matches the reference's shows the feedback
word was the table entry of the previous MAP.

Only the load stream's own rule is assumed (its source holds ``valid`` and the payload until
``ready``); ``result.ready``, the numbers and the reset are free.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from amaranth.hdl import Array, Assert, Assume, Cat, Const, Cover, Module, Mux, Shape, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.machine import (
    BUBBLE_CYCLES,
    FEEDBACK_CYCLES,
    LOAD_LATENCY,
    BayesianMachine,
    MachineNets,
    search_cycles,
)
from bayesmachine.hdl.signatures import beat_words, entropy_layout, load_layout, result_layout
from bayesmachine.params import MachineParams
from bayesmachine.sources import source_kind

__all__ = ["ControlProperties", "MachineFactory", "queue"]

MachineFactory = Callable[..., BayesianMachine]


def queue(m: Module, name: str, width: int, depth: int, push: Value, data: Value,
          pop: Value) -> tuple[Signal, list[Signal], Value]:
    """A reference FIFO of ``depth`` entries of ``width`` bits in the wrapper: returns ``(count,
    entries, overflow)`` (``entries[0]`` the head); a pop and a push in one cycle are both done
    (the pop first). ``overflow`` is a push into a full queue (the caller asserts it never
    happens: the queue then stays exact)."""
    entries = [Signal(width, name=f"{name}_{i}") for i in range(depth)]
    count = Signal(range(depth + 1), name=f"{name}_count")
    with m.If(pop & (count != 0)):
        for i in range(depth - 1):
            m.d.sync += entries[i].eq(entries[i + 1])
        with m.If(push):
            m.d.sync += Array(entries)[count - 1].eq(data)
        with m.Else():
            m.d.sync += count.eq(count - 1)
    with m.Elif(push & (count != depth)):
        m.d.sync += [Array(entries)[count].eq(data), count.eq(count + 1)]
    overflow = push & ~(pop & (count != 0)) & (count == depth)
    return count, entries, overflow


def _largest(values: list[Value]) -> Value:
    """The largest of unsigned values (a chain of compares: the wrapper's machines are small)."""
    best = values[0]
    for v in values[1:]:
        best = Mux(v > best, v, best)
    return best


def tie_rule(params: MachineParams, rows: Value) -> Value:
    """The row the MAP encoder picks among ``rows`` (a bit per row): the lowest, or under
    nomatch-first the no-match row when it is among them (0 when none is set)."""
    winner: Value = Const(0, params.map_width)
    for r in reversed(range(params.rows)):
        winner = Mux(rows[r], r, winner)
    if params.nomatch_row and params.tie_break == "nomatch-first":
        winner = Mux(rows[params.rows - 1], params.rows - 1, winner)
    return winner


@dataclass
class _Reference:
    """The reference's state and this cycle's values (see :meth:`ControlProperties.elaborate`)."""

    pq_count: Signal  # the pixels assembled and not yet run (a queue)
    pq_head: Signal  # the next pixel: its words and its line_start flag
    pq_over: Value
    run_start: Value  # a run's first compute cycle
    compute: Value  # a compute cycle (the machine's entropy_ready)
    was_compute: Signal
    asm: list[Signal]  # the words of the pixel being assembled
    beat: Signal  # the beat the next handshake carries
    accept: Value
    cnt_now: list[Value] | None = None  # the counters at this cycle's start
    cyc_now: Value | None = None  # the compute cycles done before this one
    op_words: list[Value] | None = None  # the run's operator words
    fed: list[Value] | None = None  # a neighbour prior's feedback words
    prev_row: Signal | None = None
    prev_valid: Signal | None = None
    finish: Value | None = None  # this compute cycle ends the run
    end: Value | None = None
    hit: Value | None = None  # the run ends with an overflow
    over: Value | None = None  # the rows overflowing at the stop sample
    late_ties: Value | None = None  # a row overflows later in the stop's cycle
    expected: Signal | None = None
    rq_count: Signal | None = None  # the results due and not yet taken
    rq: list[Signal] | None = None
    rq_over: Value | None = None
    unoffered: Signal | None = None  # cycles in a row with a result due and none offered


class ControlProperties(wiring.Component):
    """A formal-only wrapper: a machine with free inputs and a reference run beside it.

    Parameters
    ----------
    params : MachineParams
        The machine the reference describes (``rng = "external"``; any prior, samples per clock and
        timeout answer).
    machine : callable
        Builds the machine under check from a ``params`` keyword; ``BayesianMachine`` unless a
        mutant is being checked (a subclass: the invariants read its ``nets``).
    dut_params : MachineParams or None
        The parameters the machine is built with (default ``params``; a mutant may differ).

    Attributes
    ----------
    load_valid, load_payload, result_ready, entropy : ``In``
        The environment (free; the load source follows the stream rule).
    result_valid, result_payload, entropy_ready : ``Out``
        The machine's outputs, for the trace.
    """

    def __init__(self, *, params: MachineParams, machine: MachineFactory = BayesianMachine,
                 dut_params: MachineParams | None = None) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
        if source_kind(params.rng).on_chip:
            raise ValueError(f"the formal machine takes its numbers on a port (rng 'external'), "
                             f"not {params.rng!r}")
        dut_params = params if dut_params is None else dut_params
        if result_layout(dut_params).size != result_layout(params).size:
            raise ValueError("dut_params must keep the result's width")
        self._params = params
        self._dut = machine(params=dut_params)
        super().__init__({
            "load_valid": In(1), "load_payload": In(load_layout(params)), "result_ready": In(1),
            "entropy": In(entropy_layout(params)),
            "result_valid": Out(1), "result_payload": Out(result_layout(params)), "entropy_ready": Out(1),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dut = self._dut
        # Built here, with the nets the strengthening invariants below read.
        m.submodules.dut, nets = dut.build(platform)
        m.d.comb += [
            dut.load.valid.eq(self.load_valid), dut.load.payload.eq(self.load_payload),
            dut.result.ready.eq(self.result_ready), dut.entropy.eq(self.entropy),
            self.result_valid.eq(dut.result.valid), self.result_payload.eq(dut.result.payload),
            self.entropy_ready.eq(dut.entropy_ready),
        ]
        ref = self._assemble(m, dut.load.ready)
        self._reference_run(m, ref)
        self._port_properties(m, ref)
        self._load_invariants(m, ref, nets)
        self._run_invariants(m, ref, nets)
        self._covers(m, ref)
        return m

    def _assemble(self, m: Module, load_ready: Value) -> _Reference:
        """The environment (the load stream's rule) and the pixels assembled from its handshakes."""
        p = self._params
        nbeats, ww = p.beats_per_pixel, p.memory_word_width
        npix = p.words_per_pixel * ww
        load_stall = Signal()
        load_prev = Signal.like(self.load_payload)
        m.d.sync += [load_stall.eq(self.load_valid & ~load_ready), load_prev.eq(self.load_payload)]
        with m.If(load_stall):
            m.d.comb += Assume(self.load_valid & (self.load_payload.as_value() == load_prev.as_value()))

        accept = self.load_valid & load_ready
        beat = Signal(range(max(2, nbeats)))  # the beat the next handshake carries
        asm = [Signal(ww, name=f"asm_{w}") for w in range(p.words_per_pixel)]  # the pixel's words so far
        words_in = beat_words(p, self.load_payload)
        pixel_words: list[Value] = []  # the complete pixel, in the cycle of its last beat
        for w in range(p.words_per_pixel):
            b, lane = divmod(w, p.words_per_beat)
            pixel_words.append(words_in[lane] if b == nbeats - 1 else asm[w])
        with m.If(accept):
            m.d.sync += beat.eq(Mux(beat == nbeats - 1, 0, beat + 1))
            for w in range(p.words_per_pixel):
                b, lane = divmod(w, p.words_per_beat)
                if b < nbeats - 1:
                    with m.If(beat == b):
                        m.d.sync += asm[w].eq(words_in[lane])
        line_start = self.load_payload.line_start if p.feedback_columns else Const(0, 1)
        complete = accept & (beat == nbeats - 1)
        compute = self.entropy_ready
        was_compute = Signal()
        m.d.sync += was_compute.eq(compute)
        run_start = compute & ~was_compute
        pq_count, pq, pq_over = queue(m, "pixels", npix + 1, 2, complete, Cat(*pixel_words, line_start),
                                      run_start)
        return _Reference(pq_count=pq_count, pq_head=pq[0], pq_over=pq_over, run_start=run_start,
                          compute=compute, was_compute=was_compute, asm=asm, beat=beat, accept=accept)

    def _operator_words(self, m: Module, ref: _Reference) -> None:
        """The run's pixel (taken from the queue at its first compute cycle) as operator words, a
        neighbour prior's feedback column formed from the reference's previous result."""
        p = self._params
        ww, fb, loaded, last = p.memory_word_width, p.feedback_columns, p.loaded_columns, p.rows - 1
        act = Signal(p.words_per_pixel * ww + 1)
        pix = Mux(ref.run_start, ref.pq_head, act)
        with m.If(ref.run_start):
            m.d.sync += act.eq(ref.pq_head)
        one = Const(p.word_one, ww)
        ref.prev_row, ref.prev_valid = Signal(p.map_width), Signal()
        # A neighbour prior's feedback word per row: the table entry at the distance to the
        # previous MAP (the no-match row's own word), 1.0 without a previous hypothesis.
        ref.fed = []
        if fb:
            table = Array(Const(w, ww) for w in p.feedback_words)
            top = len(p.feedback_words) - 1
            for r in range(p.rows):
                if p.nomatch_row and r == last:
                    ref.fed.append(Mux(ref.prev_valid, p.feedback_nomatch_word, one))
                else:
                    dist = Mux(ref.prev_row > r, ref.prev_row - r, r - ref.prev_row)
                    ref.fed.append(Mux(ref.prev_valid, table[Mux(dist > top, top, dist)], one))
        ref.op_words = []
        for r in range(p.rows):
            for c in range(p.operator_columns):
                if c < fb:
                    ref.op_words.append(Mux(pix[-1], one, ref.fed[r]))  # line_start: no left neighbour
                else:
                    w = r * loaded + c - fb
                    ref.op_words.append(pix[w * ww:(w + 1) * ww])

    def _reference_run(self, m: Module, ref: _Reference) -> None:
        """The run, one sample at a time: B per compute cycle, each counted only if the run has not
        stopped at an earlier sample of the cycle; and the result it must give."""
        p = self._params
        rows, cols, ops = p.rows, p.operator_columns, p.operators
        b, n_max = p.samples_per_clock, p.counter_max
        self._operator_words(m, ref)
        cnt = [Signal(p.counter_width, name=f"ref_count_{r}") for r in range(rows)]
        cyc = Signal(p.cycle_width)
        ref.cnt_now = [Mux(ref.run_start, 0, c) for c in cnt]
        ref.cyc_now = Mux(ref.run_start, 0, cyc)
        counts: list[Value] = list(ref.cnt_now)
        stopped: Value = Const(0)
        over: Value = Const(0, rows)
        hit: Value = Const(0)
        late: Value = Const(0)
        for i in range(b):
            bus = []
            for r in range(rows):
                bit = Const(1, 1)
                for c in range(cols):
                    o = r * cols + c
                    bit = bit & (self.entropy[i * ops + o] < ref.op_words[o])  # the stochastic operator
                bus.append(bit)
            over_i = Cat(bus[r] & (counts[r] == n_max) for r in range(rows))
            late = late | (stopped & over_i.any())
            # Each sample's values are nets of their own (each is read several times by the next).
            nxt = [Signal(p.counter_width, name=f"ref_count_{r}_s{i}") for r in range(rows)]
            m.d.comb += [n.eq(Mux(~stopped & bus[r] & (counts[r] != n_max), counts[r] + 1, counts[r]))
                         for r, n in enumerate(nxt)]
            watchdog = ref.cyc_now * b + (i + 1) == p.max_cycles  # sample max_cycles
            over_n, hit_n, stopped_n = Signal(rows, name=f"ref_over_s{i}"), Signal(), Signal()
            m.d.comb += [over_n.eq(Mux(stopped, over, over_i)), hit_n.eq(hit | (~stopped & over_i.any())),
                         stopped_n.eq(stopped | over_i.any() | watchdog)]
            counts, over, hit, stopped = nxt, over_n, hit_n, stopped_n
        ref.finish, ref.hit, ref.over, ref.late_ties = stopped, hit, over, late
        with m.If(ref.compute):
            m.d.sync += [c.eq(x) for c, x in zip(cnt, counts, strict=True)]
            m.d.sync += cyc.eq(ref.cyc_now + 1)
        self._expected(m, ref, counts)

    def _expected(self, m: Module, ref: _Reference, counts: list[Value]) -> None:
        """The result the machine must give: the MAP by the tie rule among the rows overflowing at the
        stop sample; a timeout's 0, or its leading row (the largest count, the tie rule among them)."""
        p = self._params
        last = p.rows - 1
        winner = tie_rule(p, ref.over)
        answered = ref.hit
        if p.timeout_answer == "leading":
            best = _largest(counts)
            winner = Mux(ref.hit, winner, tie_rule(p, Cat(c == best for c in counts)))
            answered = Const(1)
        ref.expected = expected = Signal(result_layout(p))
        m.d.comb += [
            expected.map.eq(Mux(answered, winner, 0)),
            expected.timeout.eq(~ref.hit),
            expected.cycles.eq(ref.cyc_now + 1),
            expected.counts.eq(Cat(*counts)),
            expected.nomatch.eq(answered & (winner == last) if p.nomatch_row else 0),
        ]
        ref.end = ref.compute & ref.finish
        with m.If(ref.end):
            # The next pixel's feedback follows an overflowing run's hypothesis only.
            hypothesis = ref.hit & (winner != last) if p.nomatch_row else ref.hit
            m.d.sync += [ref.prev_row.eq(winner), ref.prev_valid.eq(hypothesis)]
        taken = self.result_valid & self.result_ready
        width = Shape.cast(result_layout(p)).width
        ref.rq_count, ref.rq, ref.rq_over = queue(m, "results", width, 2, ref.end, expected.as_value(), taken)

    def _port_properties(self, m: Module, ref: _Reference) -> None:
        """What the ports must show: runs start on complete pixels, stop at their stop sample's cycle,
        and each result taken is the reference's next one; no result lost, no idle time."""
        p = self._params
        valid, res = self.result_valid, self.result_payload
        # A run starts only with a complete pixel loaded and not yet run: the swap never takes an
        # incomplete shadow, and no pixel is run twice or skipped (its words are the ones the
        # reference assembled: checked through the results and the active memory below).
        with m.If(ref.run_start):
            m.d.comb += Assert(ref.pq_count != 0, "a run starts only on a complete loaded pixel")
        # At most one complete pixel waits (the shadow): the load stream takes no beat of the next
        # pixel while it would overwrite one (no beat lost).
        m.d.comb += Assert(~ref.pq_over & (ref.pq_count <= 1), "at most one loaded pixel waits for its run")
        # The run's length: it goes on while no row overflows and fewer than max_cycles samples were
        # taken, and stops right after the cycle of its first overflow or of sample max_cycles (the
        # watchdog fires there and only there); a compute cycle never waits for anything.
        go_on = Signal()
        m.d.sync += go_on.eq(~ref.finish)
        with m.If(ref.was_compute):
            m.d.comb += Assert(ref.compute == go_on,
                               "a run stops exactly at its first overflow or at max_cycles")
        # Each result taken is the reference's next result: the k-th result is the k-th loaded
        # pixel's, in order, its map by the tie rule, its counts the counters at the stop sample, its
        # cycles the run's compute cycles; no result without a run. (Checked whenever a result is
        # offered: back-pressure then holds it, proved by the stream group of MachineProperties.)
        head = Signal(result_layout(p))
        m.d.comb += head.eq(ref.rq[0])
        with m.If(valid):
            m.d.comb += [
                Assert(ref.rq_count != 0, "no result without a run"),
                Assert(res.map == head.map, "the result's map is the reference's"),
                Assert(res.timeout == head.timeout, "the result's timeout is the reference's"),
                Assert(res.nomatch == head.nomatch, "the result's nomatch is the reference's"),
                Assert(res.cycles == head.cycles, "the result's cycles are its run's compute cycles"),
                Assert(res.counts.as_value() == head.counts.as_value(),
                       "the result's counts are the counters at the stop"),
            ]
        m.d.comb += Assert(~ref.rq_over & (ref.rq_count <= 2),
                           "at most two finished runs wait for the result stream")
        # No result lost: a finished run's result is offered at once (the bubble hands it over; a
        # leading answer's after its search) or, if the result register is full, as soon as it empties.
        limit = 1 + search_cycles(p)
        ref.unoffered = unoffered = Signal(range(limit + 2))
        m.d.sync += unoffered.eq(Mux((ref.rq_count != 0) & ~valid, Mux(unoffered > limit, unoffered,
                                                                          unoffered + 1), 0))
        m.d.comb += Assert(~((unoffered >= limit) & (ref.rq_count != 0) & ~valid),
                           "a finished run's result is offered")
        # No idle time: a machine with no run nor bubble pending (port view: not computing, and every
        # finished run's result in the result register) starts a complete pixel at once; loaded
        # LOAD_LATENCY + 1 cycles ago it starts in that cycle, so a run follows the previous one's
        # bubble directly (the bubble is one cycle; a neighbour prior's swap is FEEDBACK_CYCLES later).
        idle = ~ref.compute & (ref.rq_count == valid)
        idle_age = Signal(range(4))
        pq_age = Signal(range(4))
        m.d.sync += idle_age.eq(Mux(idle, Mux(idle_age == 3, 3, idle_age + 1), 0))
        m.d.sync += pq_age.eq(Mux((ref.pq_count != 0) & ~ref.run_start, Mux(pq_age == 3, 3, pq_age + 1), 0))
        m.d.comb += Assert(~(idle & (idle_age + 1 >= 1 + FEEDBACK_CYCLES * p.feedback_columns)
                             & (ref.pq_count != 0) & (pq_age + 1 >= LOAD_LATENCY + 2)),
                           "no idle cycle with a complete pixel")

    def _load_invariants(self, m: Module, ref: _Reference, n: MachineNets) -> None:
        """Strengthening invariants of the load side: the machine's beat is the reference's, and the
        shadow as it will be once the beat in flight is written holds the beats taken so far."""
        p = self._params
        nbeats, npix = p.beats_per_pixel, p.words_per_pixel * p.memory_word_width
        load_q = data.View(load_layout(p), n.load_q)
        m.d.comb += Assert(ref.beat < nbeats, "the reference's beat is a beat")
        m.d.comb += Assert(n.beat == (Const(1, nbeats + 1) << ref.beat)[:nbeats],
                           "the machine's beat is the reference's")
        q_words = beat_words(p, load_q)
        eff = []
        for w in range(p.words_per_pixel):
            b, lane = divmod(w, p.words_per_beat)
            eff.append(Mux(n.write_q[b], q_words[lane], n.shadow[w]))
        pending = n.shadow_full | n.write_q[nbeats - 1]
        m.d.comb += Assert(ref.pq_count == (pending | ref.run_start), "the pixel waiting is in the shadow")
        with m.If(pending):
            m.d.comb += Assert(Cat(*eff) == ref.pq_head[:npix], "the shadow holds the pixel's beats")
            m.d.comb += Assert(ref.beat == 0, "no beat taken while a pixel waits")
            if p.feedback_columns:
                ls = Mux(n.write_q[nbeats - 1], load_q.line_start, n.shadow_line_start)
                m.d.comb += Assert(ls == ref.pq_head[-1], "the shadow's line_start")
        for w in range(p.words_per_pixel):
            b = w // p.words_per_beat
            if b < nbeats - 1:
                with m.If(ref.beat > b):
                    m.d.comb += Assert(eff[w] == ref.asm[w], f"shadow word {w} holds its beat")
        expect_write = Signal(nbeats)
        m.d.sync += expect_write.eq(Mux(ref.accept, (Const(1, nbeats + 1) << ref.beat)[:nbeats], 0))
        m.d.comb += Assert(n.write_q == expect_write, "each beat taken is written once, the cycle after")

    def _run_invariants(self, m: Module, ref: _Reference, n: MachineNets) -> None:
        """Strengthening invariants of the run: the registered enables' copies are the enables, the
        counters and their flags the reference's, and a bubble holds the reference's next result."""
        p = self._params
        b, n_max = p.samples_per_clock, p.counter_max
        for g in range(n.groups):
            m.d.comb += Assert(n.compute_rep[g] == n.compute, "compute enable copy")
            m.d.comb += Assert(n.start_rep[g] == n.start, "start enable copy")
        for r in range(p.rows):
            if b == 1:
                m.d.comb += Assert(n.full[r] == (n.counts[r] == n_max), f"full flag {r}")
            else:
                room = n_max - n.counts[r]
                m.d.comb += Assert(n.room[r] == Mux(room > 2 * b, 2 * b, room), f"room {r}")
        m.d.comb += Assert(~n.stop | n.running, "a stop only in a run")
        if n.search is not None:
            m.d.comb += Assert(~n.search | n.stop, "a search only in a bubble")
        with m.If(ref.compute):
            m.d.comb += Assert(Cat(*n.active) == Cat(*ref.op_words),
                               "the active memory holds the run's pixel")
            for r in range(p.rows):
                m.d.comb += Assert(n.counts[r] == ref.cnt_now[r], f"counter {r} is the reference's")
            m.d.comb += Assert(n.cycles_done == ref.cyc_now, "the cycle count is the reference's")
            m.d.comb += Assert(n.at_last == (ref.cyc_now == p.max_clocks - 1), "the watchdog's flag")
        # A bubble holds the finished run whose result is not in the result register yet.
        m.d.comb += Assert(ref.rq_count == self.result_valid + n.stop,
                           "the results waiting: the register's and the bubble's")
        m.d.comb += Assert(n.cycles_done <= p.max_clocks, "the cycle count stays within max_clocks")
        # The bubble's result has waited no longer than its search has run (0 without a search).
        elapsed: Value = Const(0)
        if n.search is not None:
            width = p.counter_width
            before = sum(Mux(n.search_bit[j], 2 * (width - 1 - j), 0) for j in range(width))
            elapsed = Mux(n.search, before + n.search_phase, 2 * width)
        with m.If(n.stop & ~self.result_valid):
            m.d.comb += Assert(ref.unoffered <= elapsed, "the bubble's result waits for its search only")
        pend = Signal(result_layout(p))
        m.d.comb += pend.eq(Mux(self.result_valid, ref.rq[1], ref.rq[0]))
        searching = n.search if n.search is not None else Const(0)
        with m.If(n.stop):
            nomatch = (n.valid_q & (n.winner == p.rows - 1)) if p.nomatch_row else 0
            m.d.comb += [
                Assert(searching | (pend.nomatch == nomatch), "bubble: no match"),
                Assert(n.cycles_done == pend.cycles, "bubble: the cycle count"),
                Assert(Cat(*n.counts) == pend.counts.as_value(), "bubble: the counters"),
            ]
            if p.timeout_answer == "leading":
                self._search_invariants(m, n, pend)
            else:
                m.d.comb += [Assert(n.valid_q == ~pend.timeout, "bubble: the encoder's valid"),
                             Assert(pend.map == Mux(n.valid_q, n.winner, 0), "bubble: the encoder's choice")]
        if p.feedback_columns:
            self._feedback_invariants(m, ref, n, pend)

    def _search_invariants(self, m: Module, n: MachineNets, pend: Signal) -> None:
        """In the bubble of a timed-out run, the leading answer's search: before bit j is looked at,
        the candidates are the rows whose counts agree with the largest above bit j; the search's
        per-group flags hold whether a candidate has bit j; once done, the candidates are the rows of
        the largest count, of which the encoder picks the answer."""
        p = self._params
        width = p.counter_width
        m.d.comb += Assert(n.timed_out == pend.timeout, "bubble: the run timed out")
        if p.nomatch_row:
            m.d.comb += Assert(pend.nomatch == (pend.map == p.rows - 1), "bubble: an answer's no match")
        with m.If(~n.timed_out):
            m.d.comb += [Assert(n.valid_q, "bubble: the encoder's valid"),
                         Assert(pend.map == n.winner, "bubble: the encoder's choice"), Assert(~n.search)]
        with m.Elif(~n.search):
            m.d.comb += Assert(pend.map == n.winner, "bubble: the encoder's choice once searched")

        def candidates(j: int) -> Value:  # rows whose counts agree with the largest above bit j - 1
            tops = [c >> j for c in n.counts]
            best = _largest(tops)
            return Cat(t == best for t in tops)

        for j in range(width):
            with m.If(n.timed_out & n.search & n.search_bit[j]):
                m.d.comb += Assert(n.over_q == candidates(j + 1), f"search: the candidates above bit {j}")
                with m.If(n.search_phase):
                    for g, flag in enumerate(n.search_any):
                        group = range(g * n.rows_per_group, min(p.rows, (g + 1) * n.rows_per_group))
                        has = Cat(n.over_q[r] & n.counts[r][j] for r in group).any()
                        m.d.comb += Assert(flag == has, f"search: group {g} has bit {j}")
        with m.If(n.search):
            m.d.comb += Assert(pend.map == tie_rule(p, candidates(0)), "search: the answer it will find")
            one_hot = n.search_bit.any() & ((n.search_bit & (n.search_bit - 1)) == 0)
            m.d.comb += Assert(one_hot & n.timed_out, "a search's bit is one-hot, after a timeout")
        with m.If(n.timed_out & ~n.search):
            m.d.comb += Assert(n.over_q == candidates(0), "search done: the rows of the largest count")
            m.d.comb += Assert((n.search_bit == 0) & ~n.search_phase, "search done: past bit 0")

    def _feedback_invariants(self, m: Module, ref: _Reference, n: MachineNets, pend: Signal) -> None:
        """A neighbour prior: the previous result as the machine keeps it (from the bubble on) and its
        feedback words (a cycle later) are the reference's, outside the bubble and the cycle after."""
        p = self._params
        last = p.rows - 1
        with m.If(n.stop):
            hyp = ~pend.timeout & (pend.map != last) if p.nomatch_row else ~pend.timeout
            m.d.comb += Assert(ref.prev_valid == hyp, "bubble: the reference's previous hypothesis")
            with m.If(hyp):
                m.d.comb += Assert(ref.prev_row == pend.map, "bubble: the reference's previous MAP")
        with m.Else():
            for g in range(n.groups):
                m.d.comb += Assert(n.prev_valids[g] == ref.prev_valid, "previous hypothesis")
                with m.If(ref.prev_valid):
                    m.d.comb += Assert(n.prev_rows[g] == ref.prev_row, "previous MAP")
            with m.If(~n.settle):
                for r in range(p.rows):
                    m.d.comb += Assert(n.feedback_q[r] == ref.fed[r],
                                       f"feedback word {r} is the table entry of the previous MAP")

    def _covers(self, m: Module, ref: _Reference) -> None:
        """Not vacuous: a result taken after a stall; a run directly after the previous one's bubble
        (the one-cycle bubble; with a neighbour prior, FEEDBACK_CYCLES later); a timeout; a tie of the
        no-match row with a disparity row at the stop; two results taken; with B samples, a stop
        before the cycle's last sample with a row that would overflow later in it."""
        p = self._params
        valid, ready, res = self.result_valid, self.result_ready, self.result_payload
        taken = valid & ready
        stalled = Signal()
        m.d.sync += stalled.eq(valid & ~ready)
        m.d.comb += Cover(stalled & taken)
        gap = Signal(range(8))  # non-compute cycles since the last run's last compute cycle
        with m.If(ref.compute):
            m.d.sync += gap.eq(0)
        with m.Elif((gap != 0) | ref.was_compute):
            m.d.sync += gap.eq(Mux(gap == 7, 7, gap + 1))
        m.d.comb += Cover(ref.run_start & (gap == BUBBLE_CYCLES + FEEDBACK_CYCLES * p.feedback_columns))
        m.d.comb += Cover(taken & res.timeout)
        if p.timeout_answer == "leading":
            m.d.comb += Cover(taken & res.timeout & (res.map != 0))
        if p.nomatch_row:
            m.d.comb += Cover(ref.end & ref.over[p.rows - 1] & ref.over[:p.rows - 1].any())
        if p.samples_per_clock > 1:
            m.d.comb += Cover(ref.end & ref.hit & ref.late_ties)
        n_taken = Signal(2)
        with m.If(taken & (n_taken != 3)):
            m.d.sync += n_taken.eq(n_taken + 1)
        m.d.comb += Cover(n_taken == 2)
        if p.feedback_columns:
            # A run whose feedback words come from a previous hypothesis.
            m.d.comb += Cover(ref.run_start & ref.prev_valid & ~ref.pq_head[-1])
