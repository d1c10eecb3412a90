"""The per-pixel confidence (host/confidence.py) and its figures, held to the definitions of
docs/confidence.md by an independent re-computation from result.npz (loops over pixels, not the code
under test); the board gives the same confidence as the model (same counts) or, without counts, none."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.host.confidence import (
    FRACTIONS,
    ConfidenceParams,
    expected_calibration_error,
    measure_counts,
    reliability_table,
    sparsification_curve,
)

# A crop of the bundled pair whose confidences spread over (0, 1): (32-6) x (130-6-64) output pixels.
CROP = ["--crop", "300,150,130,32", "--dmax", "64", "--model", "census", "--no-sgbm", "--quiet"]


# --- the definitions, written out again pixel by pixel -------------------------------------------


def _distribution(counts: np.ndarray) -> np.ndarray | None:
    n = counts.sum()
    return None if n == 0 else counts.astype(np.float64) / n


def _mass(p: np.ndarray, d: int, t: int) -> float:
    """sum of p_j over disparity rows j (0..Dmax: not the last, no-match row) with |j - d| <= t."""
    return float(sum(p[j] for j in range(len(p) - 1) if abs(j - d) <= t))


def definitions(counts: np.ndarray, dmap: np.ndarray, t: int, window: int) -> dict[str, np.ndarray]:
    h, w, _ = counts.shape
    half = window // 2
    out = {k: np.zeros((h, w)) for k in ("mass", "confidence", "entropy", "nomatch_mass")}
    for y in range(h):
        for x in range(w):
            p = _distribution(counts[y, x])
            if p is not None:
                out["entropy"][y, x] = -sum(v * math.log2(v) for v in p if v > 0)
                out["nomatch_mass"][y, x] = p[-1]
            d = int(dmap[y, x])
            if d < 0:
                continue
            out["mass"][y, x] = _mass(p, d, t)
            near = [_distribution(counts[yy, xx]) for yy in range(max(0, y - half), min(h, y + half + 1))
                    for xx in range(max(0, x - half), min(w, x + half + 1))]
            near = [q for q in near if q is not None]
            out["confidence"][y, x] = _mass(sum(near) / len(near), d, t)
    return out


def definitions_by_shifts(counts: np.ndarray, dmap: np.ndarray, t: int, window: int) -> dict[str, np.ndarray]:
    """The same definitions for a whole run: the window's pixels added one shift at a time."""
    h, w, m = counts.shape
    c = counts.astype(np.float64)
    n = c.sum(-1, keepdims=True)
    has = n[..., 0] > 0
    p = np.divide(c, n, out=np.zeros_like(c), where=n > 0)
    rows = np.arange(m)
    near = (np.abs(rows - dmap[..., None].astype(np.int64)) <= t) & (rows < m - 1) & (dmap[..., None] >= 0)
    total, count = np.zeros_like(p), np.zeros((h, w))
    half = window // 2
    for dy in range(-half, half + 1):
        for dx in range(-half, half + 1):
            ys, xs = slice(max(0, -dy), min(h, h - dy)), slice(max(0, -dx), min(w, w - dx))
            yn, xn = slice(max(0, dy), min(h, h + dy)), slice(max(0, dx), min(w, w + dx))
            total[ys, xs] += p[yn, xn]
            count[ys, xs] += has[yn, xn]
    pooled = total / np.maximum(count, 1)[..., None]
    logs = np.log2(np.where(p > 0, p, 1.0))
    return {"mass": (p * near).sum(-1), "confidence": (pooled * near).sum(-1),
            "entropy": -(p * logs).sum(-1), "nomatch_mass": p[..., -1]}


def ece_by_definition(conf: np.ndarray, good: np.ndarray) -> float:
    conf = np.round(conf, 9)  # binned rounded to 9 decimals
    edges = np.arange(11) / 10
    total = 0.0
    for i in range(10):
        inside = (conf >= edges[i]) & ((conf < edges[i + 1]) | (i == 9))
        if inside.any():
            total += inside.sum() / len(conf) * abs(conf[inside].mean() - good[inside].mean())
    return total


def curve_by_definition(conf: np.ndarray, bad: np.ndarray) -> list[float]:
    """Kept: the (1 - f) N most confident; a group of equal confidence cut by the boundary counts
    its bad pixels in proportion to the part kept (the expectation over a random order within it)."""
    n = len(conf)
    # Groups of equal confidence (ranked rounded to 9 decimals), the most confident first.
    values, group, sizes = np.unique(-np.round(conf, 9), return_inverse=True, return_counts=True)
    bads = np.bincount(group, weights=bad.astype(np.float64), minlength=len(values))
    before = np.concatenate([[0], np.cumsum(sizes)])  # pixels in the groups more confident than group g
    bad_before = np.concatenate([[0.0], np.cumsum(bads)])
    curve = []
    for f in FRACTIONS:
        keep = (1 - f) * n
        g = int(np.searchsorted(before, keep, side="left")) - 1  # the group the boundary cuts (or ends)
        part = keep - before[g]
        curve.append((bad_before[g] + part / sizes[g] * bads[g]) / keep)
    return curve


# --- units ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, error", [
    ({"t": 1.5}, TypeError), ({"window": True}, TypeError), ({"t": -1}, ValueError),
    ({"window": 4}, ValueError), ({"window": 0}, ValueError),
])
def test_params_are_checked(kwargs, error) -> None:
    with pytest.raises(error):
        ConfidenceParams(**kwargs)
    with pytest.raises(TypeError):
        ConfidenceParams(2, 3)  # keyword-only
    assert ConfidenceParams().to_dict() == {"t": 2, "window": 3}


@pytest.mark.parametrize("t, window", [(2, 3), (0, 1), (1, 5)])
def test_maps_follow_the_definitions(t, window) -> None:
    """Pixel by pixel (and by shifts, the version the run checks below use)."""
    rng = np.random.default_rng(5)
    counts = rng.integers(0, 17, size=(7, 9, 12)).astype(np.uint8)
    counts[2, 3] = 0  # a pixel without counts: no distribution, left out of its neighbours' pools
    dmap = rng.integers(-1, 11, size=(7, 9)).astype(np.int16)
    dmap[2, 3] = -1
    maps = measure_counts(counts, dmap, ConfidenceParams(t=t, window=window), band_rows=2)
    want = definitions(counts, dmap, t, window)
    shifted = definitions_by_shifts(counts, dmap, t, window)
    for name, values in want.items():
        np.testing.assert_allclose(getattr(maps, name), values, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(shifted[name], values, atol=1e-12, err_msg=name)


def test_sparsification_with_ties_random_and_perfect_orders() -> None:
    conf = np.array([0.9, 0.9, 0.5, 0.5, 0.5, 0.1])
    bad = np.array([False, True, False, False, True, True])
    got = sparsification_curve(conf, bad)
    np.testing.assert_allclose(got, curve_by_definition(conf, bad))
    # f = 0.5 keeps 3 pixels: both 0.9s (1 bad) and a third of the 0.5 group (1/3 bad in expectation).
    np.testing.assert_allclose(got[10], (1 + 1 / 3) / 3)
    np.testing.assert_allclose(sparsification_curve(np.zeros(6), bad), 0.5)  # random: flat at the rate
    perfect = sparsification_curve((~bad).astype(float), bad)
    np.testing.assert_allclose(perfect, [max(0.0, 3 - f * 6) / ((1 - f) * 6) for f in FRACTIONS])


def test_ece_and_reliability_table() -> None:
    conf = np.array([0.05, 0.15, 0.95, 1.0, 0.95, 0.55])
    good = np.array([False, True, True, True, False, True])
    table = reliability_table(conf, good)
    assert [r["count"] for r in table] == [1, 1, 0, 0, 0, 1, 0, 0, 0, 3]
    assert table[9]["predicted"] == pytest.approx((0.95 + 1.0 + 0.95) / 3) and table[9]["observed"] == 2 / 3
    assert table[2]["predicted"] is None and table[2]["observed"] is None
    assert expected_calibration_error(conf, good) == pytest.approx(ece_by_definition(conf, good))
    assert math.isnan(expected_calibration_error(np.empty(0), np.empty(0, bool)))


# --- the run's outputs, recomputed from result.npz ------------------------------------------------------


def check_run_against_definitions(out: Path, t: int = 2, window: int = 3) -> dict:
    """result.npz's maps and report.json's figures equal what its counts, MAP and gt give by the
    definitions (independent code above)."""
    res = np.load(out / "result.npz")
    report = json.loads((out / "report.json").read_text())
    want = definitions_by_shifts(res["counts"], res["map"], t, window)
    for name, values in want.items():
        np.testing.assert_allclose(res[name], values, atol=1e-5, err_msg=name)
    gt, dmap = res["gt"].astype(np.float64), res["map"]
    sel = np.isfinite(gt) & (dmap >= 0)
    err = np.abs(dmap[sel] - gt[sel])
    conf = want["confidence"][sel]
    good, bad = err <= t, err > 2
    got = report["confidence"]["machine"]
    # Binned and ranked at 9 decimals, the two computations agree exactly (the run is deterministic).
    tolerance = 1e-9
    assert report["machine_confidence_ece"] == pytest.approx(ece_by_definition(conf, good), abs=tolerance)
    assert got["curve"] == pytest.approx(curve_by_definition(conf, bad), abs=tolerance)
    assert report["machine_confidence_auc"] == pytest.approx(np.mean(got["curve"]), abs=1e-9)
    assert report["machine_confidence_auc_random"] == pytest.approx(bad.mean())
    n = len(bad)
    perfect = [max(0.0, bad.sum() - f * n) / ((1 - f) * n) for f in FRACTIONS]
    assert report["machine_confidence_auc_perfect"] == pytest.approx(np.mean(perfect))
    assert sum(r["count"] for r in got["reliability"]) == n == got["pixels"]
    for name in ("disparity.png", "confidence.png", "calibration.png"):
        assert (out / name).stat().st_size > 0
    return report


def test_run_writes_the_confidence_and_its_figures(tmp_path) -> None:
    out = tmp_path / "o"
    assert main(["run", *CROP, "-o", str(out)]) == 0
    report = check_run_against_definitions(out)
    assert report["confidence"]["t"] == 2 and report["confidence"]["window"] == 3
    ref = report["confidence"]["reference"]
    assert 0 <= ref["ece"] <= 1 and ref["auc_perfect"] <= ref["auc_random"]
    assert np.load(out / "result.npz")["reference_confidence"].shape == (26, 60)


def test_run_with_other_t_and_window(tmp_path) -> None:
    out = tmp_path / "o"
    assert main(["run", *CROP, "--confidence-t", "1", "--confidence-window", "5", "-o", str(out)]) == 0
    check_run_against_definitions(out, t=1, window=5)


@pytest.mark.slow  # the whole bundled pair (census-lr, about a minute or two)
def test_bundled_pair_confidence_equals_its_definition(tmp_path) -> None:
    out = tmp_path / "o"
    assert main(["run", "--no-sgbm", "--quiet", "-o", str(out)]) == 0
    report = check_run_against_definitions(out)
    assert report["machine_confidence_ece"] <= 0.03
    assert report["machine_confidence_auc"] <= 0.35 * report["machine_confidence_auc_random"]


def test_min_confidence_blanks_and_reports_the_density(tmp_path) -> None:
    out = tmp_path / "o"
    assert main(["run", *CROP, "--min-confidence", "0.9", "--calib", "bundled", "-o", str(out)]) == 0
    res = np.load(out / "result.npz")
    report = json.loads((out / "report.json").read_text())
    kept = (res["map"] >= 0) & (res["confidence"] >= np.float32(0.9))
    assert 0 < kept.sum() < (res["map"] >= 0).sum()  # the map itself keeps every MAP
    assert report["min_confidence"]["density"] == pytest.approx(kept.mean())
    gt = res["gt"]
    sel = kept & np.isfinite(gt)
    assert report["min_confidence"]["bad2"] == pytest.approx(np.mean(np.abs(res["map"][sel] - gt[sel]) > 2))
    depth = np.load(out / "depth.npy")
    assert np.array_equal(np.isfinite(depth), kept) and report["cloud_points"] == kept.sum()


@pytest.mark.parametrize("argv, message", [
    (["--min-confidence", "0"], "expected a probability in (0, 1]"),
    (["--min-confidence", "nan"], "expected a finite number"),
    (["--confidence-window", "2"], "window must be odd (a square around its pixel), got 2"),
    (["--confidence-t", "-1"], "t must be an integer in [0, 4094], got -1"),
    # Bounded before any work: 2^63 - 1 wrapped in int64, 2^64 overflowed after the run.
    (["--confidence-t", "9223372036854775807"], "t must be an integer in [0, 4094]"),
    (["--confidence-window", "18446744073709551617"], "window must be an integer in [1, 4095]"),
])
def test_bad_confidence_options_are_one_error_line(argv, message, tmp_path, capsys) -> None:
    assert main(["run", *CROP, *argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "o").exists()


def test_sgbm_left_right_baseline(tmp_path) -> None:
    from bayesmachine.host.images import random_dot_stereogram
    from bayesmachine.host.metrics import sgbm_disparity, sgbm_lr_confidence

    left, right, _ = random_dot_stereogram(height=40, width=320, background=4, square=12, seed=2)
    conf = sgbm_lr_confidence(left, right, 16)
    valid = sgbm_disparity(left, right, 16) >= 0
    assert conf is not None and conf.shape == valid.shape == (36, 320 - 4 - 16)
    assert np.all(conf[~valid] == 0) and conf.max() == 1.0
    # A random-dot pair: left and right agree within 1 px but near the right edge (the mirrored SGBM run
    # leaves its last numDisparities columns invalid)
    assert np.mean(conf[valid] >= 0.5) > 0.8
    out = tmp_path / "o"
    assert main(["run", "--crop", "300,200,200,40", "--dmax", "40", "--model", "census", "--quiet",
                 "-o", str(out)]) == 0
    lr = json.loads((out / "report.json").read_text())["confidence"]["sgbm_lr"]
    assert lr["auc_perfect"] <= lr["auc"] and lr["pixels"] > 0


# --- the board: the same counts, so the same confidence; no counts, no confidence -----------------------


def test_board_gives_the_model_confidence_or_none(tmp_path, monkeypatch, capsys) -> None:
    from fpga.boards.test_board import DMAX, HEIGHT, WIDTH, TwinPort, _twin

    from bayesmachine.fpga.boards import link as link_mod

    def open_twin(port: str, baud: int, timeout: float = 2.0) -> TwinPort:
        port = TwinPort(_twin())
        port.close = lambda: None
        return port

    monkeypatch.setattr(link_mod, "open_port", open_twin)
    common = ["run", "--crop", f"400,250,{WIDTH},{HEIGHT}", "--dmax", str(DMAX), "--model", "paper",
              "--no-sgbm", "--quiet"]
    board = ["--engine", "board", "--port", "twin"]
    assert main([*common, *board, "-o", str(tmp_path / "board")]) == 0
    assert main([*common, *board, "--board-fields", "map", "-o", str(tmp_path / "map")]) == 0
    assert main([*common, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "board" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    for name in ("confidence", "mass", "entropy", "nomatch_mass"):
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    reports = {n: json.loads((tmp_path / n / "report.json").read_text()) for n in ("board", "map", "model")}
    assert reports["board"]["confidence"]["machine"] == reports["model"]["confidence"]["machine"]
    none = reports["map"]
    assert none["confidence"]["machine"] is None and "no counts" in none["confidence"]["note"]
    assert none["machine_confidence_auc"] is None if "machine_confidence_auc" in none else True
    assert not (tmp_path / "map" / "confidence.png").exists()
    capsys.readouterr()
    assert main([*common, *board, "--board-fields", "map", "--min-confidence", "0.5",
                 "-o", str(tmp_path / "x")]) == 2
    assert "no confidence to threshold" in capsys.readouterr().err


def test_a_run_without_matched_ground_truth_pixels_has_null_figures(tmp_path) -> None:
    """Dmax 8 on a crop whose disparities are all larger: no pixel to measure, figures null, figure drawn."""
    out = tmp_path / "o"
    assert main(["run", "--crop", "300,200,30,12", "--dmax", "8", "--model", "paper", "--no-sgbm", "--quiet",
                 "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["confidence"]["machine"]["pixels"] == 0 and report["machine_confidence_ece"] is None
    assert (out / "calibration.png").stat().st_size > 0


@pytest.mark.parametrize("quiet", [True, False])
def test_a_ground_truth_without_a_known_pixel_says_so(tmp_path, capsys, quiet) -> None:
    """All-NaN ground truth gave all-n/a figures with no word, an empty calibration.png and 'no-match
    calls on occluded pixels: 0.000'."""
    import cv2

    from bayesmachine.host.images import random_dot_stereogram
    from bayesmachine.host.metrics import NO_KNOWN_GT

    left, right, _ = random_dot_stereogram(height=16, width=40, seed=3)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    np.save(tmp_path / "gt.npy", np.full(left.shape, np.nan))
    out = tmp_path / "o"
    argv = ["run", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--gt", str(tmp_path / "gt.npy"),
            "--dmax", "8", "--model", "census", "--no-sgbm", *(["--quiet"] if quiet else []), "-o", str(out)]
    assert main(argv) == 0
    said = capsys.readouterr()
    assert (said.err if quiet else said.out).count(NO_KNOWN_GT) == 1
    assert "occluded" not in said.out and "bad-2" not in said.out
    report = json.loads((out / "report.json").read_text())
    assert report["ground_truth"] is True and report["ground_truth_pixels"] == 0
    assert report["confidence"]["note"] == NO_KNOWN_GT and "machine" not in report["confidence"]
    assert report.get("machine_nomatch_occluded") is None and report["machine_bad2"] is None
    assert not (out / "calibration.png").exists() and (out / "confidence.png").exists()
