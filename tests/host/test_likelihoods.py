"""Model parameters, quantization to memory words, the likelihood-memory layout, Hamming distances.

The expected words come from the paper's formulas computed directly in floats on a small
hand-made pair (window means and gradients, exp, exact round-half-up), not from the
lookup tables the code under test uses.
"""

import math
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest

from bayesmachine.cliargs import with_flag
from bayesmachine.columns import GradH, GradV, Mean, likelihood_formula, quantize
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import hamming, hamming_plain, memory_words, memory_words_plain
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError


def test_defaults_are_the_paper_table():
    m = ModelParams(name="paper")
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
        ({"p0": math.nan}, "p0"),
        ({"sigma_gh": 1e-300}, "sigma_gh"),  # 2 sigma^2 underflows to 0: NaN likelihoods
        ({"sigma_gv": 1e200}, "sigma_gv"),  # 2 sigma^2 overflows to inf
        ({"sigma_nm": -3.0}, "sigma_nm"),
    ],
)
def test_bad_model_params_name_the_parameter(kwargs, name):
    with pytest.raises(ParameterError, match=f"^{name}") as err:
        ModelParams(name="paper", **kwargs)
    assert err.value.parameter == name


@pytest.mark.parametrize(("kwargs", "name"), [({"dmax": 2.5}, "dmax"), ({"p_nm0": True}, "p_nm0"),
                                              ({"sigma_m": "10"}, "sigma_m"), ({"name": 3}, "name")])
def test_wrong_types_are_type_errors(kwargs, name):
    with pytest.raises(TypeError, match=f"^{name}"):
        ModelParams(**{"name": "paper", **kwargs})


@pytest.mark.parametrize(
    ("kwargs", "option"),
    [({"sigma_m": 1e-300}, "--sigma-m/--sigma"), ({"p_nm0": 0.0}, "--p-nm0"), ({"p0": 2.0}, "--p0"),
     ({"sigma_nm": 0.0}, "--sigma-nm"), ({"dmax": -2}, "--dmax")],
)
def test_model_errors_speak_of_parameters_and_the_cli_adds_its_flag(kwargs, option):
    with pytest.raises(ParameterError) as err:
        ModelParams(name="paper", **kwargs)
    assert not str(err.value).startswith("--")
    assert str(with_flag(err.value)) == f"{option}: {err.value}"


def test_tiny_and_huge_sigmas_that_fit_float64_give_tables_in_0_1():
    for sigma in (1e-150, 1e150):
        m = ModelParams(name="paper", sigma_m=sigma, sigma_gh=sigma, sigma_gv=sigma, sigma_nm=sigma)
        for term in (*m.columns, m.nomatch):
            tab = term.table().values
            assert np.isfinite(tab).all() and tab.min() >= 0 and tab.max() <= 1


def test_core_model_modules_import_no_host_and_no_amaranth():
    # Every model's tables (the default's first; a semi-global column's are its member's factors').
    code = (
        "import sys, bayesmachine.models as m\n"
        "def kinds(c):\n"
        "    c = getattr(c, 'member', c)\n"
        "    return getattr(c, 'factors', lambda: (c,))()\n"
        "for model in (m.ModelParams(), *(m.ModelParams(name=n) for n in m.model_names())):\n"
        "    [t.table() for p in model.passes for c in (*p.columns, p.model.nomatch) for t in kinds(c)]\n"
        "bad = [m for m in sys.modules if m.startswith(('bayesmachine.host', 'amaranth', 'cv2'))]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_likelihood_formula_values():
    # C = (delta / scale)^2; zero cost gives 1, large cost tends to p0.
    assert likelihood_formula(np.array(0), 25, 0.02, 10.0) == 1.0
    d = np.array(25 * 10)  # a mean difference of exactly sigma
    assert likelihood_formula(d, 25, 0.02, 10.0) == pytest.approx(0.02 + 0.98 * math.exp(-0.5))
    assert likelihood_formula(np.array(5100), 20, 0.02, 10.0) == pytest.approx(0.02)


def test_tables_cover_every_difference():
    model = ModelParams(name="paper")
    m, gh, gv = (model.column(kind).table().values for kind in (Mean, GradH, GradV))
    nomatch = model.nomatch.table().values
    assert len(m) == 25 * 255 + 1 and len(gh) == len(gv) == 2 * 10 * 255 + 1 and len(nomatch) == 10 * 255 + 1
    assert nomatch[0] == 1.0 and nomatch[-1] == pytest.approx(0.01)


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
    return feature_sums(left), feature_sums(right), ModelParams(name="paper", dmax=dmax)


@pytest.mark.parametrize("prior", ["uniform", "loaded"])
def test_words_match_plain_formula_and_layout(prior):
    fl, fr, model = _pair(dmax=9)
    machine = MachineParams.for_disparity(9, word_bits=8, prior=prior, words_per_beat=8)
    words = memory_words(fl, fr, model, machine)
    plain = memory_words_plain(fl, fr, model, machine)
    ho, wo = fl.shape[0], fl.shape[1] - 9
    assert words.shape == (ho * wo, 11, machine.operator_columns) and words.dtype == np.uint16
    np.testing.assert_array_equal(words, plain)
    off = machine.operator_columns - 3
    one = 1 << 8
    # The no-match row: P(nomatch) then 1.0 in the other data columns.
    assert (words[:, 10, off + 1 :] == one).all()
    if off:
        assert (words[:, :, 0] == one).all()


def _round_half_up(p: float, word_bits: int) -> int:
    """q = round(p * 2^W), halves up, in exact rational arithmetic."""
    x = Fraction(p) * (1 << word_bits)
    q = math.floor(x)
    return q + (1 if x - q >= Fraction(1, 2) else 0)


def _features_at(img: np.ndarray, y: int, x: int) -> tuple[float, float, float]:
    """The paper's m, gH, gV of the 5x5 window centred on image pixel (y, x), in floats."""
    w = img[y - 2 : y + 3, x - 2 : x + 3].astype(np.float64)
    mean = float(w.mean())
    g_h = float((w[:, 3:].sum() - w[:, :2].sum()) / 20.0)  # right two columns - left two, per pixel pair
    g_v = float((w[3:, :].sum() - w[:2, :].sum()) / 20.0)  # bottom two rows - top two
    return mean, g_h, g_v


def test_words_equal_the_paper_formula_computed_directly():
    """Eq. 2 and 4 by hand on a 9x17 pair: L = p0 + (1-p0) exp(-(f_l - f_r)^2 / (2 sigma^2))."""
    rng = np.random.default_rng(12)
    left = rng.integers(0, 256, size=(9, 17), dtype=np.uint8)
    right = np.roll(left, -2, axis=1) // 2 + rng.integers(0, 40, size=(9, 17), dtype=np.uint8)
    model = ModelParams(name="paper", dmax=3, p0=0.05, sigma_m=7.0, sigma_gh=9.0, sigma_gv=11.0, p_nm0=0.03,
                        sigma_nm=5.0)
    w = 10
    machine = MachineParams.for_disparity(3, word_bits=w)
    words = memory_words(feature_sums(left), feature_sums(right), model, machine)
    sigmas = (model.sigma_m, model.sigma_gh, model.sigma_gv)
    ho, wo = 9 - 4, 17 - 4 - 3
    assert words.shape == (ho * wo, 5, 3)
    for i in range(ho):
        for j in range(wo):
            y, x = i + 2, j + 3 + 2  # image pixel at the centre of output pixel (i, j)
            f_left = _features_at(left, y, x)
            for d in range(4):
                f_right = _features_at(right, y, x - d)
                for k in range(3):
                    lik = model.p0 + (1 - model.p0) * math.exp(
                        -((f_left[k] - f_right[k]) ** 2) / (2 * sigmas[k] ** 2)
                    )
                    assert words[i * wo + j, d, k] == _round_half_up(lik, w), (i, j, d, k)
            p_nm = model.p_nm0 + (1 - model.p_nm0) * math.exp(-(f_left[2] ** 2) / (2 * model.sigma_nm**2))
            assert words[i * wo + j, 4].tolist() == [_round_half_up(p_nm, w), 1 << w, 1 << w]


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



def test_hamming_equals_plain():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 1 << 48, (7, 5), dtype=np.uint64)
    b = rng.integers(0, 1 << 48, (7, 5), dtype=np.uint64)
    np.testing.assert_array_equal(hamming(a, b), hamming_plain(a, b))
    assert hamming(np.uint64((1 << 48) - 1), np.uint64(0)) == 48
