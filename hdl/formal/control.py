"""The machine's control, checked against a reference run beside it (a scoreboard), from its ports only.

``ControlProperties`` puts a small ``BayesianMachine`` (numbers on the ``entropy`` port, free) next
to a reference written here from the machine's definition alone: it assembles the pixels from the
load stream's handshakes, starts a run on each burst of ``entropy_ready`` (the machine's compute
cycles) with the next pixel it assembled, evaluates the stochastic bus from the port's numbers and
that pixel's words, counts each row's 1s, stops on the first overflow or at ``max_cycles``, and
queues the result the machine must give. Every property is stated on ports (load, entropy,
result), none on the machine's internal registers, so it holds for any implementation of the
same timing contract (``docs/architecture.md``, "Timing").

With a neighbour prior (``prior = "neighbour"``) the reference forms the feedback column itself
from its own previous result (``feedback_words[min(|r - map|, last)]``, the no-match row's
``feedback_nomatch_word``, 1.0 after a timeout, a no-match result, a reset, or on a pixel whose
last beat has ``line_start``): a result that matches the reference's shows the feedback word was
the table entry of the previous MAP.

Only the load stream's own rule is assumed (its source holds ``valid`` and the payload until
``ready``); ``result.ready``, the numbers and the reset are free.
"""

from __future__ import annotations

from collections.abc import Callable

from amaranth.hdl import Array, Assert, Assume, Cat, Const, Cover, Fragment, Module, Mux, Shape, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.machine import BUBBLE_CYCLES, FEEDBACK_CYCLES, LOAD_LATENCY, BayesianMachine
from bayesmachine.hdl.signatures import beat_words, entropy_layout, load_layout, result_layout
from bayesmachine.params import MachineParams
from bayesmachine.sources import source_kind

__all__ = ["ControlProperties", "MachineFactory", "queue"]

MachineFactory = Callable[..., wiring.Component]


def driven(block: Fragment | Module, domain: str | None = None) -> dict[str, Signal]:
    """The signals an elaborated fragment's (or a module's) own statements drive (in ``domain``, or
    any), by name: a local register of ``elaborate`` that an invariant or a mutant needs (a name
    driven twice is left out)."""
    found: dict[str, Signal] = {}
    twice: set[str] = set()
    statements_of = block.statements if isinstance(block, Fragment) else block._statements
    for name, statements in statements_of.items():
        if domain is not None and name != domain:
            continue
        for stmt in statements:
            for sig in stmt._lhs_signals():
                if sig.name in found and found[sig.name] is not sig:
                    twice.add(sig.name)
                found[sig.name] = sig
    return _Driven({k: v for k, v in found.items() if k not in twice})


class _Driven(dict):
    """A name the block no longer drives (the RTL moved on) is a clear error, not a bare KeyError."""

    def __missing__(self, name: str) -> Signal:
        raise KeyError(f"no signal named {name!r} is driven (once) by this block: the RTL changed; update "
                       "the formal wrapper or mutant that watches it (hdl/formal)")


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


class ControlProperties(wiring.Component):
    """A formal-only wrapper: a machine with free inputs and a reference run beside it.

    Parameters
    ----------
    params : MachineParams
        The machine the reference describes (``rng = "external"``; any prior).
    machine : callable
        Builds the machine under check from a ``params`` keyword; ``BayesianMachine`` unless a
        mutant is being checked.
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
        p = self._params
        m = Module()
        dut = self._dut
        # The machine's shared nets (``_Nets``), captured as it elaborates, and the registers its
        # builders keep local (by name): the strengthening invariants relate the reference to them.
        nets: dict[str, object] = {}
        build = dut._memories

        def capture() -> object:
            nets["n"] = build()
            return nets["n"]

        dut._memories = capture
        m.submodules.dut = frag = Fragment.get(dut, platform)
        n = nets["n"]
        local = driven(frag)
        m.d.comb += [
            dut.load.valid.eq(self.load_valid), dut.load.payload.eq(self.load_payload),
            dut.result.ready.eq(self.result_ready), dut.entropy.eq(self.entropy),
            self.result_valid.eq(dut.result.valid), self.result_payload.eq(dut.result.payload),
            self.entropy_ready.eq(dut.entropy_ready),
        ]
        valid, ready, res = self.result_valid, self.result_ready, self.result_payload
        rows, cols, fb, loaded = p.rows, p.operator_columns, p.feedback_columns, p.loaded_columns
        ww, nbeats, last = p.memory_word_width, p.beats_per_pixel, p.rows - 1
        npix = p.words_per_pixel * ww

        # The environment: the load stream's source follows the stream rule (and nothing more).
        load_ready = dut.load.ready
        load_stall = Signal()
        load_prev = Signal.like(self.load_payload)
        m.d.sync += [load_stall.eq(self.load_valid & ~load_ready), load_prev.eq(self.load_payload)]
        with m.If(load_stall):
            m.d.comb += Assume(self.load_valid & (self.load_payload.as_value() == load_prev.as_value()))

        # --- Reference: pixels assembled from the load stream's handshakes -----------------------
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
        line_start = self.load_payload.line_start if fb else Const(0, 1)
        complete = accept & (beat == nbeats - 1)
        compute = dut.entropy_ready
        was_compute = Signal()
        m.d.sync += was_compute.eq(compute)
        run_start = compute & ~was_compute
        pq_count, pq, pq_over = queue(m, "pixels", npix + 1, 2, complete, Cat(*pixel_words, line_start),
                                      run_start)
        pq_head = pq[0]

        # --- Reference: the run ------------------------------------------------------------------
        # The pixel of the run (taken from the queue at its first compute cycle), its counters,
        # its compute cycles, and the previous result (for a neighbour prior's feedback column).
        act = Signal(npix + 1)
        cnt = [Signal(p.counter_width, name=f"ref_count_{r}") for r in range(rows)]
        cyc = Signal(p.cycle_width)
        prev_row = Signal(p.map_width)
        prev_valid = Signal()
        pix = Mux(run_start, pq_head, act)
        with m.If(run_start):
            m.d.sync += act.eq(pq_head)
        cnt_now = [Mux(run_start, 0, c) for c in cnt]
        cyc_now = Mux(run_start, 0, cyc)
        one = Const(p.word_one, ww)
        # A neighbour prior's feedback word per row: the table entry at the distance to the
        # previous MAP (the no-match row's own word), 1.0 without a previous hypothesis.
        fed: list[Value] = []
        if fb:
            table = Array(Const(w, ww) for w in p.feedback_words)
            top = len(p.feedback_words) - 1
            for r in range(rows):
                if p.nomatch_row and r == last:
                    fed.append(Mux(prev_valid, p.feedback_nomatch_word, one))
                else:
                    dist = Mux(prev_row > r, prev_row - r, r - prev_row)
                    fed.append(Mux(prev_valid, table[Mux(dist > top, top, dist)], one))
        bus = []
        op_words: list[Value] = []
        for r in range(rows):
            bit = Const(1, 1)
            for c in range(cols):
                if c < fb:
                    word = Mux(pix[-1], one, fed[r])  # line_start: the pixel has no left neighbour
                else:
                    w = r * loaded + c - fb
                    word = pix[w * ww:(w + 1) * ww]
                op_words.append(word)
                bit = bit & (self.entropy[r * cols + c] < word)  # the stochastic operator
            bus.append(bit)
        over = Cat(bus[r] & (cnt_now[r] == p.counter_max) for r in range(rows))
        next_cnt = [Mux(bus[r] & (cnt_now[r] != p.counter_max), cnt_now[r] + 1, cnt_now[r])[:p.counter_width]
                    for r in range(rows)]
        finish = over.any() | (cyc_now == p.max_cycles - 1)
        with m.If(compute):
            m.d.sync += [c.eq(x) for c, x in zip(cnt, next_cnt, strict=True)]
            m.d.sync += cyc.eq(cyc_now + 1)

        # The result the machine must give: the MAP by the tie rule (the lowest overflowing row;
        # under nomatch-first the no-match row wins any tie it is in), a timeout if none overflowed.
        winner: Value = Const(0, p.map_width)
        for r in reversed(range(rows)):
            winner = Mux(over[r], r, winner)
        if p.nomatch_row and p.tie_break == "nomatch-first":
            winner = Mux(over[last], last, winner)
        expected = Signal(result_layout(p))
        hit = over.any()
        m.d.comb += [
            expected.map.eq(Mux(hit, winner, 0)),
            expected.timeout.eq(~hit),
            expected.cycles.eq(cyc_now + 1),
            expected.counts.eq(Cat(*next_cnt)),
            expected.nomatch.eq(hit & (winner == last) if p.nomatch_row else 0),
        ]
        end = compute & finish
        with m.If(end):
            hypothesis = hit & (winner != last) if p.nomatch_row else hit
            m.d.sync += [prev_row.eq(winner), prev_valid.eq(hypothesis)]
        taken = valid & ready
        rq_count, rq, rq_over = queue(m, "results", Shape.cast(result_layout(p)).width, 2, end,
                                      expected.as_value(), taken)

        # --- Properties ---------------------------------------------------------------------------
        # A run starts only with a complete pixel loaded and not yet run: the swap never takes an
        # incomplete shadow, and no pixel is run twice or skipped (its words are the ones the
        # reference assembled: checked through the results and the active memory below).
        with m.If(run_start):
            m.d.comb += Assert(pq_count != 0, "a run starts only on a complete loaded pixel")
        # At most one complete pixel waits (the shadow): the load stream takes no beat of the next
        # pixel while it would overwrite one (no beat lost).
        m.d.comb += Assert(~pq_over & (pq_count <= 1), "at most one loaded pixel waits for its run")
        # The run's length: it goes on while no row overflows and fewer than max_cycles compute
        # cycles were done, and stops right after the first overflow or the max_cycles-th cycle (the
        # watchdog fires at max_cycles and only then); a compute cycle never waits for anything.
        go_on = Signal()
        m.d.sync += go_on.eq(~finish)
        with m.If(was_compute):
            m.d.comb += Assert(compute == go_on, "a run stops exactly at its first overflow or at max_cycles")
        # Each result taken is the reference's next result: the k-th result is the k-th loaded
        # pixel's, in order, its map by the tie rule, its counts the counters at the stop, its cycles
        # the run's compute cycles; no result without a run. (Checked whenever a result is offered:
        # back-pressure then holds it, proved by the stream group of MachineProperties.)
        head = Signal(result_layout(p))
        m.d.comb += head.eq(rq[0])
        with m.If(valid):
            m.d.comb += [
                Assert(rq_count != 0, "no result without a run"),
                Assert(res.map == head.map, "the result's map is the reference's"),
                Assert(res.timeout == head.timeout, "the result's timeout is the reference's"),
                Assert(res.nomatch == head.nomatch, "the result's nomatch is the reference's"),
                Assert(res.cycles == head.cycles, "the result's cycles are its run's compute cycles"),
                Assert(res.counts.as_value() == head.counts.as_value(),
                       "the result's counts are the counters at the stop"),
            ]
        m.d.comb += Assert(~rq_over & (rq_count <= 2), "at most two finished runs wait for the result stream")
        # No result lost: a finished run's result is offered at once (the bubble hands it over) or,
        # if the result register is full, as soon as it empties.
        waiting = Signal()
        m.d.sync += waiting.eq((rq_count != 0) & ~valid)
        m.d.comb += Assert(~(waiting & (rq_count != 0) & ~valid), "a finished run's result is offered")
        # No idle time: a machine with no run nor bubble pending (port view: not computing, and every
        # finished run's result in the result register) starts a complete pixel at once; loaded
        # LOAD_LATENCY + 1 cycles ago it starts in that cycle, so a run follows the previous one's
        # bubble directly (the bubble is one cycle; a neighbour prior's swap is FEEDBACK_CYCLES later).
        idle = ~compute & (rq_count == valid)
        idle_age = Signal(range(4))
        pq_age = Signal(range(4))
        m.d.sync += idle_age.eq(Mux(idle, Mux(idle_age == 3, 3, idle_age + 1), 0))
        m.d.sync += pq_age.eq(Mux((pq_count != 0) & ~run_start, Mux(pq_age == 3, 3, pq_age + 1), 0))
        m.d.comb += Assert(~(idle & (idle_age + 1 >= 1 + FEEDBACK_CYCLES * fb) & (pq_count != 0)
                             & (pq_age + 1 >= LOAD_LATENCY + 2)), "no idle cycle with a complete pixel")

        # --- Strengthening invariants: the reference is the machine's state ------------------------
        # (Each is a property too; they let k-induction close: every step follows from the last.)
        # The load side: the machine's beat is the reference's, and the shadow as it will be once
        # the beat in flight is written holds the beats taken so far.
        dut_beat, load_q = local["beat"], data.View(load_layout(p), local["load_q"])
        m.d.comb += Assert(beat < nbeats, "the reference's beat is a beat")
        m.d.comb += Assert(dut_beat == (Const(1, nbeats + 1) << beat)[:nbeats],
                           "the machine's beat is the reference's")
        q_words = beat_words(p, load_q)
        eff = []
        for w in range(p.words_per_pixel):
            b, lane = divmod(w, p.words_per_beat)
            eff.append(Mux(n.write_q[b], q_words[lane], n.shadow[w]))
        pending = n.shadow_full | n.write_q[nbeats - 1]
        m.d.comb += Assert(pq_count == (pending | run_start), "the pixel waiting is in the shadow")
        with m.If(pending):
            m.d.comb += Assert(Cat(*eff) == pq_head[:npix], "the shadow holds the pixel's beats")
            m.d.comb += Assert(beat == 0, "no beat taken while a pixel waits")
            if fb:
                ls = Mux(n.write_q[nbeats - 1], load_q.line_start, n.shadow_line_start)
                m.d.comb += Assert(ls == pq_head[-1], "the shadow's line_start")
        for w in range(p.words_per_pixel):
            b = w // p.words_per_beat
            if b < nbeats - 1:
                with m.If(beat > b):
                    m.d.comb += Assert(eff[w] == asm[w], f"shadow word {w} holds its beat")
        expect_write = Signal(nbeats)
        m.d.sync += expect_write.eq(Mux(accept, (Const(1, nbeats + 1) << beat)[:nbeats], 0))
        m.d.comb += Assert(n.write_q == expect_write, "each beat taken is written once, the cycle after")
        # The run: the registered enables' copies are the enables, the flags the counters'.
        for g in range(n.groups):
            m.d.comb += Assert(n.compute_rep[g] == n.compute, "compute enable copy")
            m.d.comb += Assert(n.start_rep[g] == n.start, "start enable copy")
        for r in range(rows):
            m.d.comb += Assert(n.full[r] == (n.counts[r] == p.counter_max), f"full flag {r}")
        m.d.comb += Assert(~n.stop | n.running, "a stop only in a run")
        with m.If(compute):
            m.d.comb += Assert(Cat(*n.active) == Cat(*op_words), "the active memory holds the run's pixel")
            for r in range(rows):
                m.d.comb += Assert(n.counts[r] == cnt_now[r], f"counter {r} is the reference's")
            m.d.comb += Assert(n.cycles_done == cyc_now, "the cycle count is the reference's")
            m.d.comb += Assert(n.at_last == (cyc_now == p.max_cycles - 1), "the watchdog's flag")
        # A bubble holds the finished run whose result is not in the result register yet.
        m.d.comb += Assert(rq_count == valid + n.stop, "the results waiting: the register's and the bubble's")
        pend = Signal(result_layout(p))
        m.d.comb += pend.eq(Mux(valid, rq[1], rq[0]))
        with m.If(n.stop):
            m.d.comb += [
                Assert(n.valid_q == ~pend.timeout, "bubble: the encoder's valid"),
                Assert(pend.map == Mux(n.valid_q, n.winner, 0), "bubble: the encoder's choice"),
                Assert(pend.nomatch == ((n.valid_q & (n.winner == last)) if p.nomatch_row else 0),
                       "bubble: no match"),
                Assert(n.cycles_done == pend.cycles, "bubble: the cycle count"),
                Assert(Cat(*n.counts) == pend.counts.as_value(), "bubble: the counters"),
            ]
        m.d.comb += Assert(n.cycles_done <= p.max_cycles, "the cycle count stays within max_cycles")
        if fb:
            # The previous result as the machine keeps it (from the bubble on) and its feedback
            # words (a cycle later): the reference's, outside the bubble and the cycle after.
            with m.If(n.stop):
                hyp = ~pend.timeout & (pend.map != last) if p.nomatch_row else ~pend.timeout
                m.d.comb += Assert(prev_valid == hyp, "bubble: the reference's previous hypothesis")
                with m.If(hyp):
                    m.d.comb += Assert(prev_row == pend.map, "bubble: the reference's previous MAP")
            with m.Else():
                for g in range(n.groups):
                    m.d.comb += Assert(local[f"prev_valid_rep{g}"] == prev_valid, "previous hypothesis")
                    with m.If(prev_valid):
                        m.d.comb += Assert(local[f"prev_row_rep{g}"] == prev_row, "previous MAP")
                with m.If(~n.settle):
                    for r in range(rows):
                        m.d.comb += Assert(local[f"feedback_q_{r}"] == fed[r],
                                           f"feedback word {r} is the table entry of the previous MAP")

        # Not vacuous: a result taken after a stall; a run directly after the previous one's bubble
        # (the one-cycle bubble; with a neighbour prior, FEEDBACK_CYCLES later); a timeout; a tie
        # of the no-match row with a disparity row at the stop; two results taken.
        stalled = Signal()
        m.d.sync += stalled.eq(valid & ~ready)
        m.d.comb += Cover(stalled & taken)
        gap = Signal(range(8))  # non-compute cycles since the last run's last compute cycle
        with m.If(compute):
            m.d.sync += gap.eq(0)
        with m.Elif((gap != 0) | was_compute):
            m.d.sync += gap.eq(Mux(gap == 7, 7, gap + 1))
        m.d.comb += Cover(run_start & (gap == BUBBLE_CYCLES + FEEDBACK_CYCLES * fb))
        m.d.comb += Cover(taken & res.timeout)
        if p.nomatch_row:
            m.d.comb += Cover(end & over[last] & over[:last].any())
        n_taken = Signal(2)
        with m.If(taken & (n_taken != 3)):
            m.d.sync += n_taken.eq(n_taken + 1)
        m.d.comb += Cover(n_taken == 2)
        if fb:
            # A run whose feedback words come from a previous hypothesis.
            m.d.comb += Cover(run_start & prev_valid & ~pq_head[-1])
        return m
