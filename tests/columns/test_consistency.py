"""The left-right consistency column (bayesmachine/columns/consistency.py) of the census-lr model: its
options, its words from the right pass's MAPs, the right and left passes' references against the
formulas (its per-column machine, --no-fuse-columns; the fused column: columns/test_fused.py). The
passes run on the host: host/test_passes.py; on the command line: cli/test_passes.py.

Oracles are independent constructions: per-pixel Python loops over ``likelihood_formula`` (float)
and over Python integers (words), the consistency column built lane by lane from its definition.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.columns import (
    SCALES,
    Consistency,
    GradH,
    GradV,
    Mean,
    Option,
    consistency,
    likelihood_formula,
    lr_consistent,
    lr_unknown,
    quantize,
)
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import pass_grid, pass_words
from bayesmachine.host.reference import declared_maps, reference_map, reference_quantized_map
from bayesmachine.models import (
    ModelDef,
    ModelParams,
    PassDef,
    disparity_machine,
    pass_machine,
    register_model,
)
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion

DMAX = 6


def right_machine(model, machine):
    return pass_machine(model, machine, "right")


def right_columns(model, region):
    """The right pass's map columns: every right column an output pixel reads."""
    return pass_grid(model.pass_named("right"), region).columns


def right_reference_map(fl, fr, model, word_bits=None, band_rows=None):
    return declared_maps(model, fl, fr, word_bits, band_rows)["right"]


def lr_pair():
    """A small random-dot pair with a flat patch (the tests of census-lr's passes share it)."""
    left, right, gt = random_dot_stereogram(height=14, width=34, background=2, square=8, seed=5)
    left = left.copy()
    left[4:8, 12:20] = 120  # a flat patch: left-right inconsistencies and no-match calls
    return left, right, gt


def lr_model():
    """census-lr with its per-column machine (--no-fuse-columns)."""
    return ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False)


# Module-scoped fixtures (the census-lr tests of columns/, host/ and cli/ share them).
pair = pytest.fixture(lr_pair, scope="module", name="pair")
model = pytest.fixture(lr_model, scope="module", name="model")


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"lr_beta": 0.0}, ParameterError, "lr_beta must be > 0"),
        ({"lr_beta": 1.5}, ParameterError, "lr_beta must be a probability"),
        ({"lr_gamma": -0.1}, ParameterError, "lr_gamma must be a probability"),
        ({"lr_gamma": float("nan")}, ParameterError, "lr_gamma"),
        ({"lr_tolerance": -1}, ParameterError, "lr_tolerance must be an integer"),
        ({"lr_tolerance": 1.5}, TypeError, "lr_tolerance"),
        ({"lr_nomatch": 1}, TypeError, "lr_nomatch must be True or False"),
        ({"lr_neutral": "yes"}, TypeError, "lr_neutral must be True or False"),
        ({"neighbour_prior": False}, ParameterError, "neighbour_prior must be on for the census-lr model"),
        ({"lr_right_max_cycles": 1}, ParameterError, "lr_right_max_cycles must be an integer"),
        ({"lr_right_max_cycles": 2.5}, TypeError, "lr_right_max_cycles"),
    ],
)
def test_bad_parameters_are_refused_up_front(kwargs, error, message):
    with pytest.raises(error, match="^" + message) as err:
        ModelParams(name="census-lr", **kwargs)
    assert error is TypeError or err.value.parameter == next(iter(kwargs))


def test_the_kind_of_a_pass_is_made_by_name():
    """``consistency(pass)``: one kind per pass and name, reading that pass; the column owns no option of the
    pass it reads (census-lr's right pass declares its own)."""
    kind = consistency("mirror")
    assert kind is consistency("mirror") and kind is not consistency("mirror", name="lr2")
    assert issubclass(kind, Consistency) and kind.feeds_from == "mirror" and kind.name == "lr"
    assert consistency("mirror", name="lr2").name == "lr2"
    assert not any(o.name.startswith("lr_right") for o in kind.options)
    lr = ModelParams(name="census-lr", dmax=4)
    assert lr.column(Consistency).feeds_from == "right" and lr.lr_right_nomatch is True
    with pytest.raises(TypeError, match="^consistency: pass_name must be a string, not int"):
        consistency(3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^consistency: name must not be empty"):
        consistency("mirror", name="")


def test_a_pass_declares_its_own_options():
    """A PassDef's ``options``: options of the model, named by its nomatch_option; each an Option, and
    one owner per name; the consistency base kind reads no pass."""
    own = Option("mirror_nomatch", "bool", True, lambda n, v, vs: None, "the mirror pass's no-match row")
    d = ModelDef(name="own-options", description="a pass with an option of its own",
                 columns=(Mean, GradH, GradV, consistency("mirror")),
                 passes=(PassDef(name="mirror", model="census", reference="right", machine_index=1,
                                 options=(own,), nomatch_option="mirror_nomatch"),))
    assert d.options["mirror_nomatch"] is own
    with pytest.raises(TypeError, match="^model 'bad': pass mirror: options must be a tuple of Options"):
        ModelDef(name="bad", description="x", columns=(Mean, consistency("mirror")),
                 passes=(PassDef(name="mirror", model="census", reference="right", machine_index=1,
                                 options=("mirror_nomatch",)),))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^model 'bad': option lr_beta is declared twice"):
        ModelDef(name="bad", description="x", columns=(Mean, consistency("mirror")),
                 passes=(PassDef(name="mirror", model="census", reference="right", machine_index=1,
                                 options=(Option("lr_beta", "float", 0.5, lambda n, v, vs: None, "x"),)),))
    with pytest.raises(ValueError, match="^model 'bad': column lr reads no pass"):
        ModelDef(name="bad", description="x", columns=(Mean, Consistency))


def test_a_pass_option_set_by_the_model():
    """PassDef ``sets``: census-sgm's lr_right_sgm_paths gives its right pass's sgm_paths (1 by default:
    the left path alone, temperature 1), whatever the own pass's; names are checked."""
    default = ModelParams(name="census-sgm", dmax=4)
    right = default.pass_named("right").model
    assert right.sgm_paths == 1 and right.sgm_temperature == 1.0 and default.sgm_paths == 2
    assert right.columns[-1].paths == ("left",)
    two = ModelParams(name="census-sgm", dmax=4, lr_right_sgm_paths=2, sgm_paths=4, sgm_p1=0.5)
    right = two.pass_named("right").model
    assert (right.sgm_paths, right.sgm_temperature, right.sgm_p1) == (2, 0.5, 0.5)  # p1 inherited
    with pytest.raises(ParameterError, match="^lr_right_sgm_paths must be an integer in \\[1, 4\\], got 5"):
        ModelParams(name="census-sgm", lr_right_sgm_paths=5)
    columns = (Mean, consistency("mirror"))
    with pytest.raises(ValueError, match="^model 'bad': pass mirror: sets sgm_paths from 'nope', not an "):
        ModelDef(name="bad", description="x", columns=columns,
                 passes=(PassDef(name="mirror", model="census-sg", reference="right", machine_index=1,
                                 sets=(("sgm_paths", "nope"),)),))
    with pytest.raises(TypeError, match="^model 'bad': pass mirror: sets takes \\(option, option\\) pairs"):
        ModelDef(name="bad", description="x", columns=columns,
                 passes=(PassDef(name="mirror", model="census-sg", reference="right", machine_index=1,
                                 sets=("sgm_paths",)),))  # type: ignore[arg-type]
    own = Option("mirror_paths", "int", 1, lambda n, v, vs: None, "x")
    bad = ModelDef(name="sets-unknown", description="x", columns=columns,
                   passes=(PassDef(name="mirror", model="census", reference="right", machine_index=1,
                                   options=(own,), sets=(("sgm_paths", "mirror_paths"),)),))
    with pytest.raises(ValueError, match="^model 'sets-unknown': pass 'mirror' sets 'sgm_paths', not an "
                       "option of model 'census'"):
        register_model(bad)


def test_beta_that_quantizes_to_zero_is_refused():
    model = ModelParams(dmax=4, name="census-lr", fuse_columns=False, lr_beta=1e-4)
    with pytest.raises(ParameterError, match="^lr_beta = 0.0001 quantizes to 0"):
        disparity_machine(model)


def test_consistency_column_against_its_definition():
    rng = np.random.default_rng(1)
    dmax, tol, first = 7, 1, 3
    columns = np.arange(12, 30)
    wr = 40
    hat = rng.integers(-1, dmax + 1, size=wr).astype(np.int16)
    for lr_nomatch, neutral in ((True, False), (False, False), (True, True), (False, True)):
        model = ModelParams(dmax=dmax, name="census-lr", fuse_columns=False, lr_tolerance=tol,
                            lr_nomatch=lr_nomatch, lr_neutral=neutral)
        column = model.column(Consistency)
        got = column.loaded(column.table(10), hat, first, columns)
        assert got.dtype == np.uint16 and got.shape == (columns.size, dmax + 2)
        for i, x in enumerate(columns):
            any_ok = False
            for d in range(dmax + 1):
                j = x - d - first
                ok = 0 <= j < wr and hat[j] >= 0 and abs(int(hat[j]) - d) <= tol
                unknown = 0 <= j < wr and hat[j] < 0  # inside the right columns, no right MAP
                any_ok |= ok
                one = ok or (neutral and unknown)
                assert got[i, d] == (1024 if one else int(quantize(0.1, 10))), (x, d)
            nm = (int(quantize(0.01, 10)) if any_ok else 1024) if lr_nomatch else 0
            assert got[i, dmax + 1] == nm
        floats = column.loaded(column.table(), hat, first, columns)
        assert floats.dtype == np.float64 and set(np.unique(floats[:, :-1])) <= {0.1, 1.0}
        np.testing.assert_array_equal(floats == 1.0, got == 1024)
        if neutral:
            with pytest.raises(ValueError, match="lr_neutral: the consistency column needs the unknown"):
                column.values_of(column.table(), lr_consistent(hat, first, columns, dmax, tol))
    # A right MAP column past the right pass's columns (or before them) counts as no right MAP, and is
    # not unknown (a neutral lane needs a right pixel without a MAP).
    c = lr_consistent(np.zeros(2, np.int16), 10, np.array([10, 11, 12]), 1, 0)
    np.testing.assert_array_equal(c, [[True, False], [True, False], [False, False]])  # x 12, d 0: past
    u = lr_unknown(np.array([-1, 0], np.int16), 10, np.array([10, 11, 12]), 1)
    np.testing.assert_array_equal(u, [[True, False], [False, True], [False, False]])


def _plain_likelihood(model, fa, fb, ca, cb, a, b):
    """The census model's four likelihoods of feature-map pixels a (of image fa) and b (of fb)."""
    out = []
    for f in ("m", "gh", "gv"):
        s = SCALES[f]
        delta = int(getattr(fa, f"{f}{s}")[a]) - int(getattr(fb, f"{f}{s}")[b])
        out.append(float(likelihood_formula(np.int64(delta), s, model.p0, getattr(model, f"sigma_{f}"))))
    h = bin(int(ca[a]) ^ int(cb[b])).count("1")
    out.append(float(likelihood_formula(np.int64(h), 1, model.census_p0, model.census_sigma)))
    return out


@pytest.mark.parametrize("right_nomatch", [True, False])
def test_right_pass_words_against_the_formula(pair, right_nomatch):
    left, right, _ = pair
    model = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_right_nomatch=right_nomatch)
    fl, fr = model_planes(left, model), model_planes(right, model)
    machine = right_machine(model, disparity_machine(model))
    region = OutputRegion.of_features(fl.shape, DMAX)
    xr = right_columns(model, region)
    assert xr[0] == region.map_columns[0] - DMAX and xr[-1] == region.map_columns[-1]
    y = 3
    words = pass_words(model.pass_named("right"), fl, fr, machine, rows=slice(y, y + 1),
                       above=np.full(xr.size, -1, np.int16))
    assert words.shape == (xr.size, DMAX + 2, machine.loaded_columns)
    last = int(region.map_columns[-1])
    for j, x in enumerate(xr):
        for d in range(DMAX + 1):
            if x + d > last:  # the left pixel lies past the last output column: word 0, never fires
                assert not words[j, d, 1:].any()
                continue
            lik = _plain_likelihood(model, fr, fl, fr.census, fl.census, (y, x), (y, x + d))
            np.testing.assert_array_equal(words[j, d, 1:], quantize(np.array(lik), 10))
        if right_nomatch:  # the census model's no-match row of the right pixel: [P_nm(gV), 1, 1, L_c(h_nm)]
            gv = np.int64(fr.gv20[y, x])
            p_nm = likelihood_formula(gv, SCALES["gv"], model.p_nm0, model.sigma_nm)
            h = np.int64(model.census_nomatch_h)
            l_nm = likelihood_formula(h, 1, model.census_p0, model.census_sigma)
            want = [int(quantize(float(p_nm), 10)), 1024, 1024, int(quantize(float(l_nm), 10))]
            np.testing.assert_array_equal(words[j, DMAX + 1, 1:], want)
        else:
            assert not words[j, DMAX + 1, 1:].any()  # no no-match row
    assert (words[:, :, 0] == 1024).all()


def _brute_right_pass(model, fl, fr, word_bits=None):
    """The right pass pixel by pixel: float64 (formula) or exact Python-integer products of words."""
    region = OutputRegion.of_features(fl.shape, model.dmax)
    xr = right_columns(model, region)
    last = int(region.map_columns[-1])
    out = np.full((region.shape[0], xr.size), -1, np.int64)
    one = 1.0 if word_bits is None else 1 << word_bits

    def f(k):
        p = float(likelihood_formula(np.int64(k), 1, model.prior_eps, model.prior_s))
        return p if word_bits is None else int(quantize(p, word_bits))

    def w(p):
        return p if word_bits is None else int(quantize(p, word_bits))

    for y in range(out.shape[0]):
        for j, x in enumerate(xr):
            hats = [h for h in (out[y, j - 1] if j > 0 else -1, out[y - 1, j] if y > 0 else -1) if h >= 0]
            vals = []
            for d in range(model.dmax + 1):
                if x + d > last:
                    vals.append(0)
                    continue
                lik = _plain_likelihood(model, fr, fl, fr.census, fl.census, (y, x), (y, x + d))
                v = one if word_bits is None else 1
                for p in lik:
                    v = v * w(p)
                for h in hats:
                    v = v * f(abs(d - h))
                vals.append(v)
            if model.lr_right_nomatch:
                # The census model's no-match row of the right pixel: [P_nm(gV), 1, 1, L_c(h_nm)], its
                # own no-match prior factor f(s) per matched neighbour.
                gv = np.int64(fr.gv20[y, x])
                nm = w(float(likelihood_formula(gv, SCALES["gv"], model.p_nm0, model.sigma_nm)))
                if word_bits is not None:
                    nm = nm * one * one
                l_nm = likelihood_formula(np.int64(model.census_nomatch_h), 1, model.census_p0,
                                          model.census_sigma)
                nm = nm * w(float(l_nm))
                for _ in hats:
                    nm = nm * w(model.pass_named("right").model.prior_nomatch)
                vals.append(nm)
            best = max(range(len(vals)), key=lambda k: (vals[k], -k))
            out[y, j] = best if best <= model.dmax else -1
    return out


@pytest.mark.parametrize("word_bits", [None, 10])
@pytest.mark.parametrize("right_nomatch", [False, True])
def test_right_pass_reference_against_brute_force(pair, word_bits, right_nomatch):
    left, right, _ = pair
    model = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_right_nomatch=right_nomatch)
    fl, fr = model_planes(left, model), model_planes(right, model)
    got = right_reference_map(fl, fr, model, word_bits, band_rows=4)  # bands carry the row above
    want = _brute_right_pass(model, fl, fr, word_bits)
    np.testing.assert_array_equal(got, want)
    assert (got < 0).any() == right_nomatch  # only a no-match row gives a right pixel no MAP


def _brute_left_pass(model, fl, fr, right_map, word_bits=None):
    region = OutputRegion.of_features(fl.shape, model.dmax)
    xr0 = int(right_columns(model, region)[0])
    ho, wo = region.shape
    out = np.full((ho, wo), -1, np.int64)
    wb = word_bits

    def w(p):
        return p if wb is None else int(quantize(p, wb))

    one = 1.0 if wb is None else 1 << wb
    for y in range(ho):
        for i in range(wo):
            x = int(region.map_columns[i])
            hats = [h for h in (out[y, i - 1] if i > 0 else -1, out[y - 1, i] if y > 0 else -1) if h >= 0]
            vals, any_ok = [], False
            for d in range(model.dmax + 1):
                hat = right_map[y, x - d - xr0]
                ok = hat >= 0 and abs(int(hat) - d) <= model.lr_tolerance
                any_ok |= ok
                neutral = model.lr_neutral and hat < 0  # no right MAP: no information, factor 1
                v = one if wb is None else 1
                for p in _plain_likelihood(model, fl, fr, fl.census, fr.census, (y, x), (y, x - d)):
                    v = v * w(p)
                v = v * (one if ok or neutral else w(model.lr_beta))
                for h in hats:
                    k = np.int64(abs(d - h))
                    v = v * w(float(likelihood_formula(k, 1, model.prior_eps, model.prior_s)))
                vals.append(v)
            s = SCALES["gv"]
            nm = w(float(likelihood_formula(np.int64(fl.gv20[y, x]), s, model.p_nm0, model.sigma_nm)))
            if wb is not None:
                nm = nm * one * one
            nm = nm * w(float(likelihood_formula(np.int64(model.census_nomatch_h), 1, model.census_p0,
                                                 model.census_sigma)))
            nm = nm * ((w(model.lr_gamma) if any_ok else one) if model.lr_nomatch else 0)
            for _ in hats:
                nm = nm * w(model.prior_nomatch)
            vals.append(nm)
            best = max(range(len(vals)), key=lambda k: (vals[k], -k))
            out[y, i] = best if best <= model.dmax else -1
    return out


@pytest.mark.parametrize("word_bits", [None, 10])
@pytest.mark.parametrize(("lr_nomatch", "right_nomatch", "neutral"),
                         [(True, False, False), (False, False, False), (True, True, False),
                          (True, True, True)])
def test_left_pass_reference_against_brute_force(pair, word_bits, lr_nomatch, right_nomatch, neutral):
    left, right, _ = pair
    model = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_nomatch=lr_nomatch,
                        lr_right_nomatch=right_nomatch, lr_neutral=neutral)
    fl, fr = model_planes(left, model), model_planes(right, model)
    right_map = _brute_right_pass(model, fl, fr, word_bits)
    want = _brute_left_pass(model, fl, fr, right_map, word_bits)
    if word_bits is None:
        got = reference_map(fl, fr, model, band_rows=3)
    else:
        got = reference_quantized_map(fl, fr, model, word_bits, band_rows=3)
    np.testing.assert_array_equal(got, want)
    if lr_nomatch:
        assert (got < 0).any() and (got >= 0).mean() > 0.5
    else:
        assert (got >= 0).all()  # no no-match row: never no match


def test_neutral_lanes_change_the_left_pass(pair):
    """With the right pass's no-match row, --lr-neutral changes the left MAPs (its lanes reading a right
    no-match get 1, not beta) on this pair: the brute-force test above is not vacuous for it."""
    left, right, _ = pair
    base = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_right_nomatch=True,
                       lr_neutral=False)
    fl, fr = model_planes(left, base), model_planes(right, base)
    neutral = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False, lr_right_nomatch=True,
                          lr_neutral=True)
    assert (reference_map(fl, fr, base) != reference_map(fl, fr, neutral)).any()
    assert (reference_quantized_map(fl, fr, base, 10) != reference_quantized_map(fl, fr, neutral, 10)).any()


def test_the_column_changes_the_census_model(pair, model):
    left, right, _ = pair
    fl, fr = model_planes(left, model), model_planes(right, model)
    census = ModelParams(dmax=DMAX, name="census")
    assert (reference_map(fl, fr, model) != reference_map(fl, fr, census)).any()
