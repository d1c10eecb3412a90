"""Metrics on hand-made cases: F1, RMS, bad-n, cycles, MAP agreement; SGBM region."""

import math

import numpy as np
import pytest

from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.metrics import (
    bad_rates,
    cycle_stats,
    f1_score,
    map_agreement,
    rms_error,
    sgbm_disparity,
    sgbm_numdisparities,
)
from bayesmachine.region import OutputRegion


def test_f1():
    pred = np.array([True, True, False, False])
    act = np.array([True, False, True, False])
    assert f1_score(pred, act) == pytest.approx(2 * 1 / (2 * 1 + 1 + 1))
    assert f1_score(act, act) == 1.0
    assert f1_score(~act, act) == 0.0
    assert math.isnan(f1_score(np.zeros(3, bool), np.zeros(3, bool)))


def test_rms_over_matched_pixels_and_all_rows():
    counts = np.array([[16, 8, 0], [0, 0, 16]], np.uint32)  # pixel 1 is excluded (not matched)
    post = np.array([[0.5, 0.25, 0.25], [0.9, 0.05, 0.05]])
    matched = np.array([True, False])
    # counts/16 = [1, .5, 0]; posterior/max = [1, .5, .5]: one error of 0.5 over 3 values.
    assert rms_error(counts, 16, post, matched) == pytest.approx(math.sqrt(0.25 / 3))
    assert rms_error(
        counts.reshape(1, 2, 3), 16, post.reshape(1, 2, 3), matched.reshape(1, 2)
    ) == pytest.approx(math.sqrt(0.25 / 3))
    assert math.isnan(rms_error(counts, 16, post, np.zeros(2, bool)))
    assert rms_error(np.array([[4, 2]]), 4, np.array([[0.6, 0.3]]), np.array([True])) == 0.0


def test_bad_rates():
    disp = np.array([0, 5, -1, 3])
    gt = np.array([0.0, 2.0, 4.0, np.inf])  # the last pixel has no ground truth
    b1 = bad_rates(disp, gt, 1)
    assert b1["matched"] == pytest.approx(1 / 2)  # pixel 1 is off by 3; pixel 2 is no match
    assert b1["nomatch_bad"] == pytest.approx(2 / 3)
    assert b1["coverage"] == pytest.approx(2 / 3)
    assert bad_rates(disp, gt, 3)["matched"] == 0.0
    assert bad_rates(np.array([1.5]), np.array([0.0]), 1)["matched"] == 1.0  # strictly greater than n
    assert bad_rates(np.array([1.0]), np.array([0.0]), 1)["matched"] == 0.0


def test_cycle_stats_and_agreement():
    s = cycle_stats(np.array([1, 2, 3, 4]))
    assert s["mean"] == 2.5 and s["std"] == pytest.approx(math.sqrt(1.25))
    assert s["p99"] == pytest.approx(np.percentile([1, 2, 3, 4], 99))
    assert s["median"] == 2.5 and s["p10"] == pytest.approx(1.3) and s["p90"] == pytest.approx(3.7)
    assert map_agreement(np.array([1, -1, 3, 4]), np.array([1, -1, 2, 4])) == 0.75


def test_sgbm_on_random_dots():
    assert sgbm_numdisparities(80) == 96 and sgbm_numdisparities(15) == 16 and sgbm_numdisparities(16) == 32
    left, right, gt = random_dot_stereogram(height=60, width=120, background=6, square=6, seed=2)
    d = sgbm_disparity(left, right, dmax=15)
    region = OutputRegion.of_image(gt.shape, 15)
    assert d.shape == region.cut(gt).shape == region.shape == (56, 120 - 4 - 15)
    # A fronto-parallel textured plane: SGBM should find it nearly everywhere.
    assert bad_rates(d, region.cut(gt), 1)["matched"] < 0.1
