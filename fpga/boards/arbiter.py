"""The transmit arbiter: the control records and the result records onto the one UART, a whole
record at a time, through a byte register (the record multiplexers and the CRC's XORs stay off the
UART's path). Between records a waiting control record goes first. Its twin is
:class:`TransmitArbiterTwin` (per cycle)."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .streams import packet_layout

__all__ = ["TransmitArbiter", "TransmitArbiterTwin"]


class TransmitArbiter(wiring.Component):
    """Two record streams onto one byte stream, records whole, control first.

    Attributes
    ----------
    control, results : ``In(stream.Signature(packet_layout()))``
        The records' bytes, ``last`` on each record's last byte.
    bytes : ``Out(stream.Signature(8))``
        To the UART transmitter (a register).
    busy : ``Out(1)``
        A record is being passed on, or a byte waits in the register.
    """

    def __init__(self) -> None:
        packets = stream.Signature(packet_layout())
        super().__init__({"control": In(packets), "results": In(packets), "bytes": Out(stream.Signature(8)),
                          "busy": Out(1)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        owner_control, owner_results = Signal(), Signal()
        load = Signal()  # the owner's byte goes into the register
        m.d.comb += [
            load.eq(~self.bytes.valid | self.bytes.ready),
            self.control.ready.eq(owner_control & load),
            self.results.ready.eq(owner_results & load),
            self.busy.eq(owner_control | owner_results | self.bytes.valid),
        ]
        with m.If(~owner_control & ~owner_results):
            with m.If(self.control.valid):
                m.d.sync += owner_control.eq(1)
            with m.Elif(self.results.valid):
                m.d.sync += owner_results.eq(1)
        with m.If(self.bytes.ready):
            m.d.sync += self.bytes.valid.eq(0)
        for owner, source in ((owner_control, self.control), (owner_results, self.results)):
            with m.If(source.valid & source.ready):
                m.d.sync += [self.bytes.valid.eq(1), self.bytes.payload.eq(source.payload.data)]
                with m.If(source.payload.last):
                    m.d.sync += owner.eq(0)
        return m


@dataclass
class TransmitArbiterTwin:
    """:class:`TransmitArbiter` cycle by cycle: :meth:`step` takes this cycle's inputs, returns its
    outputs (read before the clock edge), then takes the edge."""

    owner: str = ""  # "", "control" or "results"
    valid: bool = False
    byte: int = 0

    def step(self, control: tuple[bool, int, bool], results: tuple[bool, int, bool],
             ready: bool) -> dict[str, object]:
        """``control``, ``results``: (valid, byte, last) offered; ``ready``: the UART takes a byte."""
        load = not self.valid or ready
        sources = {"control": control, "results": results}
        taken = {name: self.owner == name and load for name in sources}
        out = {"control_ready": taken["control"], "results_ready": taken["results"], "valid": self.valid,
               "byte": self.byte, "busy": bool(self.owner) or self.valid}
        owner = self.owner
        if not owner:
            owner = "control" if control[0] else "results" if results[0] else ""
        if ready:
            self.valid = False
        for name, (valid, byte, last) in sources.items():
            if valid and taken[name]:
                self.valid, self.byte = True, byte
                if last:
                    owner = ""
        self.owner = owner
        return out
