"""External tools: the one lookup, running one in its own process group, and the user cache directory.

Neutral ground for every package that starts a tool (``sim.verilator``: Verilator, g++, make;
``fpga``: Yosys, nextpnr), so neither imports the other for it.

A tool runs in a session of its own (:func:`start_tool`), so that ending it
(:func:`stop_tool`) ends whatever it started too, and a signal meant for the command reaches
the command, which then stops the tool: Ctrl-C or SIGTERM never leaves a tool running
re-parented to PID 1.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = ["which", "start_tool", "stop_tool", "tool_process", "user_cache_dir"]

_HELD = (signal.SIGINT, signal.SIGTERM)  # the signals a command turns into an exception


def which(tool: str) -> str | None:
    """``tool`` on PATH, else beside this Python (a virtual environment used without activating it)."""
    return shutil.which(tool) or shutil.which(tool, path=os.path.dirname(sys.executable))


def user_cache_dir(*parts: str) -> Path:
    """``$XDG_CACHE_HOME/<parts>`` (default ``~/.cache/<parts>``): where the project's builds and the
    tools' compiled code are cached unless a variable of their own says otherwise."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base).joinpath(*parts)


def start_tool(cmd: Sequence[str], **popen: Any) -> subprocess.Popen:
    """``subprocess.Popen(cmd, **popen)`` as the leader of a new session (and process group).

    A SIGINT or SIGTERM that arrives while the tool starts is held until ``Popen`` has returned, then
    the tool is ended and the signal handled as it would have been: a handler raising inside ``Popen``
    (the command's Ctrl-C or SIGTERM) would leave the tool running with no one to end it."""
    if threading.current_thread() is not threading.main_thread():
        return subprocess.Popen(list(cmd), start_new_session=True, **popen)  # signals reach the main thread
    pending: list[int] = []
    previous = {sig: signal.getsignal(sig) for sig in _HELD}
    # None: a handler not set from Python (left alone); SIG_IGN: nothing to hold.
    held = [sig for sig, handler in previous.items() if handler not in (None, signal.SIG_IGN)]
    for sig in held:
        signal.signal(sig, lambda signum, frame: pending.append(signum))
    proc = None
    try:
        proc = subprocess.Popen(list(cmd), start_new_session=True, **popen)
    finally:
        try:
            for sig in held:
                signal.signal(sig, previous[sig])
        except BaseException:  # a signal handled as its handler came back
            if proc is not None:
                stop_tool(proc)
            raise
        if pending:  # the tool first, then the signal as the command would have had it
            if proc is not None:
                stop_tool(proc)
            signal.raise_signal(pending[0])
    return proc


def stop_tool(proc: subprocess.Popen, grace: float = 2.0) -> None:
    """End ``proc``'s whole process group: SIGTERM, then SIGKILL after ``grace`` seconds; reap it."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=grace)
            break
        except subprocess.TimeoutExpired:
            continue
    # The leader is gone; what it started may not be (it would be re-parented to PID 1).
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


@contextlib.contextmanager
def tool_process(cmd: Sequence[str], **popen: Any) -> Iterator[subprocess.Popen]:
    """Start ``cmd`` with :func:`start_tool`; on leaving the block, for whatever reason (an
    exception, Ctrl-C, SIGTERM raised as an exception), its process group is ended."""
    proc = start_tool(cmd, **popen)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            stop_tool(proc)
        else:  # the tool exited; anything it left behind in its group goes
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
