"""The random sources on the command line: run, sweep side by side, emit, clear errors."""

from __future__ import annotations

import json

import pytest

from bayesmachine.cli import main
from bayesmachine.params import MachineParams

CROP = ["--crop", "300,200,60,16", "--dmax", "16", "--no-sgbm", "--quiet"]  # 12 x 40 output pixels


@pytest.mark.parametrize("rng", ["lfsr", "lfsr-shared", "sobol"])
def test_run_with_each_on_chip_source(tmp_path, rng: str) -> None:
    out = tmp_path / rng
    assert main(["run", *CROP, "--counter-max", "8", "--rng", rng, "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["rng"] == rng and report["machine"]["rng"] == rng and report["pixels"] == 12 * 40


def test_run_defaults_to_the_default_source(tmp_path) -> None:
    out = tmp_path / "default"
    assert main(["run", *CROP, "--counter-max", "2", "-o", str(out)]) == 0
    assert json.loads((out / "report.json").read_text())["rng"] == MachineParams.rng


def test_sweep_compares_sources_side_by_side(tmp_path) -> None:
    out = tmp_path / "sweep"
    assert main(["sweep", *CROP, "--counter-max", "2,8", "--rng", "lfsr,sobol", "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["rng"] == ["lfsr", "sobol"] and "rng" not in sweep["machine"]
    assert [(p["rng"], p["counter_max"]) for p in sweep["points"]] == [
        ("lfsr", 2), ("lfsr", 8), ("sobol", 2), ("sobol", 8)
    ]
    assert (out / "sweep.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("rng", "message"),
    [("lfsr,typo", "unknown or not runnable random source 'typo'"),
     ("external", "not runnable random source 'external'"),
     ("sobol,sobol", "twice"),
     (",", "at least one")],
)
def test_sweep_rejects_bad_source_lists(tmp_path, capsys, rng: str, message: str) -> None:
    assert main(["sweep", *CROP, "--counter-max", "2", "--rng", rng, "-o", str(tmp_path / "x")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("rng", ["lfsr-shared", "sobol"])
def test_emit_summary_names_the_source(tmp_path, capsys, rng: str) -> None:
    out = tmp_path / "bm.v"
    assert main(["emit", "--dmax", "4", "--counter-max", "3", "--rng", rng, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"random source: {rng}: " in text and "entropy" not in text
    assert "module bayesmachine" in out.read_text()
