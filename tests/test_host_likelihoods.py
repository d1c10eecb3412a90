"""Model parameters, quantization to memory words, and the likelihood-memory layout."""

import math

import numpy as np
import pytest

from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import (
    ModelParams,
    likelihood_formula,
    likelihood_tables,
    memory_words,
    memory_words_plain,
    quantize,
)
from bayesmachine.params import MachineParams


def test_defaults_are_the_paper_table():
    m = ModelParams()
    assert (m.dmax, m.p0, m.sigma_m, m.sigma_gh, m.sigma_gv, m.p_nm0, m.sigma_nm) == (
        80,
        0.02,
        10,
        10,
        10,
        0.01,
        8,
    )
    assert m.hypotheses == 82


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"p0": 1.5}, "p0"),
        ({"p_nm0": -0.1}, "p_nm0"),
        ({"sigma_m": 0.0}, "sigma_m"),
        ({"sigma_nm": math.inf}, "sigma_nm"),
        ({"dmax": -1}, "dmax"),
        ({"dmax": 2.5}, "dmax"),
    ],
)
def test_bad_model_params_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ModelParams(**kwargs)


def test_likelihood_formula_values():
    # C = (delta / scale)^2; zero cost gives 1, large cost tends to p0.
    assert likelihood_formula(np.array(0), 25, 0.02, 10.0) == 1.0
    d = np.array(25 * 10)  # a mean difference of exactly sigma
    assert likelihood_formula(d, 25, 0.02, 10.0) == pytest.approx(0.02 + 0.98 * math.exp(-0.5))
    assert likelihood_formula(np.array(5100), 20, 0.02, 10.0) == pytest.approx(0.02)


def test_tables_cover_every_difference():
    t = likelihood_tables(ModelParams())
    assert len(t.m) == 25 * 255 + 1 and len(t.gh) == 2 * 10 * 255 + 1 and len(t.nomatch) == 10 * 255 + 1
    assert t.nomatch[0] == 1.0 and t.nomatch[-1] == pytest.approx(0.01)


def test_quantize_edges():
    w = 10
    assert quantize(0.0, w) == 0
    assert quantize(1.0, w) == 1 << w
    # Round half up: exact halves of an LSB go up.
    assert quantize(0.5 / 1024, w) == 1
    assert quantize(1.5 / 1024, w) == 2
    assert quantize(2.5 / 1024, w) == 3
    assert quantize(np.nextafter(0.5, 0) / 1024, w) == 0
    assert quantize(0.02, w) == round(0.02 * 1024)
    assert quantize(np.array([0.25, 0.75]), 1).tolist() == [1, 2]  # 0.5 -> 1, 1.5 -> 2 = 2^W
    assert quantize(np.array([0.0, 1.0]), 15).tolist() == [0, 1 << 15]  # the widest word, 1.0 exact
    with pytest.raises(ValueError, match="word_bits"):
        quantize(0.5, 16)


@pytest.mark.parametrize("bad", [-1e-12, 1 + 1e-12, math.nan, math.inf])
def test_quantize_rejects_out_of_range(bad):
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        quantize(np.array([0.5, bad]), 10)


def _pair(dmax):
    left, right, _ = random_dot_stereogram(height=14, width=40, background=3, square=6, seed=1)
    return feature_sums(left), feature_sums(right), ModelParams(dmax=dmax)


@pytest.mark.parametrize("prior", ["uniform", "loaded"])
def test_words_match_plain_formula_and_layout(prior):
    fl, fr, model = _pair(dmax=9)
    machine = MachineParams.for_disparity(9, word_bits=8, prior=prior, lanes=8)
    words = memory_words(fl, fr, model, machine)
    plain = memory_words_plain(fl, fr, model, machine)
    ho, wo = fl.shape[0], fl.shape[1] - 9
    assert words.shape == (ho * wo, 11, machine.operator_columns) and words.dtype == np.uint16
    np.testing.assert_array_equal(words, plain)
    off = machine.operator_columns - 3
    one = 1 << 8
    # The no-match row: P(nomatch) then 1.0 in the other data columns.
    assert (words[:, 10, off + 1 :] == one).all()
    # Row d, pixel (y, x): the quantized mean likelihood of |m_l(y, x+dmax) - m_r(y, x+dmax-d)|.
    y, x, d = 2, 5, 4
    q_m = quantize(likelihood_tables(model).m[abs(fl.m25[y, x + 9] - fr.m25[y, x + 9 - d])], 8)
    assert words[y * wo + x, d, off] == q_m
    if off:
        assert (words[:, :, 0] == one).all()


def test_words_by_row_chunks_equal_whole():
    fl, fr, model = _pair(dmax=5)
    machine = MachineParams.for_disparity(5)
    whole = memory_words(fl, fr, model, machine)
    parts = [memory_words(fl, fr, model, machine, rows=slice(y, y + 3)) for y in range(0, fl.shape[0], 3)]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_words_reject_wrong_machine():
    fl, fr, model = _pair(dmax=5)
    with pytest.raises(ValueError, match="for_disparity"):
        memory_words(fl, fr, model, MachineParams.for_disparity(6))

