"""The RTL alone installs without the host extra (OpenCV, scikit-image, Matplotlib, Dask): its commands
run without them, the host's commands say in one line which extra they need; and the distribution
lists every package of the tree."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import tomllib

from bayesmachine.extras import HOST_MODULES

ROOT = Path(__file__).resolve().parent.parent

# Runs the CLI in a Python where the host extra's modules cannot be imported (as if not installed).
WITHOUT_HOST = """
import importlib.abc, importlib.util, sys
BLOCKED = set(sys.argv[1].split(","))
class Absent(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, Absent())
_find_spec = importlib.util.find_spec
importlib.util.find_spec = lambda name, *a: None if name.split(".")[0] in BLOCKED else _find_spec(name, *a)
from bayesmachine.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _without_host(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", WITHOUT_HOST, ",".join(HOST_MODULES), *argv],
                          capture_output=True, text=True, timeout=300)


def test_emit_runs_without_the_host_extra(tmp_path: Path) -> None:
    out = tmp_path / "machine.il"
    got = _without_host("emit", "--dmax", "4", "--counter-max", "4", "-o", str(out))
    assert got.returncode == 0, got.stderr
    assert out.stat().st_size > 0


def test_a_host_command_without_the_host_extra_is_one_line(tmp_path: Path) -> None:
    got = _without_host("run", "-o", str(tmp_path / "out"))
    assert got.returncode == 2
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'bayesmachine[host]'" in lines[0], got.stderr
    assert "OpenCV" in lines[0] and "Dask" in lines[0]
    assert not (tmp_path / "out").exists()


def test_the_distribution_lists_every_package() -> None:
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    dirs = {name: Path(path) for name, path in setup["package-dir"].items()}
    found = set()
    for top, where in dirs.items():
        for init in (ROOT / where).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / where)
            found.add(".".join((top, *rel.parts)))
    assert found == set(setup["packages"])
