"""The census model: parameters, tables, census codes, words, float and word references.

Oracles are independent of the code under test: census codes pixel by pixel in Python,
Hamming distances by unpacking bytes, likelihoods and priors from the formula (no tables),
the raster-order prior in a plain Python loop, and the quantized inference as exact Python
integer products of the machine's own words.
"""

import math

import numpy as np
import pytest

from bayesmachine.cliargs import with_flag
from bayesmachine.columns import AbovePrior, Census, neighbour_words, quantize
from bayesmachine.host.features import (
    Planes,
    census_codes,
    census_codes_plain,
    census_offsets,
    feature_sums,
    model_planes,
)
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import (
    hamming,
    hamming_plain,
    memory_words,
    memory_words_plain,
)
from bayesmachine.host.reference import (
    reference_fast,
    reference_map,
    reference_prior_plain,
    reference_quantized,
    reference_quantized_map,
)
from bayesmachine.models import (
    CENSUS_WATCHDOG_RUNS,
    ModelParams,
    check_disparity_machine,
    disparity_machine,
    machine_layout,
)
from bayesmachine.params import MachineParams, ParameterError

PAPER_KEYS = ["dmax", "name", "p0", "sigma_m", "sigma_gh", "sigma_gv", "gradient_magnitude", "sigma_g",
              "p_nm0", "sigma_nm"]


# --- Parameters ---

def test_census_defaults():
    m = ModelParams(name="census", fuse_columns=False)
    census = m.column(Census)
    assert (m.census_window, census.bits, m.census_sigma, m.census_nomatch_h) == (7, 48, 6.0, 6)
    assert m.census_p0 == 0.02
    assert (m.prior_eps, m.prior_s, machine_layout(m.columns)) == (0.05, 4.0, ("neighbour", 4))
    assert m.prior_nomatch == pytest.approx(0.05 + 0.95 * math.exp(-0.5))
    assert round(m.prior_nomatch, 3) == 0.626
    five = ModelParams(name="census", fuse_columns=False, census_window=5)
    assert (five.column(Census).bits, five.census_sigma, five.census_nomatch_h) == (24, 3.0, 3)
    assert ModelParams(name="census", fuse_columns=False, census_window=5,
                       census_sigma=2.5).census_sigma == 2.5
    wide = ModelParams(name="census", fuse_columns=False, prior_eps=0.2)
    assert wide.prior_nomatch == pytest.approx(0.2 + 0.8 * math.exp(-0.5))


def test_paper_model_has_its_parameters_only_and_dicts_round_trip():
    paper = ModelParams(name="paper")
    assert list(paper.to_dict()) == PAPER_KEYS
    assert ModelParams(**paper.to_dict()) == paper  # the name too: ModelParams() is another model
    assert paper.column(Census) is None and machine_layout(paper.columns) == ("uniform", 3)
    with pytest.raises(AttributeError, match="census_window"):
        paper.census_window  # noqa: B018
    with pytest.raises(ParameterError, match="^census_window is not a parameter of the paper model"):
        ModelParams(name="paper", census_window=5)
    with pytest.raises(TypeError, match="census_widow"):
        ModelParams(name="census", census_widow=5)
    census = ModelParams(name="census", census_window=5)
    d = census.to_dict()
    assert d["name"] == "census" and d["census_sigma"] == 3.0 and d["census_nomatch_h"] == 3
    assert ModelParams(**d) == census and hash(ModelParams(**d)) == hash(census)


def test_replace_keeps_the_given_parameters_and_resolves_the_others():
    import pickle

    m = ModelParams(name="census", prior_s=3.0)
    five = m.replace(census_window=5)
    assert (five.census_window, five.census_sigma, five.census_nomatch_h, five.prior_s) == (5, 3.0, 3, 3.0)
    assert pickle.loads(pickle.dumps(m)).replace(census_window=5) == five
    # Another model: its own defaults (census-lr's no-match prior factor is its own, not census's).
    assert ModelParams(name="census-lr").replace(name="census") == ModelParams(name="census")
    assert ModelParams(name="census", census_window=5).replace(name="paper") == ModelParams(name="paper")


@pytest.mark.parametrize(("kwargs", "option"), [
    ({"name": "sgbm"}, "--model"),
    ({"census_window": 9}, "--census-window"),
    ({"census_p0": 1.5}, "--census-p0"),
    ({"census_sigma": 0.0}, "--census-sigma"),
    ({"census_sigma": math.nan}, "--census-sigma"),
    ({"census_sigma": 1e-300}, "--census-sigma"),
    ({"census_nomatch_h": 49}, "--census-nomatch-h"),
    ({"census_window": 5, "census_nomatch_h": 25}, "--census-nomatch-h"),
    ({"prior_eps": -0.1}, "--prior-eps"),
    ({"prior_s": -4.0}, "--prior-s"),
    ({"prior_s": math.inf}, "--prior-s"),
    ({"prior_nomatch": 0.0}, "--prior-nomatch"),
    ({"prior_nomatch": 1.2}, "--prior-nomatch"),
])
def test_bad_census_params_name_the_parameter_and_the_cli_its_option(kwargs, option):
    with pytest.raises(ParameterError) as err:
        ModelParams(**{"name": "census", **kwargs})
    assert str(err.value).startswith(err.value.parameter)
    assert str(with_flag(err.value)).startswith(f"{option}")


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"census_window": True}, "census_window"), ({"census_window": 7.0}, "census_window"),
    ({"census_nomatch_h": 2.5}, "census_nomatch_h"), ({"neighbour_prior": 1}, "neighbour_prior"),
])
def test_wrong_census_types_are_type_errors(kwargs, name):
    with pytest.raises(TypeError, match=f"^{name}"):
        ModelParams(**{"name": "census", **kwargs})


# --- Tables ---

def test_tables_at_known_points():
    model = ModelParams(dmax=80, name="census", fuse_columns=False)
    census, prior = model.column(Census), model.column(AbovePrior)
    t, tp = census.table(), prior.table()
    assert t.values.shape == (49,) and t.values[0] == 1.0
    assert t.values[6] == pytest.approx(0.02 + 0.98 * math.exp(-0.5))
    assert t.values[48] == pytest.approx(0.02 + 0.98 * math.exp(-48 * 48 / 72))
    assert t.nomatch == (t.values[6],) and census.nomatch_entry(t) == t.values[6]
    assert tp.values.shape == (81,) and tp.values[0] == 1.0
    assert tp.values[4] == pytest.approx(model.prior_nomatch) and tp.nomatch == (model.prior_nomatch,)
    assert tp.values[80] == pytest.approx(0.05)
    q, qp = census.table(10), prior.table(10)
    assert (q.values[0], census.nomatch_entry(q), qp.values[0], qp.nomatch[0]) == (1024, 629, 1024, 641)
    assert census.nomatch_entry(q) == quantize(t.values[6], 10)
    # last_change: the quantized prior changes up to it and is constant from it on.
    last = qp.last_change()
    assert qp.values[last - 1] != qp.values[last]
    assert (qp.values[last:] == quantize(0.05, 10)).all()
    # The paper model has no such columns, nor the census model without its prior a prior column.
    assert ModelParams(name="paper", dmax=8).column(Census) is None
    assert ModelParams(dmax=8, name="census", fuse_columns=False,
                       neighbour_prior=False).column(AbovePrior) is None
    # h_nm = 0 leaves the no-match row uncalibrated: its census entry is exactly 1.0.
    assert ModelParams(dmax=8, name="census", fuse_columns=False,
                       census_nomatch_h=0).column(Census).table().nomatch == (1.0,)


def test_every_table_is_checked_nonincreasing_in_its_cost():
    for model in (ModelParams(name="census-lr"), ModelParams(name="census", census_window=5, prior_s=0.5)):
        for p in model.passes:
            for term in (*(f for c in p.columns for f in c.factors()), p.model.nomatch):  # fused: members
                v = term.table().values
                assert (np.diff(v) <= 0).all(), term
    class Growing(Census):  # a kind whose likelihood grows with the cost: refused when its table is built
        def likelihood(self, cost):
            return np.linspace(0.5, 1.0, np.size(cost))

    model = ModelParams(name="census")
    with pytest.raises(ParameterError, match="^census_sigma = 6.0 gives likelihoods that grow with the cost"):
        Growing(values=model.parameters, dmax=model.dmax).table()


def test_neighbour_words_from_one_neighbour():
    model = ModelParams(dmax=6, name="census")
    above = model.column(AbovePrior)
    q = above.table(10)
    w = above.loaded(q, np.array([-1, 2, 3, 6], np.int16))
    assert w.shape == (4, 8)
    assert (w[0] == 1024).all()  # no matched neighbour: factor 1.0 everywhere, no-match row too
    d = np.arange(7)
    eps = model.prior_eps
    f = [quantize(eps + (1 - eps) * np.exp(-(k * k) / (2 * 16.0)), 10) for k in range(7)]
    np.testing.assert_array_equal(w[1, :7], [f[abs(k - 2)] for k in d])
    np.testing.assert_array_equal(w[2, :7], [f[abs(k - 3)] for k in d])
    np.testing.assert_array_equal(w[3, :7], [f[abs(k - 6)] for k in d])
    assert (w[1:, 7] == q.nomatch[0]).all()
    with pytest.raises(ValueError, match="0..6"):
        neighbour_words(q, 6, np.array([7]))
    # The float64 factors are the same rule on the float table (the reference's).
    f = above.loaded(above.table(), np.array([2], np.int16))
    np.testing.assert_array_equal(quantize(f, 10), w[1:2])


def test_disparity_machine_builds_the_model_s_machine():
    paper = ModelParams(name="paper", dmax=6)
    assert disparity_machine(paper, counter_max=4) == MachineParams.for_disparity(6, counter_max=4)
    no_prior = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    assert disparity_machine(no_prior) == MachineParams.for_disparity(
        6, columns=4, timeout_answer="leading", normalize=True, max_cycles=CENSUS_WATCHDOG_RUNS * 17)
    census = ModelParams(dmax=80, name="census", fuse_columns=False)
    m = disparity_machine(census, word_bits=10)
    q = census.column(AbovePrior).table(10)
    assert m.prior == "neighbour" and m.columns == 4
    assert m.feedback_words == tuple(int(v) for v in q.values[: q.last_change() + 1])
    assert m.feedback_nomatch_word == q.nomatch[0] == 641
    # The clamped table gives every |d - d_n| the full table's word.
    for k in range(81):
        assert m.feedback_words[min(k, len(m.feedback_words) - 1)] == q.values[k]
    # Loading stays hidden at counter max 16: no run is shorter than n_max + 1 = 17 cycles.
    assert (m.words_per_beat, m.words_per_pixel, m.beats_per_pixel) == (30, 410, 14)
    assert m.beats_per_pixel <= 17 - 1
    # A different word width gives its own table; contradicting fields are refused.
    assert disparity_machine(census, word_bits=8).feedback_words != m.feedback_words
    with pytest.raises(ParameterError, match="^prior: .*'neighbour'"):
        disparity_machine(census, prior="loaded")
    with pytest.raises(ParameterError, match="^columns: "):
        disparity_machine(census, columns=3)
    with pytest.raises(ParameterError, match="^feedback_words: "):
        disparity_machine(census, feedback_words=(1024, 3))
    with pytest.raises(ParameterError, match="^prior: 'neighbour'"):
        disparity_machine(no_prior, prior="neighbour")
    with pytest.raises(ParameterError, match="^prior: 'neighbour'"):
        disparity_machine(paper, prior="neighbour")
    assert disparity_machine(census, prior="neighbour", words_per_beat=7).words_per_beat == 7


# --- Census codes ---

@pytest.mark.parametrize("window", [5, 7])
@pytest.mark.parametrize("seed", [0, 1])
def test_census_codes_equal_plain(window, seed):
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (15, 19), dtype=np.uint8)
    img[4:9, 3:10] = 77  # flat patch: equal neighbours give 0 bits
    img[0, :] = 255  # a bright border row (the 7x7 windows of the grid's first row reach it)
    codes = census_codes(img, window)
    k = window // 2  # the map grid's margin: every window inside the image
    assert codes.dtype == np.uint64 and codes.shape == (15 - 2 * k, 19 - 2 * k)
    np.testing.assert_array_equal(codes, census_codes_plain(img, window))
    bits = window * window - 1
    assert int(codes.max()) < (1 << bits) and int(codes.max()).bit_length() == bits


def test_census_bit_order_is_raster():
    offs = census_offsets(7)
    assert len(offs) == 48 and offs[0] == (-3, -3) and offs[23] == (0, -1) and offs[24] == (0, 1)
    img = np.full((9, 9), 100, np.uint8)
    img[4 - 3, 4 - 3] = 10  # darker top-left neighbour of map pixel (2, 2): bit 0
    img[4, 5] = 10  # darker right neighbour: bit 24
    assert int(census_codes(img, 7)[1, 1]) == (1 << 0) | (1 << 24)  # map grid of margin 3
    # The grid keeps every 7x7 window inside the image: a 7x7 image has one code, all 48 bits read.
    dark = np.full((7, 7), 50, np.uint8)
    dark[3, 3] = 200
    dark[0, 0] = 255  # not darker: bit 0 clear
    codes = census_codes(dark, 7)
    assert codes.shape == (1, 1) and int(codes[0, 0]) == ((1 << 48) - 1) & ~1
    # The features of a 7x7-census model share that grid: the 5x5 sums around the same centres.
    img2 = np.random.default_rng(5).integers(0, 256, (12, 14), dtype=np.uint8)
    census = ModelParams(dmax=2, name="census")
    f7, f5 = model_planes(img2, census), feature_sums(img2)
    assert census.margin == 3 and f7.census.shape == f7.m25.shape == (6, 8)
    np.testing.assert_array_equal(f7.m25, f5.m25[1:-1, 1:-1])
    np.testing.assert_array_equal(f7.gv20, f5.gv20[1:-1, 1:-1])
    assert ModelParams(dmax=2, name="census", census_window=5).margin == ModelParams(name="paper").margin == 2


def test_hamming_equals_plain():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 1 << 48, (7, 5), dtype=np.uint64)
    b = rng.integers(0, 1 << 48, (7, 5), dtype=np.uint64)
    np.testing.assert_array_equal(hamming(a, b), hamming_plain(a, b))
    assert hamming(np.uint64((1 << 48) - 1), np.uint64(0)) == 48


# --- Words ---

def _pair(dmax: int, window: int = 7, seed: int = 5, **kw):
    left, right, _ = random_dot_stereogram(height=18, width=34 + dmax, background=3, square=7, seed=seed)
    left = left.copy()
    left[4:10, 20:28] = 128  # flat: no-match and tie pixels
    right = right.copy()
    right[4:10, 16:24] = 128
    model = ModelParams(**{"dmax": dmax, "name": "census", "census_window": window, **kw})
    return model_planes(left, model), model_planes(right, model), model


@pytest.mark.parametrize("window", [5, 7])
def test_census_words_equal_plain_formula(window):
    fl, fr, model = _pair(6, window, neighbour_prior=False, fuse_columns=False)
    machine = MachineParams.for_disparity(6, columns=4)
    words = memory_words(fl, fr, model, machine)
    np.testing.assert_array_equal(words, memory_words_plain(fl, fr, model, machine))
    assert words.shape[1:] == (8, 4)
    h, sigma = model.census_nomatch_h, model.census_sigma
    h_nm_word = quantize(0.02 + 0.98 * math.exp(-(h**2) / (2 * sigma**2)), 10)
    assert (words[:, 7, 1:3] == 1024).all() and (words[:, 7, 3] == h_nm_word).all()
    # The census column varies (it is not a column of ones).
    assert len(np.unique(words[:, :7, 3])) > 5
    # Row chunks equal the whole.
    part = memory_words(fl, fr, model, machine, rows=slice(3, 6))
    wo = words.shape[0] // fl.shape[0]
    np.testing.assert_array_equal(part, words[3 * wo : 6 * wo])


def test_words_with_the_neighbour_prior():
    fl, fr, model = _pair(6, fuse_columns=False)
    machine = disparity_machine(model)
    with pytest.raises(ParameterError, match="^above: .*map row above, one map row at a time"):
        memory_words(fl, fr, model, machine, rows=slice(2, 3))  # the above MAPs: the machine's results
    with pytest.raises(ParameterError, match="^above: "):
        memory_words(fl, fr, model, machine, above=np.full(fl.shape[1] - 6, -1))  # all rows: not one
    wo = fl.shape[1] - 6
    rng = np.random.default_rng(0)
    above = rng.integers(-1, 7, wo)
    words = memory_words(fl, fr, model, machine, rows=slice(2, 3), above=above)
    assert words.shape == (wo, 8, machine.loaded_columns) == (wo, 8, 5)  # the feedback column is not loaded
    want = neighbour_words(model.column(AbovePrior).table(10), 6, above)
    np.testing.assert_array_equal(words[:, :, 0], want)
    no_prior = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    plain = memory_words(fl, fr, no_prior, disparity_machine(no_prior), rows=slice(2, 3))
    np.testing.assert_array_equal(words[:, :, 1:], plain)


def test_machine_checks_are_one_function():
    census = ModelParams(dmax=6, name="census", fuse_columns=False)
    no_prior = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    with pytest.raises(ParameterError, match="^columns: .*4 data columns"):
        check_disparity_machine(no_prior, MachineParams.for_disparity(6))
    with pytest.raises(ParameterError, match="^rows: .*for_disparity"):
        check_disparity_machine(no_prior, MachineParams.for_disparity(7, columns=4))
    with pytest.raises(ParameterError, match="^neighbour_prior .*prior='neighbour'.*disparity_machine"):
        check_disparity_machine(census, MachineParams.for_disparity(6, columns=4))
    with pytest.raises(ParameterError, match="^neighbour_prior .*prior='neighbour'"):
        check_disparity_machine(census, MachineParams.for_disparity(6, columns=4, prior="loaded"))
    # A neighbour machine with another table (another model's eps) is refused: its feedback would
    # not be the model's prior.
    other = disparity_machine(ModelParams(dmax=6, name="census", fuse_columns=False, prior_eps=0.2))
    with pytest.raises(ParameterError, match="^neighbour_prior: .*feedback table"):
        check_disparity_machine(census, other)
    # A neighbour machine with a model without the prior.
    with pytest.raises(ParameterError, match="^prior: .*with neighbour_prior off has none"):
        check_disparity_machine(no_prior, disparity_machine(census))
    with pytest.raises(ParameterError, match="^p_nm0: .*quantizes to 0"):
        check_disparity_machine(ModelParams(name="paper", dmax=6, p_nm0=1e-4),
                                MachineParams.for_disparity(6, word_bits=4))
    with pytest.raises(ParameterError, match="^census_nomatch_h = 48: .*quantizes to 0"):
        far = ModelParams(dmax=6, name="census", fuse_columns=False, census_nomatch_h=48,
                          neighbour_prior=False, p_nm0=0.5)
        check_disparity_machine(far, MachineParams.for_disparity(6, columns=4, word_bits=4))
    with pytest.raises(ParameterError, match="^prior_nomatch = 0.0001 quantizes to 0"):
        disparity_machine(ModelParams(dmax=6, name="census", fuse_columns=False, prior_nomatch=1e-4))
    assert check_disparity_machine(census, disparity_machine(census)) == 2
    assert check_disparity_machine(no_prior, MachineParams.for_disparity(6, columns=4, prior="loaded")) == 1
    fl, fr, _ = _pair(6)
    with pytest.raises(ParameterError, match="census column needs the census"):
        bare = Planes({name: fl[name] for name in ("m25", "gh20", "gv20")})  # no census codes
        memory_words(bare, fr, no_prior, MachineParams.for_disparity(6, columns=4))


def test_front_end_takes_the_census_model_on_whole_rows_per_lane():
    from bayesmachine.hdl.frontend.words import check_frontend_params

    model = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    check_frontend_params(MachineParams.for_disparity(6, columns=4, words_per_beat=8),
                          model)  # 2 rows per beat
    with pytest.raises(ParameterError, match=r"words_per_beat \(6\) must be a multiple of the loaded"):
        check_frontend_params(MachineParams.for_disparity(6, columns=4, words_per_beat=6), model)


# --- References ---

@pytest.mark.parametrize("kw", [
    {},
    {"census_window": 5},
    {"neighbour_prior": False},
    {"prior_eps": 0.2, "prior_s": 1.5, "prior_nomatch": 0.3},
    {"census_nomatch_h": 0},
])
def test_reference_equals_plain_raster_prior(kw):
    fl, fr, model = _pair(8, **kw)
    fast = reference_fast(fl, fr, model)
    plain = reference_prior_plain(fl, fr, model)
    np.testing.assert_array_equal(fast.map, plain.map)
    np.testing.assert_allclose(fast.posterior, plain.posterior, rtol=1e-13, atol=1e-300)
    assert (fast.map < 0).any() and (fast.map >= 0).any()
    # Band by band (the last MAP row carried into the next band) gives the same MAP.
    for rows in (1, 4):
        np.testing.assert_array_equal(reference_map(fl, fr, model, band_rows=rows), fast.map)


def test_prior_changes_the_map_and_needs_the_row_above():
    fl, fr, model = _pair(8)
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
    fl, fr, model = _pair(8, **kw)
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
    fl, fr, _ = _pair(8)
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


# --- The machine on the census model ---

def test_machine_runs_the_census_model_without_the_prior():
    from bayesmachine.host.run import run_pair

    left, right, gt = random_dot_stereogram(height=30, width=70, background=3, square=9, seed=4)
    model = ModelParams(dmax=10, name="census", fuse_columns=False, neighbour_prior=False)
    machine = MachineParams.for_disparity(10, columns=4, rng="sobol", counter_max=16)
    out = run_pair(left, right, model, machine, engine="model", gt=gt, sgbm=False)
    assert set(out.prepared.planes[0]) == {"m25", "gh20", "gv20", "census"}  # prepare(): the model's planes
    assert out.metrics.map_agreement > 0.9
    assert out.metrics.bad["machine"]["bad2"] < 0.1
    # With the neighbour prior the machine needs its neighbour prior (its feedback column, and the
    # above column from its own results): refused, never run with a silently uniform prior.
    with pytest.raises(ParameterError, match="^neighbour_prior"):
        run_pair(left, right, ModelParams(dmax=10, name="census", fuse_columns=False), machine)
    loaded = MachineParams.for_disparity(10, columns=4, prior="loaded")
    with pytest.raises(ParameterError, match="^neighbour_prior"):
        run_pair(left, right, ModelParams(dmax=10, name="census", fuse_columns=False), loaded)
