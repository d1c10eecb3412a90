"""The top level: ``BayesianMachine(params)``, the stochastic Bayesian machine of the paper.

An M x N matrix of stochastic operators (``operator.py``) fed by a random source
(``sources.py``: LFSRs, shared LFSRs or Sobol generators, or numbers on a port) and by
double-buffered likelihood memories; the AND of a row's operators is the
row's stochastic bus signal, counted by its overflow counter (``counters.py``); the first
overflow(s) stop the run and the MAP encoder (``encoder.py``) names the winner. The exact
per-cycle semantics, ports and word order are in ``docs/architecture.md``; the NumPy model
``bayesmachine.sim.model`` computes the same thing bit for bit.

Timing:

- ``load`` writes one beat per handshake into the *shadow* likelihood memory. When it holds a
  complete pixel and the machine is idle or ending a run in this cycle, the shadow is copied
  into the *active* memory and the next run starts: runs go back to back with no idle cycle.
  ``load.ready`` is low only while the shadow holds a complete pixel not yet started.
- A compute cycle is a cycle of a run in which the result register can take a result
  (empty, or being read this cycle). Only compute cycles advance the random source, counters and cycle
  count, so back-pressure on ``result`` stalls the machine without changing any result.

The random source and the MAP encoder are direct submodules (depth 1), the very components
their unit tests drive; the operator matrix is built by ``operator.operator_rows``, the
function the operator test's component wraps (as a submodule its port copies of 246 words and
numbers would slow Amaranth's Python simulator, which also slows with hierarchy depth).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.params import MachineParams
from bayesmachine.sources import source_kind

from .counters import overflow_counter
from .encoder import MAPEncoder
from .operator import operator_rows
from .sources import random_source

__all__ = ["BayesianMachine", "load_layout", "result_layout"]


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
        beat = Signal(range(max(2, p.beats_per_pixel)))

        # --- Run state ---
        running = Signal()
        cycles_done = Signal(p.cycle_width)  # compute cycles of this run so far (k - 1)
        counts = [Signal(p.counter_width, name=f"count_{r}") for r in range(rows)]

        compute = Signal()
        m.d.comb += compute.eq(running & (~self.result.valid | self.result.ready))

        # --- Random numbers: advance on compute cycles only; a Sobol block restarts per pixel ---
        source, sources = random_source(p)
        if source is not None:
            m.submodules.source = source
            m.d.comb += source.enable.eq(compute)
            numbers = source.numbers
        else:
            numbers = [self.entropy[o] for o in range(ops)]
            m.d.comb += self.entropy_ready.eq(compute)

        # --- Operator matrix: the stochastic bus ---
        row = Signal(rows)
        m.d.comb += row.eq(operator_rows(numbers, active, rows, cols, sources))

        # --- Overflow counters ---
        over = Signal(rows)
        next_counts = []
        for r in range(rows):
            ov, nxt = overflow_counter(row[r], counts[r], p.counter_max)
            m.d.comb += over[r].eq(ov)
            next_counts.append(nxt)

        # --- MAP encoder and end of run ---
        m.submodules.encoder = encoder = MAPEncoder(rows, nomatch_row=p.nomatch_row, tie_break=p.tie_break)
        m.d.comb += encoder.over.eq(over)
        any_over, winner = encoder.valid, encoder.index
        last_cycle = cycles_done == p.max_cycles - 1  # this cycle is k == max_cycles
        finish = Signal()
        m.d.comb += finish.eq(compute & (any_over | last_cycle))
        start = Signal()
        m.d.comb += start.eq(shadow_full & (~running | finish))
        if source is not None and "restart" in source.signature.members:
            m.d.comb += source.restart.eq(start)

        with m.If(compute):
            m.d.sync += cycles_done.eq(cycles_done + 1)
            m.d.sync += [cnt.eq(nxt) for cnt, nxt in zip(counts, next_counts, strict=True)]

        # --- Result register (the result stream's payload) ---
        res = self.result.payload
        with m.If(self.result.ready):
            m.d.sync += self.result.valid.eq(0)
        with m.If(finish):
            # compute implies the register is free (or being read now), so nothing is lost.
            map_value = Signal(p.map_width)
            m.d.comb += map_value.eq(winner)
            m.d.sync += [
                self.result.valid.eq(1),
                res.map.eq(any_over.replicate(p.map_width) & map_value),
                res.timeout.eq(~any_over),
                res.cycles.eq(cycles_done + 1),
                res.counts.eq(Cat(next_counts)),
                running.eq(0),
            ]
            if p.nomatch_row:
                m.d.sync += res.nomatch.eq(any_over & (map_value == rows - 1))
            else:
                m.d.sync += res.nomatch.eq(0)

        # --- Start: swap in the shadow memory (overrides the end-of-run updates above) ---
        with m.If(start):
            m.d.sync += [a.eq(s) for a, s in zip(active, shadow, strict=True)]
            m.d.sync += [cnt.eq(0) for cnt in counts]
            m.d.sync += [cycles_done.eq(0), running.eq(1), shadow_full.eq(0)]

        # --- Load stream: one beat per handshake into the shadow memory ---
        m.d.comb += self.load.ready.eq(~shadow_full)
        accept = self.load.valid & self.load.ready
        write_beat = Signal(p.beats_per_pixel)  # one-hot: which words this beat writes
        m.d.comb += write_beat.eq(Cat(accept & (beat == b) for b in range(p.beats_per_pixel)))
        for b in range(p.beats_per_pixel):
            with m.If(write_beat[b]):
                for lane in range(p.lanes):
                    o = b * p.lanes + lane
                    if o < ops:  # unused lanes of the last beat are ignored
                        m.d.sync += shadow[o].eq(self.load.payload[lane])
        with m.If(accept):
            with m.If(beat == p.beats_per_pixel - 1):
                m.d.sync += [beat.eq(0), shadow_full.eq(1)]
            with m.Else():
                m.d.sync += beat.eq(beat + 1)

        return m
