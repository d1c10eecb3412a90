# amaranth: UnusedElaboratable=no
"""A model of your own in every engine: docs/development.md's snippet (census-lr's columns and a
gradient-magnitude column, five FEATURES columns, and a pass of its own named ``mirror``, which its
consistency column reads), in a file outside the package, imported as a user would, then used through
``bayesmachine.cli.main``. On a crop, ``run`` with pysim and Verilator fed words, Verilator fed pixels and
the simulated board write every array of the model engine's run (its mirror pass's too); ``emit --top
stereo`` builds its StereoMachine, lint clean."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import require_tool, user_models

from bayesmachine.cli import main
from bayesmachine.hdl import emit as hdl_emit
from bayesmachine.host.images import bundled_pair

MODEL = ["--model", "census-g-lr", "--dmax", "6"]
WIDTH = 24  # the crop's: dmax + 2 * margin + 1 = 13 at least


@pytest.fixture(scope="module")
def user(tmp_path_factory: pytest.TempPathFactory):
    """The user's directory: ``my_models.py`` (the snippet, imported: its models registered while the
    module's tests run), a 12 x 24 crop of the bundled pair as ``l.png`` and ``r.png`` (the right one 46
    columns further left: disparities 0..8) and ``model/``, the model engine's run of it."""
    directory = tmp_path_factory.mktemp("user")
    left, right, _ = bundled_pair()
    y, x, h, shift = 196, 300, 12, 46
    cv2.imwrite(str(directory / "l.png"), left[y : y + h, x : x + WIDTH])
    cv2.imwrite(str(directory / "r.png"), right[y : y + h, x - shift : x - shift + WIDTH])
    with user_models(directory):
        assert _run(directory, "model") == 0
        yield directory


def _run(directory: Path, out: str, *options: str) -> int:
    return main(["run", str(directory / "l.png"), str(directory / "r.png"), *MODEL, "--no-sgbm", "--quiet",
                 *options, "-o", str(directory / out)])


def assert_same_as_the_model(directory: Path, out: str) -> None:
    """Every array of ``out``'s result.npz is the model engine's, the mirror pass's among them."""
    got, want = np.load(directory / out / "result.npz"), np.load(directory / "model" / "result.npz")
    assert sorted(got.files) == sorted(want.files)
    passes = {"mirror_map", "mirror_cycles", "mirror_timeout"}
    assert {"map", "counts", "cycles", "timeout", *passes} <= set(want.files)
    for name in want.files:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    report = json.loads((directory / out / "report.json").read_text())
    assert report["model_name"] == "census-g-lr" and report["passes"] == ["mirror", "left"]


def test_the_model_engines_run_is_the_models(user: Path) -> None:
    """The run the others are held to: both passes, with matches (measured: all 72 output pixels matched,
    85 of the mirror pass's 108)."""
    npz = np.load(user / "model" / "result.npz")
    assert npz["map"].shape == (6, 12) and npz["mirror_map"].shape == (6, 18)
    assert np.all(npz["map"] >= 0) and np.sum(npz["mirror_map"] >= 0) > 70


def test_pysim_fed_words(user: Path) -> None:
    assert _run(user, "pysim", "--engine", "pysim") == 0
    assert_same_as_the_model(user, "pysim")


@pytest.mark.eda
def test_verilator_fed_words(user: Path, verilator_builds: Path) -> None:
    assert _run(user, "verilator", "--engine", "verilator") == 0
    assert_same_as_the_model(user, "verilator")


@pytest.mark.eda
def test_verilator_fed_pixels(user: Path, verilator_builds: Path) -> None:
    assert _run(user, "pixels", "--engine", "verilator", "--feed", "pixels") == 0
    assert_same_as_the_model(user, "pixels")


@pytest.mark.eda
def test_emit_builds_its_stereo_machine_lint_clean(user: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    verilator = require_tool("verilator")["verilator"]
    out = tmp_path / "bayesmachine.v"  # named after the module, as Verilator's DECLFILENAME wants
    assert main(["emit", "--top", "stereo", *MODEL, "--width", str(WIDTH), "-o", str(out)]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "mirror pass: the census-g model with the right image" in text and "mirror_result__payload" in text
    proc = subprocess.run([verilator, "--lint-only", "-Wall", str(Path(hdl_emit.__file__).with_name(
        "bayesmachine.vlt")), str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]


# The user's own script: their models, then the command line.
SCRIPT = ("import sys\nimport my_models  # noqa: F401\nfrom bayesmachine.cli import main\n"
          "sys.exit(main(sys.argv[1:]))\n")


@pytest.mark.eda
def test_the_simulated_board(user: Path, verilator_builds: Path) -> None:
    """``board simulate`` from the user's script (a process of its own), ``run --engine board`` here."""
    require_tool("verilator", "g++", "make")
    sim = subprocess.Popen([sys.executable, "-c", SCRIPT, "board", "simulate", *MODEL, "--width", str(WIDTH),
                            "--quiet"], cwd=user, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           start_new_session=True, env=dict(os.environ, PYTHONPATH=str(user)))
    try:
        port = sim.stdout.readline().strip()  # type: ignore[union-attr]
        assert port.startswith("/dev/"), (port, sim.stderr.read() if sim.poll() is not None else "")  # type: ignore[union-attr]
        assert _run(user, "board", "--engine", "board", "--port", port) == 0
    finally:
        os.killpg(sim.pid, signal.SIGTERM)
        assert sim.wait(timeout=30) == 143
    assert_same_as_the_model(user, "board")
