"""The census column (bayesmachine/columns/census.py): its options, its tables and its words.

Oracles are independent of the code under test: likelihoods from the formula (no tables) and the
words by the plain formula (``memory_words_plain``).
"""

import math

import numpy as np
import pytest

from bayesmachine.cliargs import with_flag
from bayesmachine.columns import AbovePrior, Census, quantize
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import memory_words, memory_words_plain
from bayesmachine.models import ModelParams, machine_layout
from bayesmachine.params import MachineParams, ParameterError


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


def census_pair(dmax: int, window: int = 7, seed: int = 5, **kw):
    left, right, _ = random_dot_stereogram(height=18, width=34 + dmax, background=3, square=7, seed=seed)
    left = left.copy()
    left[4:10, 20:28] = 128  # flat: no-match and tie pixels
    right = right.copy()
    right[4:10, 16:24] = 128
    model = ModelParams(**{"dmax": dmax, "name": "census", "census_window": window, **kw})
    return model_planes(left, model), model_planes(right, model), model


@pytest.mark.parametrize("window", [5, 7])
def test_census_words_equal_plain_formula(window):
    fl, fr, model = census_pair(6, window, neighbour_prior=False, fuse_columns=False)
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
