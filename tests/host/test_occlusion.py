"""Occlusion from ground truth, the share of no-match calls on occluded pixels, OpenCV StereoBM."""

import math

import numpy as np

from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.metrics import (
    bm_disparity,
    gt_region,
    nomatch_occluded_share,
    occluded_mask,
    sgbm_disparity,
)


def test_a_disparity_jump_hides_as_many_pixels():
    gt = np.full((3, 30), 2.0)
    gt[:, 10:15] = 6.0  # a nearer square: a jump of 4 at its left edge
    gt[2, 0] = np.inf  # unknown: never occluded
    occ = occluded_mask(gt)
    expected = np.zeros(30, bool)
    expected[6:10] = True  # x - 2 in [4, 8) lies under the square's [4, 9)
    np.testing.assert_array_equal(occ[0], expected)
    assert not occ[2, 0]
    # A slanted surface (disparity growing by less than 1 per pixel) hides nothing.
    ramp = np.tile(np.linspace(0.0, 20.0, 40), (2, 1))
    assert not occluded_mask(ramp).any()


def test_nomatch_occluded_share():
    disp = np.array([[-1, 3, -1, -1], [2, 2, 2, 2]])
    occ = np.array([[True, False, False, True], [True, True, False, False]])
    assert nomatch_occluded_share(disp, occ) == 2 / 3
    assert math.isnan(nomatch_occluded_share(np.zeros((2, 2)), occ[:, :2]))


def test_bm_disparity_on_a_random_dot_pair():
    left, right, gt = random_dot_stereogram(height=80, width=140, background=4, square=12, seed=2)
    dmax = 20
    for disp in (bm_disparity(left, right, dmax), sgbm_disparity(left, right, dmax)):
        g = gt_region(gt, dmax)
        assert disp.shape == g.shape
        ok = (disp >= 0) & np.isfinite(g)
        assert ok.mean() > 0.5 and np.mean(np.abs(disp[ok] - g[ok]) <= 1) > 0.9
    # The occluded pixels of this pair are where the square's jump hides the background.
    occ = gt_region(occluded_mask(gt), dmax)
    assert 0 < occ.mean() < 0.1
