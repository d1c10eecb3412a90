"""The board's protocol, as a state machine between the other components: it answers the host's
records (:class:`~.parser.HeaderParser`'s), and runs a frame from its header to its end record:
the StereoMachine reset, the ``S`` record, the bytes routed to the :class:`~.receiver.FrameReceiver`,
then the ``E`` record once every result is sent (:class:`~.serializer.ResultSerializer`), or at once
when the receive timeout fires. Its twin is :class:`~.twin.BoardTwin`'s record handling
(:meth:`~.twin.BoardTwin.answer`, :meth:`~.twin.BoardTwin.end_record`).

After a reset it says hello (``H``). A frame is refused (``X``) unless it has the width the board
was built for and at least one output line.
"""

from __future__ import annotations

from amaranth.hdl import C, Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError
from bayesmachine.region import OutputRegion

from . import protocol as pr
from .streams import header_layout, record_layout

__all__ = ["ProtocolControl"]


class ProtocolControl(wiring.Component):
    """The protocol's state machine (see the module text).

    Parameters
    ----------
    width : int
        Pixels per line of the frames the board takes.
    dmax, margin : int
        The model's (its output region: :class:`~bayesmachine.region.OutputRegion`).
    info : bytes
        The payload of the ``H`` and ``I`` records (:func:`.protocol.info_payload`).
    row_results : int, optional
        The results per map row, every pass's (default the own pass's output pixels,
        ``region.shape[1]``; census-lr adds its right pass's every right map column).

    Attributes
    ----------
    region : OutputRegion
        The model's output region on ``width``-pixel lines (read-only).
    info : bytes
        The ``H`` and ``I`` payload (read-only).
    headers : ``In(stream.Signature(header_layout()))``
        The host's records.
    records : ``Out(stream.Signature(record_layout()))``
        The board's control records (to :class:`~.serializer.ControlSerializer`).
    hunting, receiving : ``Out(1)``
        The host's bytes go to the parser, to the frame receiver.
    frame_start, frame_stop : ``Out(1)``
        The frame receiver's ``start`` (a register: ``height`` holds the frame's by then) and ``stop``.
    height : ``Out(16)``
        The frame's lines.
    frame_done, crc_ok : ``In(1)``
        The frame receiver's ``done`` and ``crc_ok``.
    fields : ``Out(2)``
        The optional result fields the frame asked for.
    clear_results : ``Out(1)``
        A frame starts: the result serializer's counts and CRC start again.
    take_results : ``Out(1)``
        The machine's results may be taken (not while a frame is given up or the machine reset).
    results_sent, results_crc : ``In(32)``
        The result records sent (every pass's) and the XOR of each pass's records' CRC-32.
    results_busy : ``In(1)``
        A result serializer holds a result.
    machine_reset : ``Out(1)``
        Resets the StereoMachine (a register: at every frame accepted and given up).
    dropped : ``In(1)``
        A received byte was dropped (the receive buffer was full).
    timed_out : ``In(1)``
        The receive timeout fired.
    in_frame, error, overflow : ``Out(1)``
        A frame is in progress; the last frame or header failed; a byte was dropped during the last frame.
    busy : ``Out(1)``
        Anything to do: a record to answer or to send, a frame in progress, the hello after a reset.
    """

    def __init__(self, *, width: int, dmax: int, margin: int, info: bytes,
                 row_results: int | None = None) -> None:
        self._region = OutputRegion(2 * margin + 1, width, dmax, margin)  # checks the three
        if not isinstance(info, bytes) or len(info) != pr.PAYLOAD_BYTES:
            raise ValueError(f"info must be {pr.PAYLOAD_BYTES} bytes (protocol.info_payload), got {info!r}")
        own = self._region.shape[1]
        row_results = own if row_results is None else row_results
        row_results = as_int("row_results", row_results)
        if not own <= row_results < 1 << 16:
            raise ParameterError(f"row_results must be in [{own}, 65535] (the own pass's {own} and the "
                                 f"declared passes'), got {row_results}", "row_results")
        self._row_results = row_results
        self._info = info
        super().__init__({
            "headers": In(stream.Signature(header_layout())),
            "records": Out(stream.Signature(record_layout())),
            "hunting": Out(1), "receiving": Out(1), "frame_start": Out(1), "frame_stop": Out(1),
            "height": Out(16), "frame_done": In(1), "crc_ok": In(1), "fields": Out(2),
            "clear_results": Out(1), "take_results": Out(1), "results_sent": In(32), "results_crc": In(32),
            "results_busy": In(1), "machine_reset": Out(1), "dropped": In(1), "timed_out": In(1),
            "in_frame": Out(1), "error": Out(1), "overflow": Out(1), "busy": Out(1),
        })

    @property
    def region(self) -> OutputRegion:
        return self._region  # its image_height is a placeholder: frames have any number of lines

    @property
    def info(self) -> bytes:
        return self._info

    @property
    def row_results(self) -> int:
        return self._row_results

    def _emit(self, m: Module, kind: int, seq: Value, payload: Value) -> None:
        """Offer a control record (only while ``records`` is free)."""
        rec = self.records.payload
        payload = payload.as_unsigned()
        m.d.sync += [self.records.valid.eq(1), rec.type.eq(kind), rec.seq.eq(seq),
                     rec.payload.eq(Cat(payload, C(0, 8 * pr.PAYLOAD_BYTES - len(payload))))]

    def _answer(self, m: Module, info: Value, seq: Value, expected: Signal, rows: Signal,
                columns: Signal) -> None:
        """The host's record at ``headers``: answered, or a frame started (then state COUNT)."""
        header = self.headers.payload
        rec, width = header.record, self._region.image_width
        fields, h_width, height = rec.payload[0:2], rec.payload[8:24], rec.payload[24:40]

        def refuse(payload: Value) -> None:
            self._emit(m, pr.ERROR, rec.seq, payload)
            m.d.sync += self.error.eq(1)

        with m.If(~header.crc_ok):
            refuse(C(pr.ERR_HEADER, 8))
        with m.Elif(rec.type == pr.INFO):
            self._emit(m, pr.INFO, rec.seq, info)
        with m.Elif(rec.type != pr.FRAME):
            refuse(Cat(C(pr.ERR_TYPE, 8), rec.type, C(0, 8)))
        with m.Elif((h_width != width) | (height < 2 * self._region.margin + 1)):
            refuse(Cat(C(pr.ERR_SIZE, 8), C(width, 16)))
        with m.Else():  # a frame: reset the machine, count the results to come
            m.d.comb += self.clear_results.eq(1)
            m.d.sync += [self.machine_reset.eq(1), self.frame_start.eq(1), seq.eq(rec.seq),
                         self.fields.eq(fields), self.height.eq(height), self.overflow.eq(0), expected.eq(0),
                         rows.eq(height - 2 * self._region.margin), columns.eq(self._row_results)]
            m.next = "COUNT"

    def _end(self, m: Module, seq: Value, status: Value) -> None:
        """The frame's end record (``status`` 8 bits), the error LED from its status."""
        self._emit(m, pr.END, seq, Cat(status, self.results_sent, self.results_crc))
        m.d.sync += self.error.eq(status != pr.STATUS_OK)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        info = Const(int.from_bytes(self._info, "little"), 8 * pr.PAYLOAD_BYTES)
        free = ~self.records.valid
        seq = Signal(8)
        expected = Signal(32)
        rows, columns = Signal(16), Signal(32)  # (height - 2 margin) x columns, by shift and add
        with m.If(self.records.ready):
            m.d.sync += self.records.valid.eq(0)
        m.d.sync += [self.machine_reset.eq(0), self.frame_start.eq(0)]
        with m.If(self.dropped):
            m.d.sync += self.overflow.eq(1)
        with m.FSM(init="BOOT") as fsm:
            with m.State("BOOT"):
                with m.If(free):
                    self._emit(m, pr.HELLO, C(0, 8), info)
                    m.next = "IDLE"
            with m.State("IDLE"):
                m.d.comb += [self.hunting.eq(1), self.headers.ready.eq(free)]
                with m.If(self.headers.valid & free):
                    self._answer(m, info, seq, expected, rows, columns)
            with m.State("COUNT"):
                with m.If(rows == 0):
                    with m.If(free):
                        width = C(self._region.image_width, 16)
                        self._emit(m, pr.START, seq, Cat(self.fields, C(0, 6), width, self.height, expected))
                        m.next = "FRAME"
                with m.Else():
                    with m.If(rows[0]):
                        m.d.sync += expected.eq(expected + columns)
                    m.d.sync += [rows.eq(rows >> 1), columns.eq(columns << 1)]
            with m.State("FRAME"):
                m.d.comb += self.receiving.eq(1)
                with m.If(self.frame_done):
                    m.next = "DRAIN"
                with m.Elif(self.timed_out):
                    m.d.comb += self.frame_stop.eq(1)
                    m.next = "ABORT"
            with m.State("DRAIN"):
                with m.If(free & (self.results_sent == expected)):
                    checked = Mux(self.crc_ok, C(pr.STATUS_OK, 8), C(pr.STATUS_CHECKSUM, 8))
                    self._end(m, seq, Mux(self.overflow, C(pr.STATUS_OVERFLOW, 8), checked))
                    m.next = "IDLE"
            with m.State("ABORT"):
                with m.If(free & ~self.results_busy):
                    self._end(m, seq, Mux(self.overflow, C(pr.STATUS_OVERFLOW, 8), C(pr.STATUS_TIMEOUT, 8)))
                    m.d.sync += self.machine_reset.eq(1)
                    m.next = "IDLE"
        m.d.comb += [
            self.in_frame.eq(~fsm.ongoing("BOOT") & ~fsm.ongoing("IDLE")),
            self.take_results.eq(~fsm.ongoing("ABORT") & ~self.machine_reset),
            self.busy.eq(~fsm.ongoing("IDLE") | self.headers.valid | self.records.valid),
        ]
        return m
