"""The board's serial protocol: one definition of every record, for the RTL bridge, its Python twin
and the host link (no Amaranth here).

Two kinds of traffic share the link (8N1, little-endian fields):

- **Control records**, 16 bytes each, both ways: ``'B' 'M'`` (sync), a type byte, a sequence
  number, 10 payload bytes, and a CRC-16/CCITT-FALSE of the first 14 bytes (low byte first).
- **Bulk bytes** inside a frame: host -> board, ``width x height`` pixel pairs (left, right) in
  raster order, then the CRC-32 (zlib's) of those bytes; board -> host, one result record per
  output pixel: ``'R'`` and a body of the fields asked for (:class:`ResultFormat`), and one per pixel
  of each pass the model runs before its own (census-lr's right pass): the pass's tag
  (:func:`pass_tag`: ``'a'`` for the first) and its machine's fields. The records of the passes
  interleave as the machines give them; each pass's records come in its own raster order.

Host -> board: ``F`` (a frame follows: fields, width, height) and ``I`` (ask for the board's info).
Board -> host: ``H`` (hello: sent after every reset, the info payload), ``I`` (info),
``S`` (frame accepted: the results that will come, every pass's), result records, ``E`` (frame end: a
status, the records sent and the XOR of each pass's records' CRC-32, tags included: with one pass, the
CRC-32 of its records) and ``X`` (a header refused: bad CRC, unknown type, a size the board was not
built for).

A frame's results are accepted only with an ``E`` of status ``OK`` whose count and CRC-32 match
the records received: a garbled, dropped or extra byte in either direction, or a board reset in
the middle (``H``), fails the frame, never silently; the host then sends it again.
"""

from __future__ import annotations

import binascii
import json
import struct
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError

if TYPE_CHECKING:
    from bayesmachine.models import ModelParams
    from bayesmachine.params import MachineParams

__all__ = [
    "BoardInfo",
    "BoardPass",
    "CONTROL_TYPES",
    "FIELD_COUNTS",
    "FIELD_CYCLES",
    "FIELDS_ALL",
    "MAX_PASSES",
    "PROTOCOL_VERSION",
    "RECORD_BYTES",
    "RESULT_TAG",
    "STATUS_NAMES",
    "SYNC",
    "Record",
    "ResultFormat",
    "board_fingerprint",
    "board_passes",
    "crc16",
    "crc32",
    "decode_record",
    "encode_record",
    "fields_from_names",
    "frame_header",
    "info_payload",
    "parse_info",
    "pass_tag",
]

PROTOCOL_VERSION = 2  # 2: the declared passes' records (their tags), the end record's XOR of CRCs
SYNC = b"BM"
RECORD_BYTES = 16  # sync 2, type 1, seq 1, payload 10, crc 2
PAYLOAD_BYTES = 10
RESULT_TAG = ord("R")  # a result record of the model's own pass
MAX_PASSES = 8  # declared passes a board carries: tags 'a' .. 'h'


def pass_tag(index: int) -> int:
    """The tag of a result record of the model's declared pass ``index`` (0: the first of
    ``model.passes``): ``'a'``, ``'b'``, ..."""
    index = as_int("index", index)
    if not 0 <= index < MAX_PASSES:
        raise ParameterError(f"index: a board carries at most {MAX_PASSES} declared passes, got pass index "
                             f"{index}", "index")
    return ord("a") + index

# Record types.
FRAME, INFO, HELLO, START, END, ERROR = (ord(c) for c in "FIHSEX")
CONTROL_TYPES = {FRAME: "frame", INFO: "info", HELLO: "hello", START: "start", END: "end", ERROR: "error"}

# Fields wanted (the frame header's ``fields``): MAP and flags always.
FIELD_COUNTS = 1
FIELD_CYCLES = 2
FIELDS_ALL = FIELD_COUNTS | FIELD_CYCLES
FIELD_NAMES = {"map": 0, "counts": FIELD_COUNTS, "cycles": FIELD_CYCLES}


def fields_from_names(text: str) -> int:
    """The ``fields`` byte of a comma-separated list of ``map``, ``counts``, ``cycles``.

    The MAP and its flags always come; ``counts`` and ``cycles`` are the optional fields. A
    MAP-only record is the tag and the MAP's bytes, without one byte per counter: the link's
    frame time falls with it."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise ValueError("--board-fields: give map, counts, cycles or a comma-separated list of them")
    fields = 0
    for n in names:
        if n not in FIELD_NAMES:
            raise ValueError(f"--board-fields: unknown field {n!r} (map, counts, cycles)")
        fields |= FIELD_NAMES[n]
    return fields

# E statuses.
STATUS_OK, STATUS_CHECKSUM, STATUS_TIMEOUT, STATUS_OVERFLOW = 0, 1, 2, 3
STATUS_NAMES = {
    STATUS_OK: "ok",
    STATUS_CHECKSUM: "the pixels' checksum did not match",
    STATUS_TIMEOUT: "the pixels stopped coming before the frame was complete (a byte lost?)",
    STATUS_OVERFLOW: "the board's receive buffer overflowed",
}
# X codes.
ERR_HEADER, ERR_TYPE, ERR_SIZE = 1, 2, 3
ERROR_NAMES = {
    ERR_HEADER: "a header with a bad checksum",
    ERR_TYPE: "an unknown record type",
    ERR_SIZE: "a frame size the board was not built for",
}


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (polynomial 0x1021, initial 0xFFFF, no reflection) of the control records."""
    return binascii.crc_hqx(data, crc)


def crc32(data: bytes, crc: int = 0) -> int:
    """CRC-32 (zlib's) of a frame's pixels and of its result records."""
    return zlib.crc32(data, crc)


@dataclass(frozen=True)
class Record:
    kind: int  # a key of CONTROL_TYPES
    seq: int
    payload: bytes  # PAYLOAD_BYTES

    @property
    def name(self) -> str:
        return CONTROL_TYPES.get(self.kind, repr(chr(self.kind)))


def encode_record(kind: int, seq: int, payload: bytes = b"") -> bytes:
    """A 16-byte control record (``payload`` padded with zeros to 10 bytes)."""
    if len(payload) > PAYLOAD_BYTES:
        raise ValueError(f"a record's payload has at most {PAYLOAD_BYTES} bytes, got {len(payload)}")
    body = SYNC + bytes([kind, seq & 0xFF]) + payload.ljust(PAYLOAD_BYTES, b"\0")
    return body + struct.pack("<H", crc16(body))


def decode_record(raw: bytes) -> Record | None:
    """The record in 16 bytes starting with the sync, or None when its CRC does not match."""
    if len(raw) != RECORD_BYTES or raw[:2] != SYNC:
        return None
    if struct.unpack("<H", raw[14:16])[0] != crc16(raw[:14]):
        return None
    return Record(raw[2], raw[3], raw[4:14])


def frame_header(seq: int, fields: int, width: int, height: int) -> bytes:
    """The ``F`` record that starts a frame."""
    return encode_record(FRAME, seq, struct.pack("<BHH", fields, width, height))


def info_payload(width: int, rows: int, rx_fifo_log2: int, fingerprint: int) -> bytes:
    """The payload of ``I`` and ``H``: version, width, rows, log2 of the receive buffer, fingerprint."""
    return struct.pack("<BHHBI", PROTOCOL_VERSION, width, rows, rx_fifo_log2, fingerprint)


@dataclass(frozen=True)
class BoardInfo:
    version: int
    width: int
    rows: int
    rx_fifo_bytes: int
    fingerprint: int


def parse_info(payload: bytes) -> BoardInfo:
    version, width, rows, log2, fingerprint = struct.unpack("<BHHBI", payload[:10])
    return BoardInfo(version, width, rows, 1 << log2, fingerprint)


def board_fingerprint(params_dict: dict, model_dict: dict, width: int) -> int:
    """A 32-bit hash of what a board's results depend on: the machine, the model, the width."""
    blob = json.dumps({"machine": params_dict, "model": model_dict, "width": width}, sort_keys=True)
    return zlib.crc32(blob.encode())


def _bytes_of(bits: int) -> int:
    return (bits + 7) // 8


@dataclass(frozen=True)
class ResultFormat:
    """A result record: its ``tag`` (``'R'``, or a declared pass's :func:`pass_tag`), then
    ``map | nomatch << map_width | timeout << map_width + 1`` in ``head_bytes``; then, if asked for, each
    row's count (an overflow counter, or a log machine's weight: ``MachineParams.readout_max``) in
    ``count_bytes`` and the cycles in ``cycle_bytes`` (the result layout's fields, each byte aligned)."""

    map_width: int
    count_width: int
    cycle_width: int
    rows: int
    fields: int
    tag: int = RESULT_TAG

    @classmethod
    def of(cls, params: object, fields: int, tag: int = RESULT_TAG) -> ResultFormat:
        if not 0 <= fields <= FIELDS_ALL:
            raise ValueError(f"fields must be in 0..{FIELDS_ALL}, got {fields}")
        return cls(params.map_width, params.readout_max.bit_length(), params.cycle_width,  # type: ignore[attr-defined]
                   params.rows, fields, tag)  # type: ignore[attr-defined]

    @property
    def head_bytes(self) -> int:
        return _bytes_of(self.map_width + 2)

    @property
    def count_bytes(self) -> int:
        return _bytes_of(self.count_width)

    @property
    def cycle_bytes(self) -> int:
        return _bytes_of(self.cycle_width)

    @property
    def body_bytes(self) -> int:
        n = self.head_bytes
        if self.fields & FIELD_COUNTS:
            n += self.rows * self.count_bytes
        if self.fields & FIELD_CYCLES:
            n += self.cycle_bytes
        return n

    @property
    def record_bytes(self) -> int:
        return 1 + self.body_bytes

    def encode(
        self,
        map_: np.ndarray,
        nomatch: np.ndarray,
        timeout: np.ndarray,
        counts: np.ndarray,
        cycles: np.ndarray,
    ) -> bytes:
        """The records of these results, in order."""
        n = len(map_)
        parts = [np.full((n, 1), self.tag, np.uint8)]
        head = (
            np.asarray(map_, np.int64)
            | (np.asarray(nomatch, np.int64) << self.map_width)
            | (np.asarray(timeout, np.int64) << (self.map_width + 1))
        )
        parts.append(_le_bytes(head, self.head_bytes))
        if self.fields & FIELD_COUNTS:
            c = np.asarray(counts, np.int64).reshape(n, self.rows)
            parts.append(_le_bytes(c, self.count_bytes).reshape(n, -1))
        if self.fields & FIELD_CYCLES:
            parts.append(_le_bytes(np.asarray(cycles, np.int64), self.cycle_bytes))
        return np.concatenate(parts, axis=1).tobytes()

    def decode(self, records: bytes) -> dict[str, np.ndarray]:
        """The fields of consecutive records of this format (tags checked): ``map``, ``nomatch``,
        ``timeout`` and, when asked for, ``counts`` (P, rows) and ``cycles``."""
        size = self.record_bytes
        if len(records) % size:
            raise ValueError(f"{len(records)} bytes are not whole {size}-byte result records")
        raw = np.frombuffer(records, np.uint8).reshape(-1, size)
        if raw.size and not np.all(raw[:, 0] == self.tag):
            raise ValueError("a result record does not start with its tag")
        at = 1
        head = _from_le(raw[:, at : at + self.head_bytes])
        at += self.head_bytes
        out = {
            "map": head & ((1 << self.map_width) - 1),
            "nomatch": ((head >> self.map_width) & 1).astype(bool),
            "timeout": ((head >> (self.map_width + 1)) & 1).astype(bool),
        }
        if self.fields & FIELD_COUNTS:
            span = self.rows * self.count_bytes
            c = raw[:, at : at + span].reshape(-1, self.rows, self.count_bytes)
            out["counts"] = _from_le(c)
            at += span
        if self.fields & FIELD_CYCLES:
            out["cycles"] = _from_le(raw[:, at : at + self.cycle_bytes])
        return out


def _le_bytes(values: np.ndarray, nbytes: int) -> np.ndarray:
    """(..., nbytes) uint8: each value little-endian."""
    v = np.asarray(values, np.uint64)[..., None]
    shifts = np.arange(nbytes, dtype=np.uint64) * np.uint64(8)
    return ((v >> shifts) & np.uint64(0xFF)).astype(np.uint8)


def _from_le(raw: np.ndarray) -> np.ndarray:
    shifts = np.arange(raw.shape[-1], dtype=np.int64) * 8
    return (raw.astype(np.int64) << shifts).sum(axis=-1)


@dataclass(frozen=True)
class BoardPass:
    """One pass's results on a board: the pass's ``name``, its machine on chip (``params``), its
    records' ``tag``."""

    name: str
    params: MachineParams
    tag: int


def board_passes(params: MachineParams, model: ModelParams) -> tuple[BoardPass, ...]:
    """Every pass of ``model`` whose results a board sends: the declared ones (census-lr's right pass) in
    the model's order, tags ``'a'``, ``'b'``, ... (:func:`pass_tag`), then the own pass (``'R'``):
    the transmit arbiter's order. ``ParameterError`` naming the model past :data:`MAX_PASSES`."""
    from bayesmachine.hdl.frontend.words import pass_params

    declared = model.passes[:-1]
    if len(declared) > MAX_PASSES:
        raise ParameterError(f"model: a board carries at most {MAX_PASSES} declared passes' results, the "
                             f"{model.name} model declares {len(declared)}", "model")
    out = [BoardPass(p.name, pass_params(model, params, p.name), pass_tag(i))
           for i, p in enumerate(declared)]
    return (*out, BoardPass(model.passes[-1].name, params, RESULT_TAG))
