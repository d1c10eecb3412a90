"""The frame receiver: a frame's bytes, once the board has accepted its header, into the
StereoMachine's pixel stream. The bytes are ``width x height`` pairs (left, right) in raster order,
then the CRC-32 of those bytes (:mod:`.protocol`); the receiver checks it and counts the output
pixels it fed (those of the model's output region, :class:`~bayesmachine.region.OutputRegion`). Its
twin is :class:`FrameReceiverTwin` (per byte)."""

from __future__ import annotations

import zlib

from amaranth.hdl import Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.signatures import pixel_in_layout
from bayesmachine.region import OutputRegion

from .streams import CRC32

__all__ = ["FrameReceiver", "FrameReceiverTwin"]


class FrameReceiver(wiring.Component):
    """A frame's bytes in, its pixel pairs out (see the module text).

    Parameters
    ----------
    width : int
        Pixels per line.
    dmax, margin : int
        The model's: its output region starts ``margin`` lines down and ``dmax + 2 margin``
        columns in (the columns from which every disparity's window lies in the image).

    Attributes
    ----------
    region : OutputRegion
        The model's output region on ``width``-pixel lines (read-only).
    start : ``In(1)``
        A frame of ``height`` lines begins (its header was accepted).
    stop : ``In(1)``
        The frame is given up (the receive timeout): back to idle.
    height : ``In(16)``
        Lines of the frame (read at ``start``).
    bytes : ``In(stream.Signature(8))``
        The frame's bytes; taken only while receiving.
    pixels : ``Out(stream.Signature(pixel_in_layout()))``
        The pairs; ``first`` on the frame's first.
    waiting : ``Out(1)``
        Waiting for the host's next byte.
    done : ``Out(1)``
        The CRC has come (until the next ``start``).
    crc_ok : ``Out(1)``
        With ``done``: it matched the pixels.
    fed : ``Out(32)``
        Output pixels fed since ``start``.
    """

    def __init__(self, *, width: int, dmax: int, margin: int) -> None:
        self._region = OutputRegion(1 << 15, width, dmax, margin)  # checks the three
        super().__init__({
            "start": In(1), "stop": In(1), "height": In(16), "bytes": In(stream.Signature(8)),
            "pixels": Out(stream.Signature(pixel_in_layout())), "waiting": Out(1), "done": Out(1),
            "crc_ok": Out(1), "fed": Out(32),
        })

    @property
    def region(self) -> OutputRegion:
        return self._region  # its image_height is a placeholder: frames have any number of lines

    def elaborate(self, platform: object) -> Module:
        m = Module()
        region = self._region
        col = Signal(range(region.image_width))
        line = Signal(16)
        height = Signal(16)
        trailer = Signal(range(4))
        m.submodules.crc = crc = CRC32.create()  # over the pixels and the CRC after them: its residue
        byte, got = self.bytes.payload, self.bytes.valid & self.bytes.ready
        pix = self.pixels.payload
        m.d.comb += [crc.data.eq(byte), crc.valid.eq(got), crc.start.eq(self.start),
                     self.crc_ok.eq(crc.match_detected), pix.first.eq((col == 0) & (line == 0))]
        def start_or_stop() -> None:  # in every state, over what the state would do
            with m.If(self.start):
                m.d.sync += [height.eq(self.height), col.eq(0), line.eq(0), trailer.eq(0), self.fed.eq(0)]
                m.next = "LEFT"
            with m.Elif(self.stop):
                m.next = "IDLE"

        with m.FSM():
            with m.State("IDLE"):
                start_or_stop()
            for state, field, after in (("LEFT", pix.left, "RIGHT"), ("RIGHT", pix.right, "PUSH")):
                with m.State(state):
                    m.d.comb += [self.bytes.ready.eq(1), self.waiting.eq(1)]
                    with m.If(got):
                        m.d.sync += field.eq(byte)
                        m.next = after
                    start_or_stop()
            with m.State("PUSH"):
                m.d.comb += self.pixels.valid.eq(1)
                with m.If(self.pixels.ready):
                    first_col = region.dmax + 2 * region.margin  # the output region's columns
                    with m.If((line >= 2 * region.margin) & (col >= first_col)):
                        m.d.sync += self.fed.eq(self.fed + 1)
                    m.d.sync += col.eq(col + 1)
                    m.next = "LEFT"
                    with m.If(col == region.image_width - 1):
                        m.d.sync += [col.eq(0), line.eq(line + 1)]
                        with m.If(line == height - 1):
                            m.next = "TRAILER"
                start_or_stop()
            with m.State("TRAILER"):
                m.d.comb += [self.bytes.ready.eq(1), self.waiting.eq(1)]
                with m.If(got):
                    m.d.sync += trailer.eq(trailer + 1)
                    with m.If(trailer == 3):
                        m.next = "DONE"
                start_or_stop()
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                start_or_stop()
        return m


class FrameReceiverTwin:
    """:class:`FrameReceiver` byte by byte: :meth:`start`, then :meth:`feed` each byte; it returns
    the pixel pair a byte completes."""

    def __init__(self, *, width: int, dmax: int, margin: int) -> None:
        self.region = OutputRegion(1 << 15, width, dmax, margin)
        self.height = 0
        self.done = False

    def start(self, height: int) -> None:
        self.height, self.done, self.fed = height, False, 0
        self._at, self._left, self._crc, self._trailer = 0, 0, 0, bytearray()

    def feed(self, byte: int) -> tuple[int, int, bool] | None:
        """(left, right, first) when ``byte`` completes a pair; None otherwise."""
        if self.done:
            raise ValueError("the frame is complete")
        pixels = 2 * self.region.image_width * self.height
        if self._at >= pixels:
            self._trailer.append(byte)
            self.done = len(self._trailer) == 4
            return None
        self._crc = zlib.crc32(bytes([byte]), self._crc)
        self._at += 1
        if self._at % 2:
            self._left = byte
            return None
        y, x = divmod(self._at // 2 - 1, self.region.image_width)
        k = self.region.margin
        self.fed += y >= 2 * k and x >= self.region.dmax + 2 * k
        return self._left, byte, self._at == 2

    @property
    def crc_ok(self) -> bool:
        return self.done and int.from_bytes(self._trailer, "little") == self._crc
