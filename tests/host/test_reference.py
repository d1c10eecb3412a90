"""The float64 reference: known disparities, fast kernel == plain formula, tie rule; the census
model's raster-order prior against a plain loop, and the quantized reference against exact Python
integer products of the machine's own words."""

import math

import numpy as np
import pytest
from columns.test_census import census_pair

from bayesmachine.columns import AbovePrior
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.metrics import gt_region
from bayesmachine.host.reference import (
    reference,
    reference_bands,
    reference_fast,
    reference_map,
    reference_plain,
    reference_prior_plain,
    reference_quantized,
    reference_quantized_map,
)
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import ParameterError


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


# --- Any number of FEATURES columns ---

@pytest.fixture(scope="module")
def five():
    """A model of five FEATURES columns (the paper's, census, gradient magnitude), registered here."""
    from bayesmachine.columns import Census, GradH, GradMag, GradV, Mean
    from bayesmachine.models import MODELS, ModelDef, register_model

    register_model(ModelDef(name="five-columns", description="five FEATURES columns",
                            columns=(Mean, GradH, GradV, Census, GradMag)))
    try:
        yield ModelParams(name="five-columns", dmax=10, census_sigma=4.0)
    finally:
        MODELS.pop("five-columns")


def test_five_feature_columns_fast_equals_plain(rds, five):
    from bayesmachine.host.features import model_planes

    left, right, _ = rds
    fl, fr = model_planes(left, five), model_planes(right, five)
    fast, plain = reference_fast(fl, fr, five), reference_plain(fl, fr, five)
    np.testing.assert_array_equal(fast.map, plain.map)
    np.testing.assert_allclose(fast.posterior, plain.posterior, rtol=1e-13, atol=1e-300)
    banded = reference_map(fl, fr, five, band_rows=7)
    np.testing.assert_array_equal(banded, fast.map)
    # The fifth column changes the paper's answer here and there (it is in the product).
    paper = ModelParams(name="paper", dmax=10)
    assert (reference_map(fl, fr, paper) != fast.map).any()


@pytest.mark.parametrize("word_bits", [10, 15])
def test_five_feature_columns_on_words_are_python_integer_products(rds, five, word_bits):
    """5 words of 10 bits: 50 bits, one int64; of 15 bits: 75 bits, two limbs (the kernel takes the
    first four columns, the fifth is a factor)."""
    import math

    from bayesmachine.host.features import model_planes
    from bayesmachine.host.likelihoods import memory_words
    from bayesmachine.host.products import limbs_for
    from bayesmachine.host.reference import reference_quantized
    from bayesmachine.models import disparity_machine

    assert limbs_for(5, word_bits) == (1 if word_bits == 10 else 2)
    left, right, _ = rds
    rows = slice(10, 14)
    fl, fr = (model_planes(im, five).band(slice(0, 24)) for im in (left, right))
    machine = disparity_machine(five, word_bits=word_bits)
    words = memory_words(fl, fr, five, machine, rows=rows)
    products = [[math.prod(int(v) for v in row) for row in pixel] for pixel in words]
    want = np.array([max(range(len(p)), key=lambda j: (p[j], -j)) for p in products])
    want[want == five.dmax + 1] = -1
    got = reference_quantized(fl, fr, five, word_bits, rows=rows)
    np.testing.assert_array_equal(got.map.reshape(-1), want)
    post = np.array([[v / sum(p) for v in p] for p in products])
    np.testing.assert_allclose(got.posterior.reshape(post.shape), post, rtol=1e-12, atol=1e-300)


def test_limbs_for():
    from bayesmachine.host.products import limbs_for

    assert [limbs_for(n, 10) for n in (1, 6, 7, 9, 10)] == [1, 1, 2, 2, 3]  # 62, 94, 126 bits a limb count
    assert limbs_for(4, 15) == 1 and limbs_for(5, 15) == 2 and limbs_for(7, 15) == 3


@pytest.mark.parametrize("kw", [
    {},
    {"census_window": 5},
    {"neighbour_prior": False},
    {"prior_eps": 0.2, "prior_s": 1.5, "prior_nomatch": 0.3},
    {"census_nomatch_h": 0},
])
def test_reference_equals_plain_raster_prior(kw):
    fl, fr, model = census_pair(8, **kw)
    fast = reference_fast(fl, fr, model)
    plain = reference_prior_plain(fl, fr, model)
    np.testing.assert_array_equal(fast.map, plain.map)
    np.testing.assert_allclose(fast.posterior, plain.posterior, rtol=1e-13, atol=1e-300)
    assert (fast.map < 0).any() and (fast.map >= 0).any()
    # Band by band (the last MAP row carried into the next band) gives the same MAP.
    for rows in (1, 4):
        np.testing.assert_array_equal(reference_map(fl, fr, model, band_rows=rows), fast.map)


def test_prior_changes_the_map_and_needs_the_row_above():
    fl, fr, model = census_pair(8)
    with_prior = reference_fast(fl, fr, model).map
    without = reference_fast(fl, fr, ModelParams(dmax=8, name="census", neighbour_prior=False)).map
    assert (with_prior != without).any()
    with pytest.raises(ValueError, match="above"):
        reference_fast(fl, fr, model, rows=slice(2, 5))
    whole = reference_fast(fl, fr, model)
    part = reference_fast(fl, fr, model, rows=slice(2, 5), above=whole.map[1])
    np.testing.assert_array_equal(part.map, whole.map[2:5])


def _quantized_plain(fl, fr, model, word_bits):
    """The exact inference on the machine's words: Python-int products of the loaded words and, with
    the prior, the feedback word the machine forms from the left MAP (its own rule, written out)."""
    machine = disparity_machine(model, word_bits=word_bits)
    ho, wo = fl.shape[0], fl.shape[1] - model.dmax
    m = model.hypotheses
    disp = np.full((ho, wo), -1, np.int64)
    post = np.empty((ho, wo, m))
    prior = model.column(AbovePrior)
    fb = machine.feedback_words
    for y in range(ho):
        # the above column: this inference's own previous row
        above = (disp[y - 1] if y > 0 else np.full(wo, -1)) if prior is not None else None
        words = memory_words(fl, fr, model, machine, rows=slice(y, y + 1), above=above)
        for x in range(wo):
            w = [[int(v) for v in row] for row in words[x]]
            left = disp[y, x - 1] if x > 0 else -1
            if prior is not None:
                for r in range(m):
                    if left < 0:
                        f = 1 << word_bits
                    elif r == m - 1:
                        f = machine.feedback_nomatch_word
                    else:
                        f = fb[min(abs(r - left), len(fb) - 1)]
                    w[r].append(f)
            vals = [math.prod(w[j]) for j in range(m)]
            best = max(range(m), key=lambda j: (vals[j], -j))
            disp[y, x] = best if best <= model.dmax else -1
            post[y, x] = [v / sum(vals) for v in vals]
    return disp, post


@pytest.mark.parametrize("kw", [{}, {"neighbour_prior": False}, {"census_window": 5}])
def test_quantized_reference_is_the_words_inference(kw):
    fl, fr, model = census_pair(8, **kw)
    got = reference_quantized(fl, fr, model, 10)
    want_map, want_post = _quantized_plain(fl, fr, model, 10)
    np.testing.assert_array_equal(got.map, want_map)
    # The weights are the exact products (the two prior factors separately, as the machine's AND
    # gates multiply them), not a rounded combined prior word.
    np.testing.assert_allclose(got.posterior, want_post, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(got.posterior.sum(axis=-1), 1.0, rtol=1e-12)
    np.testing.assert_array_equal(reference_quantized_map(fl, fr, model, 10, band_rows=3), got.map)
    # Coarse words change some MAPs; the float reference is close to 10-bit words here.
    assert np.mean(got.map == reference_fast(fl, fr, model).map) > 0.9


def test_quantized_reference_of_the_paper_model():
    fl, fr, _ = census_pair(8)
    paper = ModelParams(name="paper", dmax=8)
    got = reference_quantized(fl, fr, paper, 6)
    np.testing.assert_array_equal(got.map, _quantized_plain(fl, fr, paper, 6)[0])
    census = ModelParams(dmax=8, name="census")
    with pytest.raises(ParameterError, match="^word_bits: words of 1 to 15 bits, got 16"):
        reference_quantized(fl, fr, census, 16)
    # 4 data words and 2 prior words of 11 bits (66 bits) or 15 bits (90 bits): products of two limbs,
    # exact.
    for w in (11, 15):
        want_map, want_post = _quantized_plain(fl, fr, census, w)
        got = reference_quantized(fl, fr, census, w)
        np.testing.assert_array_equal(got.map, want_map)
        np.testing.assert_allclose(got.posterior, want_post, rtol=1e-12, atol=1e-300)
    # The paper model's three words take the widest words (their product fits 62 bits at W = 15).
    wide = reference_quantized(fl, fr, paper, 15)
    np.testing.assert_array_equal(wide.map, _quantized_plain(fl, fr, paper, 15)[0])
    assert (wide.posterior >= 0).all()
