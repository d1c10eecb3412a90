"""The top level: ``BayesianMachine(params)``, the stochastic Bayesian machine of the paper.

An M x N matrix of stochastic operators (``operator.py``) fed by a random source
(``sources.py``: LFSRs, shared LFSRs or Sobol generators, or numbers on a port) and by
double-buffered likelihood memories; the AND of a row's operators is the
row's stochastic bus signal, counted by its overflow counter (``counters.py``); the first
overflow(s) stop the run and the MAP encoder (``encoder.py``) names the winner. The exact
per-cycle semantics, ports and word order are in ``docs/architecture.md``; the NumPy model
``bayesmachine.sim.model`` computes the same thing bit for bit.

Timing (``docs/architecture.md``, "Timing"):

- ``load`` takes one beat per handshake and writes it into the *shadow* likelihood memory the
  cycle after; ``load.ready`` is low while the shadow holds a complete pixel not yet started
  (or its last beat is being written).
- A run's compute cycles advance the random source, counters and cycle count. The cycle after
  the last one is the run's *bubble* (the stop decision is registered): the result register
  takes the result, and a complete shadow is swapped into the *active* memory, so runs go back
  to back with one bubble between them. Back-pressure on ``result`` holds the bubble, never a
  compute cycle, so it changes no result.

The random source and the MAP encoder are direct submodules (depth 1), the very components
their unit tests drive; the operator matrix is built by ``operator.operator_bits`` and
``operator.bus_rows`` (``operator_rows`` is their composition, the function the operator test's
component wraps; as a submodule its port copies of 246 words and numbers would slow Amaranth's
Python simulator, which also slows with hierarchy depth).
"""

from __future__ import annotations

import numpy as np
from amaranth.hdl import Cat, Module, Mux, Signal, Value, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.params import MachineParams
from bayesmachine.sources import check_source, source_kind

from .counters import overflow_counter_full
from .encoder import MAPEncoder
from .operator import bus_rows, operator_bits, operator_rows
from .sources import random_source

__all__ = [
    "BUBBLE_CYCLES", "GROUP_OPERATORS", "LOAD_LATENCY", "BayesianMachine", "load_layout", "pixel_wall_cycles",
    "result_layout",
]

BUBBLE_CYCLES = 1  # clock cycles per run after its last compute cycle (the registered stop)
LOAD_LATENCY = 1  # a load beat is written into the shadow memory the cycle after its handshake
GROUP_OPERATORS = 12  # operators per registered copy of the compute and start enables


def pixel_wall_cycles(params: MachineParams, cycles: np.ndarray) -> np.ndarray:
    """Clock cycles per pixel in steady state (loads keep coming, results are taken at once).

    A run of k compute cycles is followed by its bubble, in which the next pixel is swapped in if
    its ``beats_per_pixel`` load beats have been written (they start the cycle after the previous
    swap, and each is written the cycle after its handshake):
    ``max(k, beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES``.
    """
    cycles = np.asarray(cycles, dtype=np.int64)
    return np.maximum(cycles, params.beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES


def load_layout(params: MachineParams) -> data.ArrayLayout:
    """One beat of the load stream: ``lanes`` likelihood-memory words of W + 1 bits."""
    return data.ArrayLayout(unsigned(params.memory_word_width), params.lanes)


def result_layout(params: MachineParams) -> data.StructLayout:
    """One pixel's result; fields in this order from bit 0 (the contract's order)."""
    return data.StructLayout({
        "map": unsigned(params.map_width),
        "nomatch": unsigned(1),
        "timeout": unsigned(1),
        "cycles": unsigned(params.cycle_width),
        "counts": data.ArrayLayout(unsigned(params.counter_width), params.rows),
    })


class BayesianMachine(wiring.Component):
    """The stochastic Bayesian machine.

    Ports:

    - ``load``: ``In(stream.Signature(load_layout(params)))``, a pixel's words in operator
      order, ``lanes`` per beat, ``beats_per_pixel`` beats per pixel.
    - ``result``: ``Out(stream.Signature(result_layout(params)))``, one per pixel, in order.
    - with an off-chip ``rng`` ("external", "smtj"): ``entropy``
      (``In(ArrayLayout(unsigned(W), operators))``, one random number per operator, sampled on
      compute cycles) and ``entropy_ready`` (``Out(1)``, high on compute cycles: the numbers on
      ``entropy`` are consumed at the clock edge).
    """

    def __init__(self, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"BayesianMachine takes a MachineParams, not {type(params).__name__}")
        check_source(params)  # before elaboration: a clear error, not one from deep inside
        self._params = params
        members = {
            "load": In(stream.Signature(load_layout(params))),
            "result": Out(stream.Signature(result_layout(params))),
        }
        if not source_kind(params.rng).on_chip:
            members["entropy"] = In(data.ArrayLayout(unsigned(params.word_bits), params.operators))
            members["entropy_ready"] = Out(1)
        super().__init__(members)

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p = self._params
        rows, cols = p.rows, p.operator_columns
        ops = p.operators

        # --- Likelihood memories (registers: every operator reads its word every cycle) ---
        # No reset: a run always starts by copying a complete shadow into the active memory.
        shadow = [Signal(p.memory_word_width, name=f"shadow_{o // cols}_{o % cols}", reset_less=True)
                  for o in range(ops)]
        active = [Signal(p.memory_word_width, name=f"word_{o // cols}_{o % cols}", reset_less=True)
                  for o in range(ops)]
        shadow_full = Signal()
        nbeats = p.beats_per_pixel
        beat = Signal(nbeats, init=1)  # one-hot: the beat the next handshake carries
        # Registered load: a beat is taken into ``load_q`` and written into the shadow memory the
        # cycle after, under a registered one-hot enable (no logic between a flip-flop and the
        # enables of a beat's words, which are spread over the whole matrix).
        load_q = Signal.like(self.load.payload)
        write_q = Signal(nbeats)

        # --- Run state ---
        running = Signal()
        cycles_done = Signal(p.cycle_width)  # compute cycles of this run so far
        counts = [Signal(p.counter_width, name=f"count_{r}") for r in range(rows)]

        # --- Control path (registered stop; see "Timing" in docs/architecture.md) ---
        # ``stop`` is the registered end-of-run decision: high in the bubble cycle that follows a
        # run's last compute cycle. Nothing advances in a bubble, so results do not depend on it;
        # every wide enable below is a function of registers only, never of the matrix.
        stop = Signal()
        compute = Signal()
        m.d.comb += compute.eq(running & ~stop)
        # The matrix's enables (compute: LFSRs, counters; start: the shadow-to-active copy) reach
        # thousands of flip-flops: each group of rows gets its own registered copy, loaded with
        # the enable's next value (``compute_n``/``start_n`` below), so no net fans out further
        # than a group. The flow keeps these ``_rep`` registers apart (docs/fpga.md).
        rows_per_group = max(1, GROUP_OPERATORS // cols)
        groups = -(-rows // rows_per_group)
        compute_rep = [Signal(name=f"compute_rep{g}") for g in range(groups)]
        start_rep = [Signal(name=f"start_rep{g}") for g in range(groups)]
        # and one copy each for a shared source's enable and restart (its next-number logic feeds
        # every group's copy of the numbers, so its inputs come straight from flip-flops). Amaranth
        # aliases these with the source's ports, so the flow's keep selection misses them and
        # Yosys merges them with compute_rep0 / start_rep0 (docs/fpga.md).
        src_reps: list[tuple[Signal, Signal]] = []

        # --- Random numbers: advance on compute cycles only; a Sobol block restarts per pixel ---
        # An on-chip source also gives the next compute cycle's numbers a cycle early
        # (``next_numbers`` after a compute cycle, ``restart_numbers`` after a run's start), so
        # each operator's comparator is registered ("prefetched", below).
        source, sources = random_source(p, [o // cols // rows_per_group for o in range(ops)])
        if source is not None:
            m.submodules.source = source
            per_operator = p.rng == "lfsr"  # random_source splits only its enable by group
            if per_operator:  # per-operator LFSRs: one enable per group of rows
                m.d.comb += source.enable.eq(Cat(compute_rep))
            else:
                src_reps.append((Signal(name="compute_rep_src"), Signal(name="start_rep_src")))
                m.d.comb += source.enable.eq(src_reps[0][0])
            numbers = source.numbers
        else:
            numbers = [self.entropy[o] for o in range(ops)]
            m.d.comb += self.entropy_ready.eq(compute)

        # --- Operator matrix: the stochastic bus ---
        # Prefetched comparators (on-chip sources): ``bit_q[o]`` holds this compute cycle's
        # ``number < word``. It is loaded in the cycle before: in a compute cycle from the next
        # numbers and the same word, in a swap from the numbers the source gives after the
        # start (a Sobol block restarts) and the incoming (shadow) word. Same bits as comparing
        # in the cycle itself, but the matrix's path to the stop flip-flop starts at a register
        # instead of a carry chain. With numbers from a port (off-chip sources) they arrive in
        # their cycle and are compared then.
        next_bits: list[Value] = []  # the next compute cycle's bits, seen from a compute cycle
        if source is not None:
            if not per_operator:
                # A number shared by a column's rows would reach all its comparators from one
                # net: each group of rows gets a registered copy of the column's next numbers,
                # loaded every clock from ``following_numbers`` (so equal to ``next_numbers``
                # in every cycle), and one of its restart numbers, loaded from
                # ``following_restart_numbers`` (equal to ``restart_numbers``). The flow keeps
                # these ``_rep`` registers apart too.
                def group_copies(name: str, following: list[Value]) -> list[list[Signal]]:
                    copies = []
                    for g in range(groups):
                        copy = [Signal(len(n), name=f"{name}_rep{g}_{i}") for i, n in enumerate(following)]
                        m.d.sync += [c.eq(n) for c, n in zip(copy, following, strict=True)]
                        copies.append(copy)
                    return copies

                def group_bits(copies: list[list[Signal]], words: list[Signal]) -> list[Value]:
                    return [operator_bits(copies[o // cols // rows_per_group], [words[o]], [sources[o]])[0]
                            for o in range(ops)]

                next_bits = group_bits(group_copies("next_number", list(source.following_numbers)), active)
                restart_copies = group_copies("restart_number", list(source.following_restart_numbers))
                start_bits = group_bits(restart_copies, shadow)
            else:
                next_bits = operator_bits(source.next_numbers, active, sources)
                start_bits = operator_bits(source.restart_numbers, shadow, sources)
            bits = []
            for o in range(ops):
                g = o // cols // rows_per_group
                bit_q = Signal(name=f"bit_{o // cols}_{o % cols}")
                with m.If(compute_rep[g]):
                    m.d.sync += bit_q.eq(next_bits[o])
                with m.Elif(start_rep[g]):
                    m.d.sync += bit_q.eq(start_bits[o])
                bits.append(bit_q)
            row_bits = bus_rows(bits, rows, cols)
        else:
            row_bits = operator_rows(numbers, active, rows, cols, sources)
        row = Signal(rows)
        m.d.comb += row.eq(row_bits)

        # --- Overflow counters, with registered "full" flags (count == n_max) ---
        full = Signal(rows)
        over = Signal(rows)
        next_counts, next_full = [], []
        for r in range(rows):
            ov, nxt, nfull = overflow_counter_full(row[r], counts[r], full[r], p.counter_max)
            m.d.comb += over[r].eq(ov)
            next_counts.append(nxt)
            next_full.append(nfull)

        # The stop decision needs only whether any row overflows (the encoder works in the bubble).
        # With prefetched comparators that too is known a cycle early, per group of rows: the
        # next cycle's ``row & full`` from the next bits and the next full flags, ORed over the
        # group's rows into one flip-flop (0 after a swap: the counters restart empty). The
        # stop is then an OR of one flip-flop per group.
        if next_bits:
            over_group = [Signal(name=f"over_group_{g}") for g in range(groups)]
            for g in range(groups):
                terms = []
                for r in range(g * rows_per_group, min(rows, (g + 1) * rows_per_group)):
                    row_next = bus_rows(next_bits[r * cols:(r + 1) * cols], 1, cols)
                    terms.append(row_next & next_full[r])
                with m.If(compute_rep[g]):
                    m.d.sync += over_group[g].eq(Cat(terms).any())
                with m.Elif(start_rep[g]):
                    m.d.sync += over_group[g].eq(0)
            any_over = Cat(over_group).any()
        else:
            any_over = over.any()

        # The watchdog, registered too: ``at_last`` is high in compute cycle k == max_cycles.
        at_last = Signal()
        finish = Signal()
        m.d.comb += finish.eq(compute & (any_over | at_last))
        over_q = Signal(rows)  # the overflow flags of the last compute cycle, for the encoder

        with m.If(compute):
            m.d.sync += [
                cycles_done.eq(cycles_done + 1),
                at_last.eq(cycles_done == p.max_cycles - 2),  # max_cycles >= 2: never at start
                stop.eq(finish),
            ]
        for r in range(rows):
            with m.If(compute_rep[r // rows_per_group]):
                m.d.sync += [counts[r].eq(next_counts[r]), full[r].eq(next_full[r]), over_q[r].eq(over[r])]

        # --- Bubble: hand the result over (the result register is empty: a register, no ready) ---
        res = self.result.payload
        leave = Signal()
        m.d.comb += leave.eq(stop & ~self.result.valid)
        with m.If(self.result.ready):
            m.d.sync += self.result.valid.eq(0)
        m.submodules.encoder = encoder = MAPEncoder(rows, nomatch_row=p.nomatch_row, tie_break=p.tie_break)
        m.d.comb += encoder.over.eq(over_q)
        valid_q, winner = encoder.valid, encoder.index
        with m.If(leave):
            map_value = Signal(p.map_width)
            m.d.comb += map_value.eq(winner)
            m.d.sync += [
                self.result.valid.eq(1),
                res.map.eq(valid_q.replicate(p.map_width) & map_value),
                res.timeout.eq(~valid_q),
                res.cycles.eq(cycles_done),
                res.counts.eq(Cat(counts)),
                running.eq(0),
                stop.eq(0),
            ]
            if p.nomatch_row:
                m.d.sync += res.nomatch.eq(valid_q & (map_value == rows - 1))
            else:
                m.d.sync += res.nomatch.eq(0)

        # --- Start: swap in the shadow memory, in a bubble or when idle (overrides the above) ---
        start = Signal()
        m.d.comb += start.eq(shadow_full & (leave | ~running))
        if source is not None and "restart" in source.signature.members:
            m.d.comb += source.restart.eq(src_reps[0][1])
        with m.If(start):
            m.d.sync += [at_last.eq(0), cycles_done.eq(0), running.eq(1), shadow_full.eq(0)]
        for r in range(rows):
            with m.If(start_rep[r // rows_per_group]):
                m.d.sync += [active[o].eq(shadow[o]) for o in range(r * cols, (r + 1) * cols)]
                m.d.sync += [counts[r].eq(0), full[r].eq(0)]

        # --- Load stream: one beat per handshake into the shadow memory ---
        # Not ready while the shadow is full or its last beat is being written.
        m.d.comb += self.load.ready.eq(~shadow_full & ~write_q[nbeats - 1])
        accept = self.load.valid & self.load.ready

        # --- Next values of the replicated enables (the registers' updates above, one cycle early) ---
        # Written as a last 2:1 choice on ``compute`` so that the OR over the rows (``fin``), the
        # late signal, enters the last gate only: in a compute cycle there is no start or leave,
        # running stays 1 and stop becomes ``fin``.
        fin = any_over | at_last
        shadow_full_n = ~start & (shadow_full | write_q[nbeats - 1])
        valid_n = leave | (self.result.valid & ~self.result.ready)
        stop_idle = stop & ~leave  # stop's next value outside compute cycles
        running_n = start | (running & ~leave)
        compute_n, start_n = Signal(), Signal()
        m.d.comb += [
            compute_n.eq(Mux(compute, ~fin, running_n & ~stop_idle)),
            start_n.eq(Mux(compute, fin & shadow_full_n & ~valid_n,
                           shadow_full_n & ((stop_idle & ~valid_n) | ~running_n))),
        ]
        m.d.sync += [c.eq(compute_n) for c in compute_rep + [c for c, _ in src_reps]]
        m.d.sync += [s.eq(start_n) for s in start_rep + [s for _, s in src_reps]]
        m.d.sync += write_q.eq(Mux(accept, beat, 0))
        with m.If(accept):
            m.d.sync += [load_q.eq(self.load.payload), beat.eq(beat.rotate_left(1))]
        for b in range(nbeats):
            with m.If(write_q[b]):
                for lane in range(p.lanes):
                    o = b * p.lanes + lane
                    if o < ops:  # unused lanes of the last beat are ignored
                        m.d.sync += shadow[o].eq(load_q[lane])
        with m.If(write_q[nbeats - 1]):
            m.d.sync += shadow_full.eq(1)

        return m
