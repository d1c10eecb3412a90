"""The random sources on the command line: run, sweep side by side, emit, clear errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import bundled_pair, crop_image, parse_crop
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams
from bayesmachine.params import DEFAULT_RNG, MachineParams
from bayesmachine.sim.model import MachineModel

# The paper model (its words computed below without the command line): 12 x 40 output pixels.
CROP = ["--crop", "300,200,60,16", "--dmax", "16", "--model", "paper", "--no-sgbm", "--quiet"]
ON_CHIP = ("lfsr", "lfsr-shared", "sobol")


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[dict, dict[str, np.ndarray]]]:
    """``run`` with each on-chip source, and with no ``--rng`` ("default"): (report, result.npz)."""
    out: dict[str, tuple[dict, dict[str, np.ndarray]]] = {}
    for name in (*ON_CHIP, "default"):
        path = tmp_path_factory.mktemp(name)
        rng = [] if name == "default" else ["--rng", name]
        assert main(["run", *CROP, "--counter-max", "8", *rng, "-o", str(path)]) == 0
        with np.load(path / "result.npz") as npz:
            out[name] = json.loads((path / "report.json").read_text()), dict(npz)
    return out


def _model_result(rng: str) -> dict[str, np.ndarray]:
    """What the model gives for the same crop and machine, computed without the command line."""
    left, right, _ = bundled_pair()
    crop = parse_crop("300,200,60,16")
    model = ModelParams(name="paper", dmax=16)
    machine = MachineParams.for_disparity(16, counter_max=8, rng=rng)
    words = memory_words(feature_sums(crop_image(left, crop)), feature_sums(crop_image(right, crop)),
                         model, machine)
    res = MachineModel(machine).run(words)
    shape = (12, 40)
    disp = np.where(res.nomatch | res.timeout, -1, res.map).reshape(shape)
    return {"map": disp, "cycles": res.cycles.reshape(shape), "counts": res.counts.reshape(*shape, -1)}


@pytest.mark.parametrize("rng", ON_CHIP)
def test_run_with_each_on_chip_source(runs, rng: str) -> None:
    report, result = runs[rng]
    assert report["rng"] == rng and report["machine"]["rng"] == rng and report["pixels"] == 12 * 40
    want = _model_result(rng)
    for field in ("map", "cycles", "counts"):
        assert np.array_equal(result[field], want[field]), f"{rng}: {field} differs from the model's"


def test_sources_give_different_results(runs) -> None:
    """--rng is not ignored: each source's stream gives its own runs (cycles of 480 pixels)."""
    cycles = {rng: runs[rng][1]["cycles"] for rng in ON_CHIP}
    for a in ON_CHIP:
        for b in ON_CHIP:
            assert a == b or not np.array_equal(cycles[a], cycles[b]), (a, b)


def test_run_defaults_to_the_default_source(runs) -> None:
    report, result = runs["default"]
    assert report["rng"] == DEFAULT_RNG
    for field in ("map", "cycles", "counts"):
        assert np.array_equal(result[field], runs[DEFAULT_RNG][1][field]), field


def test_sweep_compares_sources_side_by_side(tmp_path, runs) -> None:
    out = tmp_path / "sweep"
    assert main(["sweep", *CROP, "--counter-max", "2,8", "--rng", "lfsr,sobol", "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["rng"] == ["lfsr", "sobol"] and "rng" not in sweep["machine"]
    assert [(p["rng"], p["counter_max"]) for p in sweep["points"]] == [
        ("lfsr", 2), ("lfsr", 8), ("sobol", 2), ("sobol", 8)
    ]
    assert (out / "sweep.png").stat().st_size > 0
    # Each point ran its own source: at counter max 8, the same cycles as `run --rng` (which the
    # model holds), and the two sources' frames differ.
    frame = {p["rng"]: p["frame_cycles"] for p in sweep["points"] if p["counter_max"] == 8}
    assert frame == {rng: int(runs[rng][1]["cycles"].sum()) for rng in ("lfsr", "sobol")}
    assert frame["lfsr"] != frame["sobol"]


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


@pytest.mark.eda
@pytest.mark.parametrize("rng", ["lfsr-shared", "sobol"])
def test_emit_summary_names_the_source(tmp_path, capsys, rng: str) -> None:
    out = tmp_path / "bm.v"
    assert main(["emit", "--dmax", "4", "--counter-max", "3", "--rng", rng, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"random source: {rng}: " in text and "entropy" not in text
    assert "module bayesmachine" in out.read_text()
