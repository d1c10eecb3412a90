"""Occlusion fill (bayesmachine.host.fill): the rules on hand-made rows, the left-right column's rejection,
a run's filled map beside the machine's own in report.json and result.npz, and the semi-global model's
refusal of several machines on the hardware paths (its paths continue from the row above on one)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.host.fill import FILLS, fill_rows
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.models import ModelParams
from bayesmachine.params import ParameterError

ROW = np.array([[5, -1, -1, 3, 7, -1, 9, -1]])


@pytest.mark.parametrize(("rule", "want", "source"), [
    ("background", [5, 3, 3, 3, 7, 7, 9, 9], [0, 3, 3, 3, 4, 4, 6, 6]),
    ("left", [5, 5, 5, 3, 7, 7, 9, 9], [0, 0, 0, 3, 4, 4, 6, 6]),
    ("none", [5, -1, -1, 3, 7, -1, 9, -1], list(range(8))),
])
def test_rules_on_a_row(rule: str, want: list[int], source: list[int]) -> None:
    fill = fill_rows(ROW, np.zeros(ROW.shape, bool), rule)
    assert fill.map.tolist() == [want] and fill.source.tolist() == [source]
    assert fill.holes.tolist() == [(ROW < 0).tolist()[0]]
    assert fill.filled.tolist() == [[a < 0 and b >= 0 for a, b in zip(ROW[0], want, strict=True)]]
    conf = np.arange(8, dtype=float)[None] / 10
    assert fill.carried(conf).tolist() == [[s / 10 for s in source]]  # a filled pixel: its source's


def test_holes_beyond_no_match_and_rows_without_a_value() -> None:
    disp = np.array([[4, 6, 2, 8], [-1, -1, -1, -1]])
    holes = np.array([[False, True, False, False], [False] * 4])
    back = fill_rows(disp, holes, "background")
    assert back.map.tolist() == [[4, 2, 2, 8], [-1, -1, -1, -1]]  # the lower of 4 and 2; none to take
    left = fill_rows(np.array([[-1, 3, -1]]), np.zeros((1, 3), bool), "left")
    assert left.map.tolist() == [[-1, 3, 3]] and left.filled.tolist() == [[False, False, True]]
    with pytest.raises(ParameterError, match="fill must be one of") as err:
        fill_rows(disp, holes, "nearest")
    assert err.value.parameter == "fill" and FILLS == ("background", "left", "none")


def test_the_left_right_column_rejects_as_it_weighs() -> None:
    """A lane the column gives beta is rejected; a lane whose right pixel has no MAP is neutral (with
    lr_neutral) and not rejected; a pixel without a disparity is not."""
    column = ModelParams(name="census-sgm", dmax=4).columns[-1]
    right = np.array([[2, -1, 0, 1, 1]])  # right map columns 0..4
    disp = np.array([[2, 0, 1, -1]])  # left map columns 2..5: x - d = 0, 3, 3, -
    got = column.rejects(disp, right, 0, np.array([2, 3, 4, 5]))
    assert got.tolist() == [[False, False, False, False]]
    got = column.rejects(np.array([[0, 2, 3, 1]]), right, 0, np.array([2, 3, 4, 5]))
    # x - d = 2 (right MAP 0: consistent), 1 (none: neutral), 1 (neutral), 4 (MAP 1: consistent)
    assert got.tolist() == [[False, False, False, False]]
    got = column.rejects(np.array([[2, 3, 0, 4]]), right, 0, np.array([2, 3, 4, 5]))
    # x - d = 0 (MAP 2 vs 2), 0 (2 vs 3: within 1), 4 (1 vs 0: within 1), 1 (none)
    assert got.tolist() == [[False, False, False, False]]
    got = column.rejects(np.array([[0, 0, 4]]), right, 0, np.array([2, 3, 4]))
    # x - d = 2 (MAP 0 vs 0), 3 (MAP 1 vs 0: within 1), 0 (MAP 2 vs 4: rejected)
    assert got.tolist() == [[False, False, True]]


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("pair")
    left, right, gt = random_dot_stereogram(height=16, width=40, background=2, square=7, seed=4)
    cv2.imwrite(str(d / "l.png"), left)
    cv2.imwrite(str(d / "r.png"), right)
    np.save(d / "gt.npy", gt.astype(np.float64))
    return d


def _run(pair, out, *options: str) -> int:
    return main(["run", str(pair / "l.png"), str(pair / "r.png"), "--gt", str(pair / "gt.npy"), "--dmax", "6",
                 "--model", "census-sgm", "--no-sgbm", "--quiet", *options, "-o", str(out)])


def test_a_run_keeps_the_machines_map_beside_the_filled_one(pair, tmp_path) -> None:
    assert _run(pair, tmp_path / "bg") == 0
    npz = np.load(tmp_path / "bg" / "result.npz")
    report = json.loads((tmp_path / "bg" / "report.json").read_text())
    own, filled, mask = npz["map"], npz["filled_map"], npz["filled"]
    assert report["fill"] == "background" and report["filled_pixels"] == int(mask.sum())
    kept = ~mask & (filled >= 0)
    np.testing.assert_array_equal(filled[kept], own[kept])  # the machine's disparity where not filled
    assert (filled[mask] >= 0).all() and report["fill_holes"] >= mask.sum() >= (own < 0).sum() > 0
    assert npz["nomatch"].dtype == bool and (npz["nomatch"] <= (own < 0)).all()
    assert {"filled_bad2_nomatch_bad", "filled_confidence_ece", "machine_bad2_nomatch_bad"} <= set(report)
    assert _run(pair, tmp_path / "none", "--fill", "none") == 0
    npz_none = np.load(tmp_path / "none" / "result.npz")
    assert "filled_map" not in npz_none.files
    np.testing.assert_array_equal(npz_none["map"], own)  # the fill changes no result of the machine


@pytest.mark.parametrize("argv", [
    ["emit", "--top", "stereo", "--width", "120", "--dmax", "8", "-o", "{o}/stereo.v"],
    ["run", "--feed", "pixels", "--engine", "verilator", "--crop", "250,200,140,16", "-o", "{o}"],
])
def test_the_hardware_paths_refuse_several_machines_of_the_semiglobal_model(argv, tmp_path, capsys) -> None:
    argv = [a.replace("{o}", str(tmp_path / "o")) for a in argv]
    assert main([*argv, "--model", "census-sgm", "--machines", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "semiglobal column continues from the row above on one machine" in err[0], err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_a_sweep_fills_as_asked_and_says_so(pair, tmp_path) -> None:
    """``sweep --fill``: each point's figures of the filled map by the rule asked, sweep.json names the
    rule, and a point's result fingerprint differs between rules (a resumed sweep never mixes them)."""
    base = ["sweep", str(pair / "l.png"), str(pair / "r.png"), "--gt", str(pair / "gt.npy"), "--dmax", "6",
            "--model", "census-sgm", "--counter-max", "16", "--no-sgbm", "--quiet", "--workers", "0"]
    sweeps = {}
    for rule in ("left", "none"):
        assert main([*base, "--fill", rule, "-o", str(tmp_path / rule)]) == 0
        sweeps[rule] = json.loads((tmp_path / rule / "sweep.json").read_text())
    assert _run(pair, tmp_path / "run-left", "--fill", "left") == 0
    run = json.loads((tmp_path / "run-left" / "report.json").read_text())
    left, none = sweeps["left"], sweeps["none"]
    assert left["fill"] == "left" and none["fill"] == "none"
    point = left["points"][0]
    assert point["filled_bad2_nomatch_bad"] == run["filled_bad2_nomatch_bad"]  # the run's own figure
    assert point["filled_pixels"] == run["filled_pixels"] > 0
    assert none["points"][0].get("filled_pixels") is None
    results = [json.loads(next((tmp_path / r / "runs").rglob("result.json")).read_text()) for r in sweeps]
    assert results[0]["fingerprint"] != results[1]["fingerprint"]
