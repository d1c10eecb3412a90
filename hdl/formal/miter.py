"""A miter: back-pressure on ``result`` (and a slower load source) never changes a result.

Two copies of the same machine see the same pixels and, in each run, the same random numbers:
the pixels come from a free table (two pixels, used in turn: each copy's k-th pixel is the same),
the numbers from a free table indexed by the compute cycle within the run (each copy's i-th
compute cycle of a run gets the same numbers). Copy A runs at full speed (its load source is
always valid, its results always taken); copy B's load ``valid`` and ``result.ready`` are free
(its load source follows the stream rule). Both tables are free but fixed (assumed constant).
The property: B's k-th result is A's k-th result, field for field.
"""

from __future__ import annotations

from amaranth.hdl import Array, Assert, Assume, Const, Cover, Module, Mux, Shape, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.hdl.signatures import entropy_layout, load_layout, result_layout
from bayesmachine.params import MachineParams
from bayesmachine.sources import source_kind

__all__ = ["MiterProperties"]

RING = 4  # A's results kept for the comparison (A is at most this many results ahead)


class MiterProperties(wiring.Component):
    """A formal-only wrapper: two copies of a machine, one stalled at will, and their results compared.

    Parameters
    ----------
    params : MachineParams
        The machine (``rng = "external"``, no neighbour prior: its pixels carry no line flag here).
    machine : callable
        Builds copy B (the stalled one) from a ``params`` keyword; ``BayesianMachine`` unless a mutant
        is being checked. Copy A is always a ``BayesianMachine``.

    Attributes
    ----------
    pixel_table, number_table : ``In``
        Two pixels' load beats, and ``max_cycles`` compute cycles' numbers (free, held constant).
    load_valid, result_ready : ``In(1)``
        Copy B's environment (free).
    result_valid, result_payload : ``Out``
        Copy B's result stream, for the trace.
    """

    def __init__(self, *, params: MachineParams, machine: type = BayesianMachine) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
        if source_kind(params.rng).on_chip or params.feedback_columns:
            raise ValueError("the miter takes its numbers on a port (rng 'external') and no neighbour prior")
        self._params = params
        self._machine = machine
        beat_bits = Shape.cast(load_layout(params)).width
        number_bits = Shape.cast(entropy_layout(params)).width
        super().__init__({
            "pixel_table": In(2 * params.beats_per_pixel * beat_bits),
            "number_table": In(params.max_cycles * number_bits),
            "load_valid": In(1), "result_ready": In(1),
            "result_valid": Out(1), "result_payload": Out(result_layout(params)),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        p = self._params
        m = Module()
        nbeats = p.beats_per_pixel
        beat_bits = Shape.cast(load_layout(p)).width
        number_bits = Shape.cast(entropy_layout(p)).width

        # The tables are fixed: free in the first cycle (and after a reset), then held.
        held = Signal()
        prev_pixels, prev_numbers = Signal.like(self.pixel_table), Signal.like(self.number_table)
        m.d.sync += [held.eq(1), prev_pixels.eq(self.pixel_table), prev_numbers.eq(self.number_table)]
        with m.If(held):
            m.d.comb += Assume((self.pixel_table == prev_pixels) & (self.number_table == prev_numbers))
        beats = Array(self.pixel_table[i * beat_bits:(i + 1) * beat_bits] for i in range(2 * nbeats))
        numbers = Array(self.number_table[i * number_bits:(i + 1) * number_bits] for i in range(p.max_cycles))

        def feed(name: str, dut: wiring.Component, valid: object) -> None:
            """The copy's k-th pixel is table pixel k mod 2; its i-th compute cycle of a run gets
            table numbers i."""
            beat = Signal(range(max(2, nbeats)), name=f"{name}_beat")
            pixel = Signal(name=f"{name}_pixel")
            with m.If(dut.load.valid & dut.load.ready):
                with m.If(beat == nbeats - 1):
                    m.d.sync += [beat.eq(0), pixel.eq(~pixel)]
                with m.Else():
                    m.d.sync += beat.eq(beat + 1)
            cycle = Signal(range(p.max_cycles + 1), name=f"{name}_cycle")
            m.d.sync += cycle.eq(Mux(dut.entropy_ready, cycle + 1, 0))
            m.d.comb += [
                dut.load.valid.eq(valid),
                dut.load.payload.eq(beats[pixel * nbeats + beat]),
                dut.entropy.eq(data.View(entropy_layout(p), numbers[cycle])),
            ]

        m.submodules.a = a = BayesianMachine(params=p)
        m.submodules.b = b = self._machine(params=p)
        feed("a", a, Const(1))
        feed("b", b, self.load_valid)
        m.d.comb += [a.result.ready.eq(1), b.result.ready.eq(self.result_ready),
                     self.result_valid.eq(b.result.valid), self.result_payload.eq(b.result.payload)]
        # B's load source follows the stream rule (its payload is held by construction).
        stall = Signal()
        m.d.sync += stall.eq(self.load_valid & ~b.load.ready)
        with m.If(stall):
            m.d.comb += Assume(self.load_valid)

        # A's results, in order; B's k-th result against A's k-th.
        width = Shape.cast(result_layout(p)).width
        ring = Array(Signal(width, name=f"a_result_{i}") for i in range(RING))
        a_count = Signal(8)
        b_count = Signal(8)
        with m.If(a.result.valid):
            m.d.sync += [ring[a_count % RING].eq(a.result.payload.as_value()), a_count.eq(a_count + 1)]
        b_taken = b.result.valid & b.result.ready
        with m.If(b_taken):
            m.d.sync += b_count.eq(b_count + 1)
            # Back-pressure is not the only reason B lags: its loads may come later; either way its
            # k-th result is A's k-th (A keeps the last RING of its results).
            with m.If(a_count > b_count):
                m.d.comb += Assume(a_count - b_count <= RING)
                m.d.comb += Assert(b.result.payload.as_value() == ring[b_count % RING],
                                   "a stalled copy's k-th result is the free copy's k-th")
        # Not vacuous: B's result compared after a stall of its result stream.
        was_stalled = Signal()
        m.d.sync += was_stalled.eq(b.result.valid & ~b.result.ready)
        m.d.comb += Cover(b_taken & was_stalled & (a_count > b_count) & (b_count == 1))
        return m
