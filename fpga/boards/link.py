"""The host side of the board's serial link: ``run --engine board --port PORT [--baud B]``.

:class:`BoardLink` speaks :mod:`.protocol` over any port with pyserial's ``read``/``write``/
``reset_input_buffer`` (a ``serial.Serial``, or the pseudo-terminal of ``board simulate``):

1. ``info()``: ask the board what it was built for (width, rows, receive buffer, fingerprint);
   no answer within ``timeout`` seconds is one clear error.
2. ``run_frame(left, right)``: the ``F`` header; once the board accepts it (``S``), the pixel
   pairs line by line, paced so the board's receive buffer cannot overflow (line y goes out once
   the own pass's results of image line y - lag are in, lag from the buffer's size), then the CRC-32.
   Every pass's records come (the declared passes' by their tags, :func:`~.protocol.board_passes`).
   The results are accepted only with an ``E`` of status OK whose count and CRCs match what came:
   anything else (a refused header, a board reset, a garbled or lost byte either way, silence)
   fails the attempt, and after the board has settled the frame is sent again, under a new
   sequence number, up to ``attempts`` times.

The pixel engine ``board`` (:class:`~.engine.BoardEngine`) runs frames through it for
``bayesmachine run --engine board``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bayesmachine.integrators import INTEGRATOR_KINDS
from bayesmachine.models import ModelParams
from bayesmachine.params import DEFAULT_INTEGRATOR, MachineParams
from bayesmachine.region import OutputRegion

from . import protocol as pr

__all__ = ["BoardError", "BoardLink", "LinkStats", "design_differences", "design_record",
           "fingerprint_message", "open_port", "record_design"]


class BoardError(RuntimeError):
    """The board did not answer, or kept failing a frame; the message says which and why."""


class _AttemptFailed(Exception):
    pass


@dataclass(frozen=True)
class _Frame:
    """What a frame sends and expects: its lines and the pixels' CRC, the record formats of every pass by
    tag (with the pass's name), the records to come in all, the own pass's results per output row, the
    lines before the first output row and the lines the receive buffer holds beyond the one awaited."""

    lines: list[bytes]
    trailer: bytes
    width: int
    fields: int
    formats: dict[int, tuple[str, pr.ResultFormat]]
    expected: int
    out_cols: int
    edge: int
    lag: int

    @property
    def height(self) -> int:
        return len(self.lines)


@dataclass
class _Attempt:
    """One attempt at a frame: its sequence number, whether the board accepted it, the lines sent, the
    records received (every pass's, and the own pass's: they pace the lines) and their bytes by tag."""

    seq: int
    records: dict[int, bytearray]
    started: bool = False
    sent: int = 0
    count: int = 0
    own: int = 0


@dataclass
class LinkStats:
    bytes_sent: int = 0
    bytes_received: int = 0
    garbage_bytes: int = 0  # received bytes that were neither a record nor a result
    attempts: int = 0
    failures: list[str] = field(default_factory=list)
    seconds: float = 0.0


class BoardLink:
    """The protocol over an open port (see the module text). ``timeout``: seconds of silence
    from the board before an attempt (or the first question) is given up."""

    def __init__(
        self, port, *, timeout: float = 2.0, attempts: int = 4, name: str = "the board", log=None
    ) -> None:  # noqa: ANN001 - a serial.Serial-like object
        self.port = port
        self.timeout = timeout
        self.attempts = attempts
        self.name = name
        self.stats = LinkStats()
        self._buf = bytearray()
        self._seq = 0
        self._log = log if log is not None else (lambda msg: print(msg, file=sys.stderr))
        self.board_info: pr.BoardInfo | None = None

    # --- bytes and records
    def _write(self, data: bytes) -> None:
        self.port.write(data)
        self.stats.bytes_sent += len(data)

    def _fill(self, wait: float) -> bool:
        """Read what is there (waiting up to ``wait`` s for the first byte); True if anything came."""
        self.port.timeout = wait
        first = self.port.read(1)
        if not first:
            return False
        more = self.port.read(self.port.in_waiting) if self.port.in_waiting else b""
        self._buf += first + more
        self.stats.bytes_received += len(first) + len(more)
        return True

    def _next_item(self, bodies: dict[int, int]):  # noqa: ANN202
        """The next complete item of the buffer: ("R", record bytes, its tag first) of a result record
        whose tag ``bodies`` knows (tag -> body bytes), or ("C", Record); None if incomplete. Bytes that
        start neither are dropped (counted as garbage)."""
        while self._buf:
            b = self._buf[0]
            if b in bodies:
                size = 1 + bodies[b]
                if len(self._buf) < size:
                    return None
                rec = bytes(self._buf[:size])
                del self._buf[:size]
                return ("R", rec)
            if b == pr.SYNC[0]:
                if len(self._buf) < 2:
                    return None
                if self._buf[1] == pr.SYNC[1]:
                    if len(self._buf) < pr.RECORD_BYTES:
                        return None
                    rec = pr.decode_record(bytes(self._buf[: pr.RECORD_BYTES]))
                    if rec is not None:
                        del self._buf[: pr.RECORD_BYTES]
                        return ("C", rec)
            del self._buf[0]
            self.stats.garbage_bytes += 1
        return None

    def _drain(self) -> None:
        self.port.reset_input_buffer()
        self._buf.clear()

    def _settle(self) -> None:
        """After a failed attempt: wait until the board has been quiet for ``timeout`` s (it ends any
        frame it was receiving by itself: its receive timeout), then forget what came."""
        deadline = time.monotonic() + 10 * self.timeout
        while self._fill(self.timeout):
            self._buf.clear()
            if time.monotonic() > deadline:
                raise BoardError(f"{self.name} keeps sending after a failed frame; reset it")
        self._drain()

    def _new_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFF
        return self._seq

    # --- requests
    def info(self) -> pr.BoardInfo:
        """What the board was built for; a clear error if it does not answer."""
        self._drain()
        for _ in range(2):
            seq = self._new_seq()
            self._write(pr.encode_record(pr.INFO, seq))
            deadline = time.monotonic() + self.timeout
            while time.monotonic() < deadline:
                item = self._next_item({})
                if item is None:
                    self._fill(max(0.0, deadline - time.monotonic()))
                    continue
                if item[0] == "C" and item[1].kind == pr.INFO and item[1].seq == seq:
                    self.board_info = pr.parse_info(item[1].payload)
                    if self.board_info.version != pr.PROTOCOL_VERSION:
                        raise BoardError(
                            f"{self.name} speaks protocol version {self.board_info.version}, "
                            f"this host {pr.PROTOCOL_VERSION}: rebuild the bitstream"
                        )
                    return self.board_info
        raise BoardError(
            f"{self.name} did not answer within {self.timeout:g} s: is it programmed with a "
            "`bayesmachine board build` bitstream (or is `bayesmachine board simulate` running), "
            "and is the baud rate the one it was built for?"
        )

    def run_frame(
        self,
        left: np.ndarray,
        right: np.ndarray,
        params: MachineParams,
        model: ModelParams,
        fields: int = pr.FIELDS_ALL,
        progress=None,
    ) -> dict[str, dict[str, np.ndarray]]:  # noqa: ANN001
        """One frame's results, every pass's by pass name (the fields of :meth:`ResultFormat.decode`),
        each in raster order of its pixels; ``progress(n)`` is called with the own pass's results
        received as they come."""
        info = self.board_info or self.info()
        height, width = left.shape
        if width != info.width:
            raise BoardError(
                f"{self.name} was built for {info.width}-pixel lines, the frame has {width}: crop "
                f"to width {info.width} (--crop X,Y,{info.width},H) or rebuild with --width {width}"
            )
        from bayesmachine.hdl.frontend.passes import pass_row_pixels

        passes = pr.board_passes(params, model)
        pixels = np.stack([left, right], axis=-1).astype(np.uint8)
        lines = [pixels[y].tobytes() for y in range(height)]
        region = OutputRegion.of_model(left.shape, model)  # census 7x7: margin 3
        frame = _Frame(
            lines=lines, trailer=struct.pack("<I", pr.crc32(b"".join(lines))), width=width, fields=fields,
            formats={bp.tag: (bp.name, pr.ResultFormat.of(bp.params, fields, bp.tag)) for bp in passes},
            expected=region.shape[0] * sum(pass_row_pixels(model, bp.name, width) for bp in passes),
            out_cols=region.shape[1], edge=2 * region.margin,
            # Lines in flight beyond the one whose results are awaited: what the receive buffer holds.
            lag=max(1, info.rx_fifo_bytes // (2 * width) - 1))
        reasons = []
        for _ in range(self.attempts):
            self.stats.attempts += 1
            try:
                return self._attempt(frame, progress)
            except _AttemptFailed as exc:
                reasons.append(str(exc))
                self.stats.failures.append(str(exc))
                self._log(f"board: frame failed ({exc}); sending it again")
                self._settle()
        raise BoardError(f"{self.name} failed the frame {self.attempts} times: " + "; ".join(reasons))

    def _attempt(self, frame: _Frame, progress) -> dict[str, dict[str, np.ndarray]]:  # noqa: ANN001
        a = _Attempt(self._new_seq(), {tag: bytearray() for tag in frame.formats})
        self._drain()
        self._write(pr.frame_header(a.seq, frame.fields, frame.width, frame.height))
        bodies = {tag: fmt.body_bytes for tag, (_, fmt) in frame.formats.items()}
        last_heard = time.monotonic()
        while True:
            if a.started:
                self._send_lines(frame, a)
            item = self._next_item(bodies)
            if item is None:
                if self._fill(0.05):
                    last_heard = time.monotonic()
                elif time.monotonic() - last_heard > self.timeout:
                    what = ("accept the frame" if not a.started
                            else f"send results ({a.count} of {frame.expected} came)")
                    raise _AttemptFailed(f"no answer within {self.timeout:g} s (waiting for it to {what})")
                continue
            kind, value = item
            if kind == "R":
                if not a.started:
                    raise _AttemptFailed("a result came before the frame was accepted")
                a.records[value[0]] += value
                a.count += 1
                if value[0] == pr.RESULT_TAG:
                    a.own += 1
                    if progress is not None:
                        progress(1)
            elif self._control(frame, a, value):
                return {name: fmt.decode(bytes(a.records[tag])) for tag, (name, fmt) in frame.formats.items()}

    def _send_lines(self, frame: _Frame, a: _Attempt) -> None:
        """Send what the board can take: line y once image line y - lag is answered (the own pass's
        results of its output row), then the pixels' CRC."""
        while a.sent < frame.height and (a.sent < frame.edge + frame.lag
                                         or a.own >= (a.sent - frame.edge - frame.lag + 1) * frame.out_cols):
            self._write(frame.lines[a.sent])
            a.sent += 1
            if a.sent == frame.height:
                self._write(frame.trailer)

    def _control(self, frame: _Frame, a: _Attempt, rec: pr.Record) -> bool:
        """A control record during an attempt: True for the frame's good end record; the attempt fails
        (:class:`_AttemptFailed`, the reason) on anything wrong; a refused size is a :class:`BoardError`."""
        if rec.kind == pr.HELLO:
            raise _AttemptFailed("the board was reset")
        if rec.kind == pr.ERROR:
            code = rec.payload[0]
            detail = struct.unpack("<H", rec.payload[1:3])[0]
            what = pr.ERROR_NAMES.get(code, f"error {code}")
            if code == pr.ERR_SIZE:
                raise BoardError(f"{self.name} refused the frame: {what} (it was built for {detail}-pixel "
                                 "lines)")
            raise _AttemptFailed(f"the board refused the header: {what}")
        if rec.seq != a.seq:
            return False  # a record of an earlier attempt
        if rec.kind == pr.START:
            fields_b, _w, _h, n = struct.unpack("<BHHI", rec.payload[:9])
            if n != frame.expected or fields_b != frame.fields:
                raise _AttemptFailed(f"the board accepted a different frame ({n} results, fields {fields_b})")
            a.started = True
        elif rec.kind == pr.END:
            status, n, crc = struct.unpack("<BII", rec.payload[:9])
            if status != pr.STATUS_OK:
                raise _AttemptFailed(f"the board ended the frame: {pr.STATUS_NAMES.get(status, status)}")
            if n != frame.expected or a.count != frame.expected:
                raise _AttemptFailed(f"{a.count} results came, the board sent {n}, the frame has "
                                     f"{frame.expected}")
            came = 0
            for records in a.records.values():  # each pass's records' CRC-32, XORed
                came ^= pr.crc32(bytes(records))
            if crc != came:
                raise _AttemptFailed("the results' checksum does not match (a byte garbled on the way back)")
            if a.sent != frame.height:
                raise _AttemptFailed("the board ended the frame before all of it was sent")
            return True
        return False


def open_port(port: str, baud: int, timeout: float = 2.0):  # noqa: ANN201
    """``serial.Serial`` on ``port``, held exclusively (a lock on it: a second run on the same port is
    refused at once, never interleaved with the first), or one clear error."""
    try:
        import serial
    except ImportError:
        raise BoardError("--engine board needs pyserial: pip install 'bayesmachine[board]'") from None
    try:
        return serial.Serial(port, baud, timeout=timeout, write_timeout=30 * timeout, exclusive=True)
    except (serial.SerialException, OSError, ValueError, OverflowError) as exc:
        if getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
            raise BoardError(f"{port} is in use: another run is talking to the board on it; wait for it to "
                             "finish") from None
        raise BoardError(f"cannot open {port} at {baud} baud: {exc}") from None


def design_record(fingerprint: int) -> Path:
    """Where this machine keeps the design a board fingerprint stands for (``board build`` and
    ``board simulate`` record theirs), so that a run can name the options in which it differs."""
    from bayesmachine.sim.verilator.build import cache_dir

    return cache_dir().parent / "boards" / f"{fingerprint:08x}.json"


def record_design(machine: MachineParams, model: ModelParams, width: int) -> None:
    """Record the design of a board being built or simulated (:func:`design_record`); a cache, so a
    file-system problem only costs the run's message its detail."""
    from bayesmachine.outputs import atomic_write_text

    fingerprint = pr.board_fingerprint(machine.to_dict(), model.to_dict(), width)
    path = design_record(fingerprint)
    record = {"fingerprint": f"{fingerprint:08x}", "width": width, "machine": machine.to_dict(),
              "model": model.to_dict()}
    with contextlib.suppress(OSError):
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, json.dumps(record, indent=1) + "\n")


# Machine fields that follow from the model's options (its Dmax, columns, prior): named through those.
_DERIVED = ("rows", "columns", "nomatch_row", "feedback_words", "feedback_nomatch_word", "words_per_beat",
           "prior")


def design_differences(board: dict, machine: MachineParams, model: ModelParams) -> list[str]:
    """The options in which this run's design differs from ``board``'s (:func:`record_design`'s
    record), each as ``FLAG: VALUE here, VALUE on the board``."""
    from bayesmachine.cliargs import flag_of

    def differ(mine: dict, theirs: object, skip: tuple[str, ...] = ()) -> list[str]:
        theirs = theirs if isinstance(theirs, dict) else {}
        # A field only one side has follows from another option (--model): that one is named.
        return [f"{flag_of(k) or k} {mine[k]} here, {theirs[k]} on the board" for k in mine
                if k in theirs and k not in skip and mine[k] != theirs[k]]

    theirs = board.get("model") if isinstance(board.get("model"), dict) else {}
    name = theirs.get("name", "paper")  # an older paper model's dict left its name out
    if name != model.name:  # the other model fields follow from it
        found = [f"--model {model.name} here, {name} on the board"]
    else:
        found = differ(model.to_dict(), theirs)
    board_machine = board.get("machine") if isinstance(board.get("machine"), dict) else {}
    # A stochastic machine's dict leaves its integrator out; the feedback words follow from it. Only the
    # fields this machine's integrator reads are compared (a log machine's dict has no stochastic one).
    theirs_integrator = board_machine.get("integrator", DEFAULT_INTEGRATOR)
    if INTEGRATOR_KINDS.get(theirs_integrator) is not machine.kind:
        found.append(f"--integrator {machine.integrator} here, {theirs_integrator} on the board")
    skip = _DERIVED if found else ("rows",)
    return found + differ(machine.to_dict(), board_machine, skip)


def fingerprint_message(port: str, found: int, expect: int, machine: MachineParams,
                         model: ModelParams) -> str:
    """Why a board of fingerprint ``found`` is refused for this run (``expect``): the options that
    differ, when this machine recorded the board's design (:func:`record_design`)."""
    head = (f"the board on {port} was built for another machine or model (fingerprint {found:08x}, these "
            f"options give {expect:08x})")
    record = design_record(found)
    try:
        board = json.loads(record.read_text())
    except (OSError, ValueError):
        return (f"{head}; this machine has no record of the board's design: run with the options it was "
                "built with (the report.json of its `board build`, or of `board simulate -o`), or rebuild it")
    diffs = design_differences(board, machine, model) if isinstance(board, dict) else []
    if diffs:
        return f"{head}: {'; '.join(diffs)}; run with the board's options, or rebuild it"
    return f"{head}: its design is {record}; run with its options, or rebuild it"
