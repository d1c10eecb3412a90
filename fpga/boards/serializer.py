"""The record transmitters: a control record, or one StereoMachine result, into the bytes the link
carries (:mod:`.protocol`), one byte per handshake of a :func:`~.streams.packet_layout` stream whose
``last`` marks a record's end (the arbiter sends records whole).

- :class:`ControlSerializer`: ``'B' 'M'``, the record, its CRC-16 computed on the way (its twin:
  :func:`.protocol.encode_record`).
- :class:`ResultSerializer`: one pass's results, its tag (``'R'`` for the model's own pass) and the
  fields a frame asked for (its twin: :class:`ResultSerializerTwin`, on
  :meth:`.protocol.ResultFormat.encode`); it counts the results it took and sent and keeps the CRC-32 of
  the bytes sent, for the frame's end record. :func:`.protocol.board_passes` says which passes a board
  sends, on which machine, with which tag.
"""

from __future__ import annotations

import zlib

from amaranth.hdl import Array, C, Cat, Module, Mux, Signal, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.hdl.signatures import result_layout
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.results import MachineResult

from . import protocol as pr
from .streams import CRC16, CRC32, packet_layout, record_layout

__all__ = ["ControlSerializer", "ResultSerializer", "ResultSerializerTwin"]


class ControlSerializer(wiring.Component):
    """A control record into its 16 bytes. The record is read where it is offered (the stream's
    payload holds still until ``ready``) and taken with its last byte.

    Attributes
    ----------
    records : ``In(stream.Signature(record_layout()))``
        The records to send.
    bytes : ``Out(stream.Signature(packet_layout()))``
        Their bytes, ``last`` on each record's CRC high byte.
    """

    def __init__(self) -> None:
        super().__init__({"records": In(stream.Signature(record_layout())),
                          "bytes": Out(stream.Signature(packet_layout()))})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.crc = crc = CRC16.create()
        rec = self.records.payload
        index = Signal(range(pr.RECORD_BYTES))
        payload = [rec.payload[8 * i : 8 * i + 8] for i in range(pr.PAYLOAD_BYTES)]
        sync = [C(pr.SYNC[0], 8), C(pr.SYNC[1], 8)]
        body = Array([*sync, rec.type, rec.seq, *payload, crc.crc[:8], crc.crc[8:]])
        last = index == pr.RECORD_BYTES - 1
        sent = self.bytes.valid & self.bytes.ready
        m.d.comb += [
            self.bytes.valid.eq(self.records.valid),
            self.bytes.payload.data.eq(body[index]),
            self.bytes.payload.last.eq(last),
            self.records.ready.eq(sent & last),
            # The CRC of the 14 bytes before it, a byte per handshake (it is ready the cycle after).
            crc.data.eq(self.bytes.payload.data),
            crc.start.eq(index == 0),
            crc.valid.eq(sent & (index < pr.RECORD_BYTES - 2)),
        ]
        with m.If(sent):
            m.d.sync += index.eq(Mux(last, 0, index + 1))
        return m


def _chunks(value: Value, nbytes: int) -> list[Value]:
    """``value`` as ``nbytes`` little-endian bytes (zero-extended)."""
    v = value.as_unsigned()
    v = Cat(v, C(0, nbytes * 8 - len(v))) if len(v) < nbytes * 8 else v
    return [v[8 * i : 8 * i + 8] for i in range(nbytes)]


class ResultSerializer(wiring.Component):
    """One result at a time into a record of the fields asked for (:class:`.protocol.ResultFormat`).

    Parameters
    ----------
    params : MachineParams
        The machine whose results come in (their layout: :func:`~bayesmachine.hdl.signatures.result_layout`).
    tag : int
        The records' first byte (``'R'``: the model's own pass; a declared pass's :func:`.protocol.pass_tag`).

    Attributes
    ----------
    results : ``In(stream.Signature(result_layout(params)))``
        The machine's results; one is taken when the last is sent.
    fields : ``In(2)``
        :data:`.protocol.FIELD_COUNTS` and :data:`.protocol.FIELD_CYCLES`: the optional fields sent
        (held while a frame's results go out).
    bytes : ``Out(stream.Signature(packet_layout()))``
        The records' bytes, ``last`` on each record's last byte.
    clear : ``In(1)``
        A new frame: the counts and the CRC start again.
    taken, sent : ``Out(32)``
        Results taken, records sent since ``clear``.
    crc : ``Out(32)``
        The CRC-32 (zlib's) of the bytes sent since ``clear``, tags included.
    busy : ``Out(1)``
        A result is held (taken, not all sent).
    """

    def __init__(self, *, params: MachineParams, tag: int = pr.RESULT_TAG) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
        tag = as_int("tag", tag)
        if tag not in (pr.RESULT_TAG, *map(pr.pass_tag, range(pr.MAX_PASSES))):
            raise ParameterError(f"tag must be 'R' or a pass's tag ('a' ...), got {tag}", "tag")
        self._params = params
        self._tag = tag
        super().__init__({
            "results": In(stream.Signature(result_layout(params))), "fields": In(2),
            "bytes": Out(stream.Signature(packet_layout())), "clear": In(1),
            "taken": Out(32), "sent": Out(32), "crc": Out(32), "busy": Out(1),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def tag(self) -> int:
        return self._tag

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p = self._params
        fmt = pr.ResultFormat.of(p, pr.FIELDS_ALL)
        res = Signal(result_layout(p))
        head = [C(self._tag, 8), *_chunks(Cat(res.map, res.nomatch, res.timeout), fmt.head_bytes)]
        counts = [b for i in range(p.rows) for b in _chunks(res.counts[i], fmt.count_bytes)]
        body = Array([*head, *counts, *_chunks(res.cycles, fmt.cycle_bytes)])
        end_head, end_counts, end = len(head) - 1, len(head) + len(counts) - 1, len(body) - 1
        index = Signal(range(len(body)))
        # The byte after this one, and whether this one ends the record, given the fields asked for.
        after, done = Signal.like(index), Signal()
        with m.If(index == end_head):
            m.d.comb += [after.eq(Mux(self.fields[0], end_head + 1, end_counts + 1)),
                         done.eq(~self.fields[0] & ~self.fields[1])]
        with m.Elif(index == end_counts):
            m.d.comb += [after.eq(end_counts + 1), done.eq(~self.fields[1])]
        with m.Else():
            m.d.comb += [after.eq(index + 1), done.eq(index == end)]

        m.submodules.crc = crc = CRC32.create()
        sent = self.bytes.valid & self.bytes.ready
        take = self.results.valid & self.results.ready
        m.d.comb += [
            self.results.ready.eq(~self.busy),
            self.bytes.valid.eq(self.busy),
            self.bytes.payload.data.eq(body[index]),
            self.bytes.payload.last.eq(done),
            crc.data.eq(self.bytes.payload.data), crc.valid.eq(sent), crc.start.eq(self.clear),
            self.crc.eq(crc.crc),
        ]
        with m.If(take):
            m.d.sync += [res.eq(self.results.payload), self.busy.eq(1), self.taken.eq(self.taken + 1)]
        with m.If(sent):
            m.d.sync += index.eq(Mux(done, 0, after))
            with m.If(done):
                m.d.sync += [self.busy.eq(0), self.sent.eq(self.sent + 1)]
        with m.If(self.clear):
            m.d.sync += [self.taken.eq(0), self.sent.eq(0)]
        return m


class ResultSerializerTwin:
    """:class:`ResultSerializer` record by record: the bytes of each result, the counts, the CRC."""

    def __init__(self, params: MachineParams, tag: int = pr.RESULT_TAG) -> None:
        self.params = params
        self.tag = tag
        self.clear()

    def clear(self) -> None:
        self.sent, self.crc = 0, 0

    def send(self, result: MachineResult, fields: int) -> bytes:
        """The ``R`` records of ``result``'s pixels."""
        records = pr.ResultFormat.of(self.params, fields, self.tag).encode(
            result.map, result.nomatch, result.timeout, result.counts, result.cycles)
        self.sent += len(result)
        self.crc = zlib.crc32(records, self.crc)
        return records
