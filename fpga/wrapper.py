"""The pin-saving wrapper: a core behind a few registered pins, so that synthesis keeps it whole.

A machine's ports are hundreds of bits wide (a 16-word load beat is 176 bits, a Dmax = 80 result
440 bits): more than any package has pins, and a design whose ports were left undriven would
be trimmed to nothing. ``PinWrapper`` puts any component with one input stream and a ``result``
output stream behind ``2 * pin_width + 3`` pins, all registered at the boundary, so every
payload bit stays observable and the timing report measures the core, not the pads.

The input stream is taken from the core's signature (:func:`input_stream`): its one ``In``
member that is a ``stream.Signature``. That is ``load`` (likelihood-memory words) for
``BayesianMachine`` and ``ParallelMachines``, ``pixels`` (pixel pairs) for the front end's
``StereoMachine``; the wrapper is the same for all of them.

Protocol (one clock, ``pin_width`` = P bits per chunk):

- **In**: ``din`` / ``din_valid`` (inputs, registered on entry) and ``din_ready`` (a registered
  output). In each cycle in which ``din_ready`` is high, the host may drive one chunk
  (``din_valid = 1``). Chunks fill one input beat lowest bits first, ``ceil(input_width / P)``
  chunks per beat; a complete beat goes to the core's input stream. ``din_ready`` already
  accounts for the chunk in flight, so a host that obeys it never loses a chunk.
- **Out**: ``dout`` / ``dout_valid`` (registered outputs). Each result is shifted out lowest
  bits first, ``ceil(result_width / P)`` consecutive chunks marked by ``dout_valid``, one per
  cycle; the host takes every chunk (a FIFO or a logic analyser). The core's ``result`` stream
  waits while the shifter is busy, so the core stalls rather than losing a result. A stereo top's
  declared passes' results (``<pass>_result``, census-lr's right pass) are taken as they come and left
  unconnected (their ``ready`` high: the design the Verilator harness runs).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Shape, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.hdl.signatures import ENTROPY_PORTS
from bayesmachine.params import ParameterError

__all__ = ["PinWrapper", "input_stream", "stream_widths"]

OUT_GROUP = 8  # result chunks per registered copy of the shifter's take enable


def input_stream(core: wiring.Component) -> str:
    """The name of ``core``'s one input stream: its only ``In`` member whose signature is a
    ``stream.Signature`` (``load`` for the machine and K machines, ``pixels`` for the StereoMachine)."""
    members = core.signature.members
    names = [name for name, member in members.items()
             if member.flow == In and member.is_signature and isinstance(member.signature, stream.Signature)]
    if len(names) != 1:
        found = ", ".join(repr(n) for n in names) or "none"
        raise ParameterError(f"the wrapped core must have exactly one input stream port (found {found})")
    return names[0]


def stream_widths(core: wiring.Component) -> tuple[int, int]:
    """(input payload width, result payload width) of a component with one input stream
    (:func:`input_stream`) and a ``result`` output stream."""
    members = core.signature.members
    name = input_stream(core)
    if ("result" not in members or members["result"].flow != Out or not members["result"].is_signature
            or not isinstance(members["result"].signature, stream.Signature)):
        raise ParameterError("the wrapped core must have a 'result' output stream port")
    width_in = Shape.cast(members[name].signature.members["payload"].shape).width
    result = Shape.cast(members["result"].signature.members["payload"].shape).width
    return width_in, result


class PinWrapper(wiring.Component):
    """``core`` behind ``2 * pin_width + 3`` registered pins (see the module docstring)."""

    def __init__(self, core: wiring.Component, pin_width: int = 8) -> None:
        pin_width = as_int("pin_width", pin_width, 1, 64)
        if any(name in core.signature.members for name in ENTROPY_PORTS):
            raise ParameterError("the wrapper needs an on-chip random source (an off-chip one has an "
                                 "entropy port as wide as the matrix)")
        self._core = core
        self._pin_width = pin_width
        self._input = input_stream(core)
        self._input_width, self._result_width = stream_widths(core)
        super().__init__({
            "din": In(pin_width),
            "din_valid": In(1),
            "din_ready": Out(1),
            "dout": Out(pin_width),
            "dout_valid": Out(1),
        })

    @property
    def core(self) -> wiring.Component:
        return self._core

    @property
    def pin_width(self) -> int:
        return self._pin_width

    @property
    def input_name(self) -> str:
        """The core's input stream (``load`` or ``pixels``)."""
        return self._input

    @property
    def chunks_in(self) -> int:
        """Chunks per input beat."""
        return -(-self._input_width // self._pin_width)

    @property
    def chunks_out(self) -> int:
        """Chunks per result."""
        return -(-self._result_width // self._pin_width)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.core = core = self._core
        pw, n_in, n_out = self._pin_width, self.chunks_in, self.chunks_out

        # --- In: registered pins -> shift register -> one beat of the core's input stream ---
        # Chunk counts are kept as shift registers of marks (no adder, no compare): the
        # wrapper must never be the critical path of the design it measures.
        din_q = Signal(pw)
        din_valid_q = Signal()
        m.d.sync += [din_q.eq(self.din), din_valid_q.eq(self.din_valid)]
        beat = Signal(n_in * pw)
        # After j chunks the top j bits of ``mark`` are ones: mark[k] = 1 iff j >= n_in - k.
        mark = Signal(n_in)
        sink = getattr(core, self._input)
        m.d.comb += [sink.payload.eq(beat[: self._input_width]), sink.valid.eq(mark[0])]
        with m.If(din_valid_q):
            m.d.sync += beat.eq(Cat(beat[pw:], din_q))  # the first chunk ends lowest
        kept = Signal.like(mark)
        m.d.comb += kept.eq(Mux(sink.valid & sink.ready, 0, mark))
        mark_next = Signal.like(mark)
        m.d.comb += mark_next.eq(Mux(din_valid_q, Cat(kept[1:], Const(1, 1)), kept))
        m.d.sync += mark.eq(mark_next)

        def fits(k: int) -> object:  # j + k < n_in after this cycle
            return ~mark_next[k] if k < n_in else Const(0, 1)

        # A chunk driven now lands next cycle: allow another only if both still fit.
        m.d.sync += self.din_ready.eq(Mux(self.din_valid, fits(1), fits(0)))

        # --- Out: one result -> shift register -> registered pins ---
        out = Signal(n_out * pw)
        busy = Signal(n_out)  # ones for the chunks still to send
        m.d.comb += core.result.ready.eq(~busy[0])
        for name in core.signature.members:
            if name.endswith("_result"):  # a declared pass's results: taken as they come
                m.d.comb += getattr(core, name).ready.eq(1)
        take = core.result.valid & ~busy[0]
        # The take loads the whole shift register (a full machine's result: 440 bits): each group
        # of OUT_GROUP chunks has a registered copy of ``~busy[0]`` (``free_rep<g>``, loaded with
        # its next value, kept apart by the flow), so no single net reaches every bit.
        payload = core.result.payload.as_value()
        for g in range(-(-n_out // OUT_GROUP)):
            free = Signal(name=f"free_rep{g}", init=1)
            m.d.sync += free.eq(~Mux(take, 1, busy[1] if n_out > 1 else 0))
            lo, hi = g * OUT_GROUP, min(n_out, (g + 1) * OUT_GROUP)
            bits = slice(lo * pw, hi * pw)
            nxt = Cat(out, Const(0, pw))[(lo + 1) * pw:(hi + 1) * pw]
            with m.If(core.result.valid & free):
                m.d.sync += [out[bits].eq(Cat(payload, Const(0, n_out * pw))[bits]), busy[lo:hi].eq(-1)]
            with m.Else():
                m.d.sync += [out[bits].eq(nxt), busy[lo:hi].eq(Cat(busy, Const(0, 1))[lo + 1:hi + 1])]
        m.d.sync += [self.dout.eq(out[:pw]), self.dout_valid.eq(busy[0])]
        return m
