"""A model's passes on the command line (census-lr): ``run`` and ``sweep`` report each pass's machine
and figures, and census-lr's options are refused, in one line, where they do not apply."""

from __future__ import annotations

import numpy as np
import pytest
from columns.test_consistency import DMAX, lr_pair, right_machine

from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import CENSUS_WATCHDOG_RUNS, RIGHT_WATCHDOG_RUNS, ModelParams, disparity_machine

# A module-scoped fixture (the census-lr tests of columns/, host/ and cli/ share it).
pair = pytest.fixture(lr_pair, scope="module", name="pair")


@pytest.fixture(scope="module")
def pair_files(tmp_path_factory, pair):
    import cv2

    d = tmp_path_factory.mktemp("lr-pair")
    left, right, gt = pair
    cv2.imwrite(str(d / "l.png"), left)
    cv2.imwrite(str(d / "r.png"), right)
    np.save(d / "gt.npy", gt.astype(np.float64))
    return d


def _argv(d, *extra):
    files = [str(d / "l.png"), str(d / "r.png"), "--gt", str(d / "gt.npy")]
    return [*files, "--dmax", str(DMAX), "--quiet", *extra]


def test_cli_run_census_lr(pair_files, pair, tmp_path):
    import json

    from bayesmachine.cli import main

    out = tmp_path / "run"
    argv = _argv(pair_files, "--model", "census-lr", "--counter-max", "8", "--lr-beta", "0.2", "--no-sgbm",
                 "--no-fuse-columns")
    assert main(["run", *argv, "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    model = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_beta=0.2)
    machine = disparity_machine(model, counter_max=8)
    # Every resolved value, B = 1 included (not left out as in the fingerprint's to_dict()).
    assert report["model"] == model.to_dict() and report["machine"] == machine.to_dict(complete=True)
    assert report["machine"]["samples_per_clock"] == 1 and report["machine"]["normalize"] is True
    assert report["right_pass_machine"] == right_machine(model, machine).to_dict(complete=True)
    left, right, gt = pair
    want = run_machine(prepare(left, right, model, gt), machine, "model", progress=False)
    npz = np.load(out / "result.npz")
    np.testing.assert_array_equal(npz["map"], want.map)
    np.testing.assert_array_equal(npz["right_map"], want.passes["right"].map)
    # Cycles per pixel count both passes; the right pass's own figures beside them.
    both = (want.cycles.sum() + want.passes["right"].cycles.sum()) / want.map.size
    assert report["cycles_per_pixel_mean"] == pytest.approx(both)
    assert report["left_pass_cycles_per_pixel_mean"] == pytest.approx(want.cycles.mean())
    assert report["right_pass_cycles_per_pixel_mean"] == pytest.approx(want.passes["right"].cycles.mean())
    assert report["right_pass_pixels"] == want.passes["right"].map.size
    assert report["right_pass_timeouts"] == int(want.passes["right"].timeout.sum())
    assert report["machine"]["max_cycles"] == CENSUS_WATCHDOG_RUNS * 9  # census-lr's default watchdog
    assert report["frame_cycles"] == int(want.cycles.sum() + want.passes["right"].cycles.sum())


def test_cli_census_lr_without_its_right_nomatch_neutral_lanes_and_watchdog(pair_files, tmp_path):
    """--no-lr-right-nomatch --no-lr-neutral --max-cycles N: census-lr without the right pass's no-match
    row, the neutral lanes and its watchdog, as report.json records it."""
    import json

    from bayesmachine.cli import main

    out = tmp_path / "issue"
    argv = _argv(pair_files, "--model", "census-lr", "--counter-max", "8", "--no-sgbm", "--no-fuse-columns",
                 "--no-lr-right-nomatch", "--no-lr-neutral", "--max-cycles", "5000")
    assert main(["run", *argv, "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    model = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_right_nomatch=False,
                        lr_neutral=False)
    assert report["model"] == model.to_dict()
    assert report["machine"]["max_cycles"] == 5000  # the right pass keeps its own watchdog
    assert report["right_pass_machine"]["max_cycles"] == RIGHT_WATCHDOG_RUNS * 9


def test_cli_sweep_three_models(pair_files, tmp_path):
    import json

    from bayesmachine.cli import main

    out = tmp_path / "sweep"
    argv = _argv(pair_files, "--model", "paper,census,census-lr", "--counter-max", "4", "--no-sgbm",
                 "--lr-gamma", "0.02", "--prior-s", "3")
    assert main(["sweep", *argv, "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    points = {p["model_name"]: p for p in sweep["points"]}
    assert list(points) == ["paper", "census", "census-lr"]
    assert points["census-lr"]["model"] == ModelParams(dmax=DMAX, name="census-lr", lr_gamma=0.02,
                                                       prior_s=3.0).to_dict()
    assert points["census"]["model"] == ModelParams(dmax=DMAX, name="census", prior_s=3.0).to_dict()
    assert points["census-lr"]["machine"]["columns"] == 2  # fused: one image column and lr
    assert "right_pass_cycles_per_pixel_mean" in points["census-lr"]
    assert "right_pass_pixels" not in points["census"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "--model", "census", "--lr-beta", "0.2"], "--lr-beta: options of --model census-lr"),
        (["run", "--model", "paper", "--no-lr-nomatch"], "--no-lr-nomatch: options of --model census-lr"),
        # With --engine board or --machines K and --model census, census-lr's options are refused as
        # everywhere with --model census.
        (["run", "--engine", "board", "--port", "unused", "--model", "census", "--no-lr-nomatch"],
         "--no-lr-nomatch: options of --model census-lr and census-sgm, which do not apply to --model "
         "census"),
        (["run", "--machines", "2", "--model", "census", "--lr-beta", "0.2"],
         "--lr-beta: options of --model census-lr and census-sgm, which do not apply to --model census"),
        (["run", "--model", "census", "--no-lr-neutral"], "--no-lr-neutral: options of --model census-lr"),
        (["sweep", "--model", "paper,census", "--lr-right-nomatch"], "--lr-right-nomatch: options of"),
        (["run", "--model", "census-lr", "--lr-beta", "0"], "--lr-beta: lr_beta must be > 0"),
        (["run", "--model", "census-lr", "--lr-gamma", "2"], "--lr-gamma: lr_gamma must be a probability"),
        (["run", "--model", "census-lr", "--lr-tolerance", "-1"], "--lr-tolerance: lr_tolerance must be"),
        (["run", "--model", "census-lr", "--lr-beta", "1e-5"], "--lr-beta: lr_beta = 1e-05 quantizes to 0"),
        (["run", "--model", "census-lr", "--no-neighbour-prior"], "neighbour_prior must be on"),
        (["run", "--model", "census-lr", "--lr-right-max-cycles", "16"], "--lr-right-max-cycles: lr_right"),
        (["run", "--model", "census", "--lr-right-max-cycles", "100"], "--lr-right-max-cycles: options of"),
        # On chip the right pass's machine has no entropy port: an off-chip source is refused.
        pytest.param(["run", "--model", "census-lr", "--engine", "verilator", "--feed", "pixels", "--rng",
                      "smtj"],
                     "--rng: rng must be an on-chip random source for the census-lr model on chip",
                     marks=pytest.mark.eda),
    ],
)
def test_cli_refusals_are_one_line(pair_files, tmp_path, capsys, argv, message):
    from bayesmachine.cli import main

    argv = [argv[0], *_argv(pair_files, *argv[1:])]
    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
