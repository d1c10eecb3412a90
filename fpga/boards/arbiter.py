"""The transmit arbiter: the control records and the result records (one stream per pass of the model)
onto the one UART, a whole record at a time, through a byte register (the record multiplexers and the
CRC's XORs stay off the UART's path). Between records a waiting control record goes first, then the
result streams in their order (the declared passes' first: the own pass reads their MAPs). Its twin is
:class:`TransmitArbiterTwin` (per cycle)."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Module, Signal, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int

from .streams import packet_layout

__all__ = ["TransmitArbiter", "TransmitArbiterTwin"]


class TransmitArbiter(wiring.Component):
    """Record streams onto one byte stream, records whole, control first.

    Parameters
    ----------
    results : int
        The result streams (1 .. 9: one per pass of the model).

    Attributes
    ----------
    control : ``In(stream.Signature(packet_layout()))``
        The control records' bytes, ``last`` on each record's last byte.
    results : ``In(stream.Signature(packet_layout())).array(results)``
        The result records' bytes, one stream per pass, in priority order.
    bytes : ``Out(stream.Signature(8))``
        To the UART transmitter (a register).
    busy : ``Out(1)``
        A record is being passed on, or a byte waits in the register.
    """

    def __init__(self, *, results: int = 1) -> None:
        self._results = results = as_int("results", results, 1, 9)
        packets = stream.Signature(packet_layout())
        super().__init__({"control": In(packets), "results": In(packets).array(results),
                          "bytes": Out(stream.Signature(8)), "busy": Out(1)})

    @property
    def result_streams(self) -> int:
        return self._results

    def elaborate(self, platform: object) -> Module:
        m = Module()
        sources = [self.control, *self.results]
        owners = [Signal(name=f"owner_{i}") for i in range(len(sources))]
        idle = ~_any(owners)
        load = Signal()  # the owner's byte goes into the register
        m.d.comb += [load.eq(~self.bytes.valid | self.bytes.ready),
                     self.busy.eq(_any(owners) | self.bytes.valid)]
        for owner, source in zip(owners, sources, strict=True):
            m.d.comb += source.ready.eq(owner & load)
        with m.If(idle):
            for i, (owner, source) in enumerate(zip(owners, sources, strict=True)):
                with (m.If if i == 0 else m.Elif)(source.valid):
                    m.d.sync += owner.eq(1)
        with m.If(self.bytes.ready):
            m.d.sync += self.bytes.valid.eq(0)
        for owner, source in zip(owners, sources, strict=True):
            with m.If(source.valid & source.ready):
                m.d.sync += [self.bytes.valid.eq(1), self.bytes.payload.eq(source.payload.data)]
                with m.If(source.payload.last):
                    m.d.sync += owner.eq(0)
        return m


def _any(values: list[Signal]) -> Value:
    out = values[0]
    for v in values[1:]:
        out = out | v
    return out


@dataclass
class TransmitArbiterTwin:
    """:class:`TransmitArbiter` cycle by cycle: :meth:`step` takes this cycle's inputs, returns its
    outputs (read before the clock edge), then takes the edge."""

    owner: int | None = None  # None, 0 (control) or 1 + the result stream's index
    valid: bool = False
    byte: int = 0

    def step(self, control: tuple[bool, int, bool], results: list[tuple[bool, int, bool]],
             ready: bool) -> dict[str, object]:
        """``control`` and each of ``results``: (valid, byte, last) offered; ``ready``: the UART takes a
        byte. Returns ``control_ready``, ``results_ready`` (one per stream), ``valid``, ``byte``, ``busy``."""
        load = not self.valid or ready
        sources = [control, *results]
        taken = [self.owner == i and load for i in range(len(sources))]
        out = {"control_ready": taken[0], "results_ready": taken[1:], "valid": self.valid, "byte": self.byte,
               "busy": self.owner is not None or self.valid}
        owner = self.owner
        if owner is None:
            owner = next((i for i, (valid, _, _) in enumerate(sources) if valid), None)
        if ready:
            self.valid = False
        for i, (valid, byte, last) in enumerate(sources):
            if valid and taken[i]:
                self.valid, self.byte = True, byte
                if last:
                    owner = None
        self.owner = owner
        return out
