"""The float64 reference: known disparities, fast kernel == plain formula, tie rule."""

import numpy as np
import pytest

from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.metrics import gt_region
from bayesmachine.host.reference import (
    reference,
    reference_bands,
    reference_fast,
    reference_map,
    reference_plain,
)
from bayesmachine.models import ModelParams


@pytest.fixture(scope="module")
def rds():
    return random_dot_stereogram(height=48, width=90, background=3, square=11, seed=5)


def test_map_finds_the_known_disparity(rds):
    left, right, gt = rds
    model = ModelParams(name="paper", dmax=16)
    ref = reference(left, right, model)
    g = gt_region(gt, model.dmax)
    assert ref.map.shape == (44, 90 - 4 - 16) == g.shape
    # A pixel whose whole 5x5 window lies at one disparity has an exact match in the right image.
    win = np.lib.stride_tricks.sliding_window_view(gt, (5, 5))[:, model.dmax :]
    uniform = (win.min(axis=(-1, -2)) == win.max(axis=(-1, -2))) & np.isfinite(g)
    assert uniform.sum() > 0.7 * uniform.size
    for d in (3, 11):
        sel = uniform & (g == d)
        assert sel.sum() > 100
        assert np.mean(ref.map[sel] == d) > 0.95
    # Windows straddling the square's edges see two disparities: still mostly right overall.
    known = np.isfinite(g)
    assert np.mean(ref.map[known] == g[known]) > 0.85


def test_posterior_is_normalized_with_nomatch_last(rds):
    left, right, _ = rds
    model = ModelParams(name="paper", dmax=12)
    ref = reference(left, right, model)
    assert ref.posterior.shape == (44, 90 - 4 - 12, 14) and ref.posterior.dtype == np.float64
    np.testing.assert_allclose(ref.posterior.sum(axis=-1), 1.0, rtol=1e-12)
    idx = np.where(ref.map < 0, model.dmax + 1, ref.map)
    np.testing.assert_array_equal(idx, ref.posterior.argmax(axis=-1))


@pytest.mark.parametrize("seed", [0, 1])
def test_fast_equals_plain(rds, seed):
    rng = np.random.default_rng(seed)
    left, right, _ = rds
    # Add smooth and flat patches so ties and no-match pixels occur too.
    left = left.copy()
    right = right.copy()
    left[10:30, 40:70] = 128
    right[10:30, 30:60] = 128
    left[:, :20] = rng.integers(100, 104, size=(48, 20))
    for model in (ModelParams(name="paper", dmax=10),
                  ModelParams(name="paper", dmax=20, p0=0.1, sigma_m=4, sigma_gv=20, sigma_nm=3)):
        fl, fr = feature_sums(left), feature_sums(right)
        fast, plain = reference_fast(fl, fr, model), reference_plain(fl, fr, model)
        np.testing.assert_allclose(fast.posterior, plain.posterior, rtol=1e-13, atol=1e-300)
        np.testing.assert_array_equal(fast.map, plain.map)
        assert fast.map.dtype == np.int16
        assert (fast.map < 0).any() and (fast.map >= 0).any()


def test_exact_ties_go_to_the_lowest_index():
    # A flat pair: every disparity has likelihood 1 and so has no match (gV = 0): a full tie.
    img = np.full((9, 20), 77, np.uint8)
    model = ModelParams(name="paper", dmax=5)
    for ref in (reference(img, img, model), reference_plain(feature_sums(img), feature_sums(img), model)):
        assert (ref.map == 0).all()
        np.testing.assert_allclose(ref.posterior, 1.0 / model.hypotheses)


def test_out_buffer_is_checked(rds):
    left, right, _ = rds
    fl, fr = feature_sums(left), feature_sums(right)
    model = ModelParams(name="paper", dmax=4)
    with pytest.raises(ValueError, match="out must be float64"):
        reference_fast(fl, fr, model, out=np.empty((1, 2, 3)))


@pytest.mark.parametrize("band_rows", [1, 5, 100])
def test_bands_equal_the_whole_frame(rds, band_rows):
    left, right, _ = rds
    fl, fr = feature_sums(left), feature_sums(right)
    model = ModelParams(name="paper", dmax=9)
    whole = reference_fast(fl, fr, model)
    posts, maps, rows_seen = [], [], []
    for rows, band in reference_bands(fl, fr, model, band_rows):
        rows_seen.append(rows)
        posts.append(band.posterior.copy())  # the buffer is reused by the next band
        maps.append(band.map)
    assert rows_seen[0].start == 0 and rows_seen[-1].stop == 44
    assert all(a.stop == b.start for a, b in zip(rows_seen, rows_seen[1:], strict=False))
    np.testing.assert_array_equal(np.concatenate(posts), whole.posterior)
    np.testing.assert_array_equal(np.concatenate(maps), whole.map)
    np.testing.assert_array_equal(reference_map(fl, fr, model, band_rows), whole.map)
