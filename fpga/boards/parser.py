"""The command parser: the host's bytes into control records. It hunts for the sync ``'B' 'M'``, takes
the 14 bytes after it and checks their CRC-16 (:mod:`.protocol`); a record whose CRC does not match
comes out all the same, flagged, for the board to refuse. Its twin is :class:`HeaderParserTwin`
(per byte)."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from . import protocol as pr
from .streams import CRC16, header_layout

__all__ = ["Header", "HeaderParser", "HeaderParserTwin"]

_AFTER_SYNC = pr.RECORD_BYTES - 2  # type, sequence, payload and CRC
_CHECKED = pr.RECORD_BYTES - 4  # of those, the ones the CRC covers (with the sync)


class HeaderParser(wiring.Component):
    """Bytes in, control records out (see the module text).

    Attributes
    ----------
    bytes : ``In(stream.Signature(8))``
        The host's bytes; none is taken while a record waits at ``headers``.
    headers : ``Out(stream.Signature(header_layout()))``
        Each record after a sync, ``crc_ok`` set if its CRC matched.
    """

    def __init__(self) -> None:
        super().__init__({"bytes": In(stream.Signature(8)),
                          "headers": Out(stream.Signature(header_layout()))})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.crc = crc = CRC16.create()
        byte = self.bytes.payload
        got = self.bytes.valid & self.bytes.ready
        shift = Signal(8 * _AFTER_SYNC)  # the bytes after the sync, the first at bit 0
        count = Signal(range(_AFTER_SYNC))
        rec = self.headers.payload.record
        m.d.comb += [
            Cat(rec.type, rec.seq, rec.payload).eq(shift[: 8 * _CHECKED]),
            self.headers.payload.crc_ok.eq(crc.crc == shift[8 * _CHECKED :]),
            crc.data.eq(byte),
        ]
        with m.FSM():
            with m.State("SYNC0"):
                m.d.comb += [self.bytes.ready.eq(1), crc.start.eq(1)]
                with m.If(got & (byte == pr.SYNC[0])):
                    m.d.comb += crc.valid.eq(1)
                    m.next = "SYNC1"
            with m.State("SYNC1"):
                m.d.comb += self.bytes.ready.eq(1)
                with m.If(got & (byte == pr.SYNC[1])):
                    m.d.comb += crc.valid.eq(1)
                    m.d.sync += count.eq(0)
                    m.next = "RECORD"
                with m.Elif(got & (byte == pr.SYNC[0])):  # "BB": the second may start the sync
                    m.d.comb += [crc.start.eq(1), crc.valid.eq(1)]
                with m.Elif(got):
                    m.next = "SYNC0"
            with m.State("RECORD"):
                m.d.comb += [self.bytes.ready.eq(1), crc.valid.eq(got & (count < _CHECKED))]
                with m.If(got):
                    m.d.sync += [shift.eq(Cat(shift[8:], byte)), count.eq(count + 1)]
                    with m.If(count == _AFTER_SYNC - 1):
                        m.next = "OUT"
            with m.State("OUT"):
                m.d.comb += self.headers.valid.eq(1)
                with m.If(self.headers.ready):
                    m.next = "SYNC0"
        return m


@dataclass(frozen=True)
class Header:
    """A record as :class:`HeaderParser` gives it."""

    type: int
    seq: int
    payload: bytes
    crc_ok: bool


class HeaderParserTwin:
    """:class:`HeaderParser` byte by byte: :meth:`feed` returns the record a byte completes."""

    def __init__(self) -> None:
        self._state = "SYNC0"
        self._bytes = bytearray()

    def feed(self, byte: int) -> Header | None:
        if self._state == "SYNC0":
            self._state = "SYNC1" if byte == pr.SYNC[0] else "SYNC0"
        elif self._state == "SYNC1":
            if byte == pr.SYNC[1]:
                self._state, self._bytes = "RECORD", bytearray()
            elif byte != pr.SYNC[0]:
                self._state = "SYNC0"
        else:
            self._bytes.append(byte)
            if len(self._bytes) == _AFTER_SYNC:
                self._state = "SYNC0"
                raw = pr.SYNC + bytes(self._bytes)
                return Header(raw[2], raw[3], raw[4:14], pr.decode_record(raw) is not None)
        return None
