"""The Python twin of the board (``BoardCore``: UART bridge + StereoMachine), at the byte level.

``BoardTwin(params, model, width).feed(data)`` takes the bytes the host sends and returns the
bytes the board sends back: for headers, info requests, garbage and whole frames, byte for byte
what the RTL sends for the same input (``tests/test_board_sim.py`` holds the RTL to it). A
frame's results are the machine model's on the host's words of that frame, from reset (the board
resets the StereoMachine at every frame it accepts). Timing is not modelled: :meth:`silence` is
the board's receive timeout firing (the host went quiet mid-frame), :meth:`reset` a board reset.
"""

from __future__ import annotations

import struct

import numpy as np

from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams

from . import protocol as pr

__all__ = ["BoardTwin", "frame_results"]


def frame_results(params: MachineParams, model: ModelParams, left: np.ndarray, right: np.ndarray):
    """The machine model's results for one frame from reset (what the StereoMachine computes)."""
    from bayesmachine.host.features import model_features
    from bayesmachine.host.likelihoods import memory_words
    from bayesmachine.sim.model import MachineModel

    words = memory_words(model_features(left, model), model_features(right, model), model, params)
    with MachineModel(params) as engine:
        return engine.run(words)


class BoardTwin:
    """A board built for ``params``, ``model`` and ``width`` (see the module text)."""

    def __init__(
        self, params: MachineParams, model: ModelParams, width: int, *, rx_fifo_log2: int = 12
    ) -> None:
        self.params, self.model, self.width = params, model, width
        self.fingerprint = pr.board_fingerprint(params.to_dict(), model.to_dict(), width)
        self.info = pr.info_payload(width, params.rows, rx_fifo_log2, self.fingerprint)
        self._buf = bytearray()
        self._frame: tuple[int, int, int] | None = None  # seq, fields, height while receiving pixels

    def reset(self) -> bytes:
        """A board reset: whatever was received is dropped; the board says hello."""
        self._buf.clear()
        self._frame = None
        return pr.encode_record(pr.HELLO, 0, self.info)

    def silence(self) -> bytes:
        """The receive timeout: a frame still receiving ends with status TIMEOUT. (The RTL sends
        the results of the pixels it had before its end record, and counts them in it; the twin
        computes none before a frame is complete: the host discards them either way.)"""
        if self._frame is None:
            self._buf.clear()
            return b""
        seq = self._frame[0]
        self._frame = None
        self._buf.clear()
        return pr.encode_record(pr.END, seq, struct.pack("<BII", pr.STATUS_TIMEOUT, 0, 0))

    def feed(self, data: bytes) -> bytes:
        self._buf += data
        out = bytearray()
        while True:
            if self._frame is not None:
                seq, fields, height = self._frame
                need = self.width * height * 2 + 4
                if len(self._buf) < need:
                    return bytes(out)
                out += self._finish_frame(seq, fields, height, bytes(self._buf[:need]))
                del self._buf[:need]
                self._frame = None
                continue
            at = self._buf.find(pr.SYNC)
            if at < 0:
                # Keep a trailing 'B': it may start the next sync.
                del self._buf[: len(self._buf) - (1 if self._buf.endswith(b"B") else 0)]
                return bytes(out)
            del self._buf[:at]
            if len(self._buf) < pr.RECORD_BYTES:
                return bytes(out)
            raw = bytes(self._buf[: pr.RECORD_BYTES])
            del self._buf[: pr.RECORD_BYTES]
            out += self._header(raw)

    def _header(self, raw: bytes) -> bytes:
        seq = raw[3]
        rec = pr.decode_record(raw)
        if rec is None:
            return pr.encode_record(pr.ERROR, seq, struct.pack("<BH", pr.ERR_HEADER, 0))
        if rec.kind == pr.INFO:
            return pr.encode_record(pr.INFO, seq, self.info)
        if rec.kind != pr.FRAME:
            return pr.encode_record(pr.ERROR, seq, struct.pack("<BH", pr.ERR_TYPE, rec.kind))
        fields, width, height = struct.unpack("<BHH", rec.payload[:5])
        fields &= pr.FIELDS_ALL
        if width != self.width or height < 2 * self.model.margin + 1:
            return pr.encode_record(pr.ERROR, seq, struct.pack("<BH", pr.ERR_SIZE, self.width))
        self._frame = (seq, fields, height)
        edge = 2 * self.model.margin
        results = (height - edge) * (self.width - edge - self.model.dmax)
        return pr.encode_record(pr.START, seq, struct.pack("<BHHI", fields, width, height, results))

    def _finish_frame(self, seq: int, fields: int, height: int, data: bytes) -> bytes:
        pixels, (crc,) = data[:-4], struct.unpack("<I", data[-4:])
        pairs = np.frombuffer(pixels, np.uint8).reshape(height, self.width, 2)
        res = frame_results(self.params, self.model, pairs[..., 0].copy(), pairs[..., 1].copy())
        fmt = pr.ResultFormat.of(self.params, fields)
        records = fmt.encode(res.map, res.nomatch, res.timeout, res.counts, res.cycles)
        status = pr.STATUS_OK if pr.crc32(pixels) == crc else pr.STATUS_CHECKSUM
        end = pr.encode_record(pr.END, seq, struct.pack("<BII", status, len(res.map), pr.crc32(records)))
        return records + end
