"""The ``verilator`` engine: a persistent harness process and its pipe protocol.

Each ``run`` writes a batch (header and the pixels' words) to the harness's stdin, then serves
its requests for random numbers (off-chip sources) until it answers with the batch's raw result
payloads, decoded in Python from the result layout. The protocol is described at the top of
``sim/harness/harness.cpp``.
"""

from __future__ import annotations

import os
import struct
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bayesmachine.params import MachineParams
from bayesmachine.sim.activity import activity_env
from bayesmachine.sim.engines import EngineBase
from bayesmachine.sim.results import MachineResult, NumberFeed, decode_results, ran_out_error, result_words

from .build import VerilatorBuild, build_harness
from .tools import VerilatorError

__all__ = ["HarnessProcess", "VerilatorEngine"]

_MAGIC_RUN = 0x4E524D42  # "BMRN", see harness.cpp
_MAGIC_QUIT = 0x54514D42  # "BMQT"
_DONE, _RAN_OUT, _NEED_NUMBERS = 0, 1, 2  # the harnesses' messages (common.h)
_DROP_NUMBERS = 1  # header flag: drop the rows of random numbers left from earlier batches
_TRACE_KINDS = {".vcd": 1, ".fst": 2}


class HarnessProcess:
    """A persistent harness process and what every harness's client shares: starting it, writing
    requests, reading replies, the raw result payloads (decoded by ``decode_results``), failure
    messages from its stderr, ending it; and the cycle statistics.

    A subclass sets ``params``, ``build`` (a :class:`~.build.VerilatorBuild`) and ``_args`` (the
    harness's command line), optionally ``_env`` (variables added to the harness's environment), and
    calls :meth:`_init_process`.
    """

    params: MachineParams
    build: VerilatorBuild
    _args: list[str]
    _env: dict[str, str] | None = None

    def _init_process(self) -> None:
        self._proc: subprocess.Popen[bytes] | None = None
        self._stderr: Any = None
        self._reset_stats()

    def _reset_stats(self) -> None:
        self.last_compute_cycles = 0
        self.last_wall_cycles = 0
        self.last_seconds = 0.0
        self.total_pixels = 0
        self.total_compute_cycles = 0
        self.total_wall_cycles = 0

    @property
    def compiled(self) -> bool:
        """Whether constructing this engine compiled the harness (False: reused from the cache)."""
        return self.build.compiled

    @property
    def wall_cycles(self) -> int:
        """Clock cycles simulated since reset, loading included."""
        return self.total_wall_cycles

    @property
    def stats(self) -> dict[str, float]:
        return {
            "pixels": self.total_pixels,
            "compute_cycles": self.total_compute_cycles,
            "wall_cycles": self.total_wall_cycles,
            "last_compute_cycles": self.last_compute_cycles,
            "last_wall_cycles": self.last_wall_cycles,
            "last_seconds": self.last_seconds,
            "build_seconds": self.build.seconds,
        }

    def _start(self) -> subprocess.Popen[bytes]:
        if self._proc is None:
            self._stderr = tempfile.TemporaryFile()
            try:
                self._proc = subprocess.Popen(
                    [str(self.build.executable), *self._args],
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr, bufsize=0,
                    env=None if self._env is None else {**os.environ, **self._env},
                )
            except OSError as exc:
                raise VerilatorError(f"cannot start the Verilator harness {self.build.executable} ({exc}); "
                                     f"delete {self.build.directory} to rebuild it") from None
        return self._proc

    def _failure(self, what: str) -> VerilatorError:
        msg = ""
        if self._proc is not None:
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._proc.kill()
            if self._stderr is not None:
                self._stderr.seek(0)
                msg = self._stderr.read().decode(errors="replace").strip()
        self._proc = None
        return VerilatorError(f"{what}: {msg or 'the harness exited without a message'}")

    def _read(self, proc: subprocess.Popen[bytes], nbytes: int) -> bytearray:
        assert proc.stdout is not None
        buf = bytearray(nbytes)
        view, got = memoryview(buf), 0
        while got < nbytes:
            k = proc.stdout.readinto(view[got:])
            if not k:
                raise self._failure("the Verilator harness stopped before returning all results")
            got += k
        return buf

    def _write(self, proc: subprocess.Popen[bytes], *parts: bytes | memoryview) -> None:
        assert proc.stdin is not None
        try:
            for part in parts:
                proc.stdin.write(part)
        except OSError as exc:
            raise self._failure(f"the Verilator harness stopped ({exc})") from None

    def _read_results(self, proc: subprocess.Popen[bytes], n: int, t0: float) -> MachineResult:
        """The rest of a DONE reply (after its message word): ``n`` raw payloads and the wall
        cycles; decoded, and counted in the statistics (``t0``: when the request began)."""
        p = self.params
        nwords = result_words(p)
        raw = self._read(proc, n * nwords * 4 + 16)
        self.last_seconds = time.perf_counter() - t0
        out = decode_results(p, np.frombuffer(raw, dtype="<u4", count=n * nwords).reshape(n, nwords))
        wall, _ = struct.unpack_from("<QQ", raw, n * nwords * 4)
        self.last_compute_cycles = int(out.cycles.sum())
        self.last_wall_cycles = int(wall)
        self.total_pixels += n
        self.total_compute_cycles += self.last_compute_cycles
        self.total_wall_cycles += self.last_wall_cycles
        return out

    def _serve_numbers(self, proc: subprocess.Popen[bytes], feed: NumberFeed | None) -> None:
        """Answer the harness's requests for random numbers (an off-chip source: rows from ``feed``)
        until its DONE message; RAN OUT (the feed had no more) ends the process and raises."""
        while True:
            (message,) = struct.unpack("<Q", self._read(proc, 8))
            if message == _NEED_NUMBERS:
                (want,) = struct.unpack("<Q", self._read(proc, 8))
                if feed is not None:
                    rows = feed.take_clocks(int(want))  # a row per compute cycle: B numbers per operator
                else:
                    rows = np.zeros((0, self.params.operators * self.params.samples_per_clock), np.uint16)
                self._write(proc, struct.pack("<Q", len(rows)),
                            np.ascontiguousarray(rows, dtype="<u2").tobytes())
            elif message == _RAN_OUT:
                self._proc = None
                proc.wait()
                raise ran_out_error(feed.source if feed is not None else None)
            elif message == _DONE:
                return
            else:
                raise self._failure(f"the Verilator harness sent an unknown message {message}")

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.wait()

    def _reset(self) -> None:
        self._stop()
        self._reset_stats()

    def _close(self) -> None:
        self._stop()

    def _stop(self) -> None:
        """End the harness (flushes and closes a waveform file); the next run starts a fresh one."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            assert proc.stdin is not None
            proc.stdin.write(struct.pack("<IIQ", _MAGIC_QUIT, 0, 0))
            proc.stdin.close()
        except OSError:
            pass
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None

    def __del__(self) -> None:
        try:
            self.close()  # type: ignore[attr-defined]
        except Exception:
            pass


class VerilatorEngine(HarnessProcess, EngineBase):
    """The RTL compiled with Verilator; the engines' contract (see :mod:`bayesmachine.sim.engines`).

    ``build_dir``: cache directory for builds (default: see :func:`~.build.cache_dir`).
    ``activity``: a directory where the harness, built to count every signal bit's toggles, writes them
    (:func:`bayesmachine.sim.activity.activity_env`: since the harness started, after each ``run``).
    ``trace``: ``(first_pixel, last_pixel, path)`` writes a waveform (``.fst`` → FST, else VCD)
    while pixels first..last (inclusive, counted from reset across ``run`` calls) are in flight;
    the file is complete after :meth:`close`. A traced build has its own cache key.
    ``load_stall`` / ``result_stall``: probability that the harness drops ``load.valid`` /
    ``result.ready`` in a cycle (a pseudo-random pattern from ``stall_seed``), as in ``pysim``;
    results do not depend on them. ``result_stall > 0`` uses a build whose top keeps
    ``result.ready`` a port (about half the cycles per second of the default, which ties it high).
    ``jobs``: parallel C++ compiles; ``verbose``: one line on stderr when it compiles.

    After each ``run``: ``last_compute_cycles`` (sum of the pixels' ``cycles``),
    ``last_wall_cycles`` (clock cycles from the first load beat to the last result, loading
    included) and ``stats`` (totals since reset as well).
    """

    name = "verilator"
    FEEDBACK = True
    OPTIONS = ("build_dir", "trace", "jobs", "verbose", "load_stall", "result_stall", "stall_seed",
               "activity")

    def __init__(
        self,
        params: MachineParams,
        build_dir: str | os.PathLike[str] | None = None,
        trace: tuple[int, int, str | os.PathLike[str]] | None = None,
        *,
        jobs: int = 2,
        verbose: bool = True,
        load_stall: float = 0.0,
        result_stall: float = 0.0,
        stall_seed: int = 0,
        activity: str | os.PathLike[str] | None = None,
    ) -> None:
        super().__init__(params)
        self._args: list[str] = []
        trace_kind = 0
        if trace is not None:
            first, last, path = trace
            if not 0 <= int(first) <= int(last):
                raise ValueError(f"trace pixel range must satisfy 0 <= first <= last, got {first}..{last}")
            trace_kind = _TRACE_KINDS.get(Path(path).suffix.lower(), 1)
            self._args += ["--trace", str(Path(path).resolve()), str(int(first)), str(int(last))]
        for name, v in (("load_stall", load_stall), ("result_stall", result_stall)):
            if not 0.0 <= v < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {v}")
        if load_stall or result_stall:
            permille = [str(min(999, round(v * 1000))) for v in (load_stall, result_stall)]
            self._args += ["--stall", *permille, str(int(stall_seed))]
        self.build = build_harness(params, build_dir=build_dir, trace_kind=trace_kind,
                                   tie_ready=not result_stall, activity=activity is not None, jobs=jobs,
                                   verbose=verbose)
        self._env = activity_env(activity, self.build)
        self._held: object = None  # the number source whose unused rows the harness holds
        self._init_process()

    def _start(self) -> subprocess.Popen[bytes]:
        if self._proc is None:
            self._held = None  # a fresh harness holds no rows
        return super()._start()

    def _run_feedback(self, q: np.ndarray, feed: NumberFeed | None, line_start: np.ndarray) -> MachineResult:
        # The protocol's pixel record with a neighbour prior: its words, then its line_start flag.
        records = np.empty((q.shape[0], self.params.words_per_pixel + 1), "<u2")
        records[:, :-1] = q.reshape(q.shape[0], -1)
        records[:, -1] = line_start
        return self._run(records, feed)

    def _run(self, q: np.ndarray, feed: NumberFeed | None) -> MachineResult:
        p = self.params
        n = q.shape[0]
        if n == 0:
            return MachineResult.empty(p.rows)
        proc = self._start()
        source = feed.source if feed is not None else None
        flags = _DROP_NUMBERS if source is not self._held else 0
        t0 = time.perf_counter()
        try:
            self._write(proc, struct.pack("<IIQ", _MAGIC_RUN, flags, n),
                        memoryview(np.ascontiguousarray(q, dtype="<u2")).cast("B"))
            self._held = source
            self._serve_numbers(proc, feed)
            return self._read_results(proc, n, t0)
        except (VerilatorError, ValueError):
            raise
        except BaseException:
            self._kill()  # an interrupt leaves the pipes mid-batch
            raise
