"""The Python twin of the board (``BoardCore``: UART bridge + StereoMachine), at the byte level.

``BoardTwin(params, model, width, results=...).feed(data)`` takes the bytes the host sends and
returns the bytes the board sends back: for headers, info requests, garbage and whole frames, byte
for byte what the RTL sends for the same input (``tests/fpga/boards/test_simulate.py`` holds the RTL to it).
It is put together as the RTL is, from its components' twins: the command parser's
(:class:`~.parser.HeaderParserTwin`), the frame receiver's (:class:`~.receiver.FrameReceiverTwin`),
the result serializers' (:class:`~.serializer.ResultSerializerTwin`, one per pass of the model);
:meth:`BoardTwin.answer` and :meth:`BoardTwin.end_record` are the protocol control's. A frame's results
are ``results(left, right)``: the machine model's on the host's words of that frame, from reset (the
board resets the StereoMachine at every frame it accepts), every pass's by pass name (or, for a model
without declared passes, the own pass's ``MachineResult``). Timing is not modelled: :meth:`silence` is
the board's receive timeout firing (the host went quiet mid-frame), :meth:`reset` a board reset; and a
model with declared passes gets each pass's records whole, the declared passes' first, where the RTL
interleaves them as its machines give them (each pass's records in its order, the end record the same).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping

import numpy as np

from bayesmachine.hdl.frontend.passes import pass_row_pixels
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.region import OutputRegion
from bayesmachine.sim.results import MachineResult

from . import protocol as pr
from .parser import Header, HeaderParserTwin
from .protocol import board_passes
from .receiver import FrameReceiverTwin
from .serializer import ResultSerializerTwin

__all__ = ["BoardTwin"]

FrameResults = Callable[[np.ndarray, np.ndarray], "MachineResult | Mapping[str, MachineResult]"]


class BoardTwin:
    """A board built for ``params``, ``model`` and ``width`` (see the module text); ``results``
    gives the model's results of a frame (left, right) from reset."""

    def __init__(self, params: MachineParams, model: ModelParams, width: int, *, results: FrameResults,
                 rx_fifo_log2: int = 12) -> None:
        self.params, self.model, self.width = params, model, width
        self.results = results
        self.passes = board_passes(params, model)
        self.fingerprint = pr.board_fingerprint(params.to_dict(), model.to_dict(), width)
        self.info = pr.info_payload(width, params.rows, rx_fifo_log2, self.fingerprint)
        self._parser = HeaderParserTwin()
        self._receiver = FrameReceiverTwin(width=width, dmax=model.dmax, margin=model.margin)
        self._frame: tuple[int, int] | None = None  # seq, fields while receiving a frame
        self._pairs: list[tuple[int, int]] = []

    def reset(self) -> bytes:
        """A board reset: whatever was received is dropped; the board says hello."""
        self._parser = HeaderParserTwin()
        self._frame = None
        return pr.encode_record(pr.HELLO, 0, self.info)

    def silence(self) -> bytes:
        """The receive timeout: a frame still receiving ends with status TIMEOUT. (The RTL sends
        the results of the pixels it had before its end record, and counts them in it; the twin
        computes none before a frame is complete: the host discards them either way.)"""
        if self._frame is None:
            return b""
        seq = self._frame[0]
        self._frame = None
        return pr.encode_record(pr.END, seq, struct.pack("<BII", pr.STATUS_TIMEOUT, 0, 0))

    def feed(self, data: bytes) -> bytes:
        out = bytearray()
        for byte in data:
            if self._frame is None:
                header = self._parser.feed(byte)
                if header is not None:
                    out += self.answer(header)
                continue
            pair = self._receiver.feed(byte)
            if pair is not None:
                self._pairs.append(pair[:2])
            if self._receiver.done:
                out += self._finish_frame()
        return bytes(out)

    def answer(self, header: Header) -> bytes:
        """The board's answer to a record: refused, the info, or a frame accepted (then its pixels
        are expected)."""
        seq = header.seq
        if not header.crc_ok:
            return pr.encode_record(pr.ERROR, seq, struct.pack("<BH", pr.ERR_HEADER, 0))
        if header.type == pr.INFO:
            return pr.encode_record(pr.INFO, seq, self.info)
        if header.type != pr.FRAME:
            return pr.encode_record(pr.ERROR, seq, struct.pack("<BH", pr.ERR_TYPE, header.type))
        fields, width, height = struct.unpack("<BHH", header.payload[:5])
        fields &= pr.FIELDS_ALL
        if width != self.width or height < 2 * self.model.margin + 1:
            return pr.encode_record(pr.ERROR, seq, struct.pack("<BH", pr.ERR_SIZE, self.width))
        self._frame = (seq, fields)
        self._receiver.start(height)
        self._pairs = []
        rows = OutputRegion(height, width, self.model.dmax, self.model.margin).shape[0]
        results = rows * sum(pass_row_pixels(self.model, bp.name, width) for bp in self.passes)
        return pr.encode_record(pr.START, seq, struct.pack("<BHHI", fields, width, height, results))

    @staticmethod
    def end_record(seq: int, status: int, sent: int, crc: int) -> bytes:
        """A frame's end record: its status, the result records sent (every pass's) and the XOR of each
        pass's records' CRC-32."""
        return pr.encode_record(pr.END, seq, struct.pack("<BII", status, sent, crc))

    def _finish_frame(self) -> bytes:
        assert self._frame is not None
        seq, fields = self._frame
        self._frame = None
        pairs = np.array(self._pairs, np.uint8).reshape(-1, self.width, 2)
        res = self.results(pairs[..., 0].copy(), pairs[..., 1].copy())
        if isinstance(res, MachineResult):
            res = {self.model.passes[-1].name: res}
        records, sent, crc = b"", 0, 0
        for bp in self.passes:  # the declared passes' records, then the own pass's
            serializer = ResultSerializerTwin(bp.params, bp.tag)
            records += serializer.send(res[bp.name], fields)
            sent, crc = sent + serializer.sent, crc ^ serializer.crc
        status = pr.STATUS_OK if self._receiver.crc_ok else pr.STATUS_CHECKSUM
        return records + self.end_record(seq, status, sent, crc)
