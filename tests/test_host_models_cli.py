"""``--model`` on the command line: run, reference, sweep and emit with the census model (issue 17)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from bayesmachine import cliargs
from bayesmachine.cli import main
from bayesmachine.host.features import model_features
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.reference import reference_map
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.likelihood import DEFAULT_MODEL, ModelParams, disparity_machine

DMAX = 12


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("pair")
    left, right, gt = random_dot_stereogram(height=24, width=60, background=3, square=9, seed=2)
    cv2.imwrite(str(d / "l.png"), left)
    cv2.imwrite(str(d / "r.png"), right)
    np.save(d / "gt.npy", gt.astype(np.float64))
    return d, left, right, gt


def _args(pair, *extra: str) -> list[str]:
    d = pair[0]
    return [str(d / "l.png"), str(d / "r.png"), "--gt", str(d / "gt.npy"), "--dmax", str(DMAX), "--quiet",
            *extra]


def test_run_census_is_the_neighbour_machine_of_the_model(pair, tmp_path):
    out = tmp_path / "run"
    assert main(["run", *_args(pair, "--model", "census", "--counter-max", "8", "--prior-s", "3"),
                 "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    model = ModelParams(dmax=DMAX, name="census", prior_s=3.0)
    machine = disparity_machine(model, counter_max=8)
    assert report["model_name"] == "census" and report["model"] == model.to_dict()
    assert report["machine"] == machine.to_dict() and report["machine"]["prior"] == "neighbour"
    for key in ("machine_bad2", "machine_bad2_nomatch_bad", "sgbm_bad2", "bm_bad2", "bm_bad2_nomatch_bad",
                "machine_nomatch_occluded", "reference_nomatch_occluded"):
        assert key in report, key
    # The command's map is the run API's (the above column and line starts from the machine's results),
    # on the census model's own output region (margin 3: every 7x7 window inside the image).
    _, left, right, gt = pair
    assert report["output_shape"] == [left.shape[0] - 6, left.shape[1] - 6 - DMAX]
    want = run_machine(prepare(left, right, model, gt), machine, "model", progress=False)
    np.testing.assert_array_equal(np.load(out / "result.npz")["map"], want.map)


def test_default_model_is_one_constant(pair, tmp_path, monkeypatch):
    # The census model is the default (it wins on the measurements: README, Models); the paper's
    # model stays one option away and its report is what it always was.
    assert DEFAULT_MODEL == "census"
    out = tmp_path / "default"
    assert main(["run", *_args(pair, "--counter-max", "4", "--no-sgbm"), "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model_name"] == "census" and report["machine"]["prior"] == "neighbour"
    out = tmp_path / "paper"
    argv = _args(pair, "--model", "paper", "--counter-max", "4", "--no-sgbm")
    assert main(["run", *argv, "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model_name"] == "paper" and report["machine"]["prior"] == "uniform"
    assert "name" not in report["model"]  # the paper model's dict is what it always was
    monkeypatch.setattr(cliargs, "DEFAULT_MODEL", "paper")
    out = tmp_path / "switched"
    assert main(["run", *_args(pair, "--counter-max", "4", "--no-sgbm"), "-o", str(out)]) == 0
    assert json.loads((out / "report.json").read_text())["machine"]["prior"] == "uniform"


def test_reference_census(pair, tmp_path):
    out = tmp_path / "ref.npz"
    assert main(["reference", *_args(pair, "--model", "census")[:2], "--dmax", str(DMAX), "--model", "census",
                 "--quiet", "-o", str(out)]) == 0
    _, left, right, _ = pair
    model = ModelParams(dmax=DMAX, name="census")
    want = reference_map(model_features(left, model), model_features(right, model), model)
    np.testing.assert_array_equal(np.load(out)["map"], want)


def test_sweep_puts_models_side_by_side(pair, tmp_path):
    out = tmp_path / "sweep"
    argv = _args(pair, "--model", "paper,census", "--counter-max", "2,4", "--rng", "sobol,lfsr", "--no-sgbm")
    assert main(["sweep", *argv, "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["models"] == ["paper", "census"]
    got = [(p["model_name"], p["rng"], p["counter_max"]) for p in sweep["points"]]
    assert got == [(m, r, n) for m in ("paper", "census") for r in ("sobol", "lfsr") for n in (2, 4)]
    census = disparity_machine(ModelParams(dmax=DMAX, name="census"))
    h, w = pair[1].shape
    assert sweep["output_shape"] == [h - 4, w - 4 - DMAX]  # the first model's region
    for p in sweep["points"]:
        assert p["model"] == ModelParams(dmax=DMAX, name=p["model_name"]).to_dict()
        if p["model_name"] == "census":
            # Its own output region: every 7x7 window inside the image (margin 3).
            assert p["output_shape"] == [h - 6, w - 6 - DMAX]
            assert p["machine"]["prior"] == "neighbour" and p["machine"]["columns"] == 4
            assert p["machine"]["feedback_words"] == list(census.feedback_words)
        else:
            assert "output_shape" not in p
            assert p["machine"]["prior"] == "uniform" and p["machine"]["columns"] == 3
    assert "prior" not in sweep["machine"] and sweep["machine"]["rows"] == DMAX + 2
    assert set(sweep["reference_seconds"]) == {"paper", "census"}
    # The census points are better than the paper's on these textured dots.
    best = {m: min(p["machine_bad2_nomatch_bad"] for p in sweep["points"] if p["model_name"] == m)
            for m in ("paper", "census")}
    assert best["census"] < best["paper"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "--model", "paper", "--census-sigma", "3"], "--census-sigma: options of --model census"),
        (["run", "--model", "paper", "--no-neighbour-prior", "--prior-eps", "0.1"],
         "--prior-eps, --no-neighbour-prior: options of --model census"),
        (["sweep", "--model", "paper", "--census-window", "5"],
         "--census-window: options of --model census"),
        (["run", "--model", "census", "--prior", "loaded"], "--prior: prior: the census model"),
        (["run", "--model", "census", "--no-neighbour-prior", "--prior", "neighbour"], "--prior neighbour"),
        (["run", "--model", "paper", "--prior", "neighbour"], "--prior neighbour: the census model's"),
        (["run", "--model", "census", "--census-window", "6"],
         "--census-window: census_window must be 5 or 7"),
        (["run", "--model", "census", "--prior-s", "0"], "--prior-s: prior_s must be"),
        (["run", "--model", "census", "--engine", "verilator", "--feed", "pixels", "--lanes", "12"],
         "multiple of the loaded columns"),
        (["sweep", "--model", "paper,paper"], "listed twice"),
        (["sweep", "--model", "sgbm"], "unknown model"),
        (["run", "--model", "sgbm"], "invalid choice"),
        (["emit", "--top", "stereo", "--model", "census", "--lanes", "12"],
         "multiple of the loaded columns (5)"),
        (["emit", "--model", "paper", "--census-window", "5"], "--census-window: options of --model census"),
        (["emit", "--model", "census", "--columns", "3"], "--columns: columns: the census model has 4"),
        (["emit", "--model", "census", "--prior", "uniform"], "--prior: prior:"),
    ],
)
def test_refusals_are_one_line(pair, tmp_path, capsys, argv, message):
    if argv[0] in ("run", "sweep"):
        argv = [argv[0], *_args(pair, *argv[1:])]
    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_emit_census_machine(tmp_path, capsys):
    """The census model's machine: its neighbour prior's two prior columns and the line_start flag."""
    out = tmp_path / "census.v"
    rc = main(["emit", "--model", "census", "--dmax", "6", "--counter-max", "3", "-o", str(out)])
    text = capsys.readouterr()
    assert rc == 0 and "6 operator columns" in text.out
    verilog = out.read_text()
    assert "prev_row" in verilog and "line_start" in verilog  # the feedback column is formed on chip
    # Without the prior the census machine is a plain 4-column machine.
    out = tmp_path / "no-prior.v"
    assert main(["emit", "--model", "census", "--no-neighbour-prior", "--dmax", "6", "-o", str(out)]) == 0
    assert "4 operator columns" in capsys.readouterr().out and out.stat().st_size > 0
