"""The definitions and the host need no RTL package: where Amaranth is absent, ``run --engine model``
runs with either integrator, and a command that needs Amaranth says so in one line (exit code 2)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

# The CLI in a child whose imports of amaranth fail as for a package not installed.
_WITHOUT = """
import sys
class Absent:
    def find_spec(self, name, path=None, target=None):
        if name == "amaranth" or name.startswith("amaranth."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, Absent())
from bayesmachine.cli import main
code = main(sys.argv[1:])
assert not [m for m in sys.modules if m.startswith("amaranth")]
sys.exit(code)
"""

CROP = ["--crop", "300,200,40,24", "--dmax", "8", "--quiet"]


def without_amaranth(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", _WITHOUT, *argv], capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("integrator", ["stochastic", "log"])
def test_run_on_the_model_needs_no_amaranth(integrator: str, tmp_path: Path) -> None:
    done = without_amaranth("run", "--engine", "model", "--integrator", integrator, *CROP, "-o",
                            str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["machine"]["integrator"] == integrator


@pytest.mark.parametrize("argv", [["run", "--engine", "pysim", *CROP], ["emit"]])
def test_a_command_that_needs_amaranth_says_so(argv: list[str], tmp_path: Path) -> None:
    done = without_amaranth(*argv, "-o", str(tmp_path / "out"))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "'amaranth'" in lines[0] and "not installed" in lines[0], lines
    assert not (tmp_path / "out").exists()
