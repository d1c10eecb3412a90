"""The fused column (bayesmachine.columns.fused): its words by the rule of docs/architecture.md ("The
fused column") against a plain oracle (each member's likelihood by its plain cost and formula, coded,
summed, the pixel's smallest sum subtracted, the exp table), its float64 reference against the
per-column model's, the machine on its words (model engine, pysim), and the kind's checks."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.columns import (
    Census,
    Fused,
    GradH,
    GradMag,
    GradV,
    LeftPrior,
    Mean,
    energy_codes,
    exp_table,
    fused,
)
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair, random_dot_stereogram
from bayesmachine.host.likelihoods import likelihoods_plain, memory_words, pass_context, pass_grid, pass_words
from bayesmachine.host.reference import declared_maps, reference_fast, reference_quantized
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.modeldef import ModelDef
from bayesmachine.models import MODELS, ModelParams, disparity_machine, pass_machine, register_model
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion


@pytest.fixture(scope="module")
def pair():
    return random_dot_stereogram(height=20, width=48, background=2, square=7, seed=3)


def _planes(pair, model):
    left, right, _ = pair
    return model_planes(left, model), model_planes(right, model)


def _oracle(lik: np.ndarray, nm: np.ndarray, entries: list[float], word_bits: int) -> np.ndarray:
    """The rule in plain NumPy: codes of each member's likelihood summed per row, the no-match row the
    rule's code plus the other members' no-match codes, the pixel's smallest subtracted, X read."""
    s = energy_codes(lik).astype(np.int64).sum(axis=-1)  # (Ho, Wo, Dmax+1)
    s_nm = energy_codes(nm).astype(np.int64) + sum(int(energy_codes(e)) for e in entries)
    low = np.minimum(s.min(axis=-1), s_nm)
    x = exp_table(word_bits).astype(np.int64)
    words = x[np.minimum(np.concatenate([s, s_nm[..., None]], axis=-1) - low[..., None], x.size - 1)]
    return words.reshape(-1, s.shape[-1] + 1)


@pytest.mark.parametrize("word_bits", [10, 8])
def test_words_are_the_rule(pair, word_bits: int) -> None:
    model = ModelParams(name="census", dmax=6, neighbour_prior=False, fuse_columns=True)
    assert [isinstance(c, Fused) for c in model.columns] == [True]
    left, right = _planes(pair, model)
    machine = disparity_machine(model, word_bits=word_bits, counter_max=4)
    assert machine.loaded_columns == 1
    words = memory_words(left, right, model, machine)[..., 0].astype(np.int64)
    lik, nm = likelihoods_plain(left, right, model)
    census = model.column(Fused).members[-1]
    assert isinstance(census, Census)
    np.testing.assert_array_equal(words, _oracle(lik, nm, [census.nomatch_values()[0]], word_bits))
    # The best row of every pixel reads 2^W: it fires every cycle.
    assert (words.max(axis=1) == 1 << word_bits).all()


def test_right_pass_words_zero_without_a_match_pixel(pair) -> None:
    model = ModelParams(name="census-lr", dmax=6, fuse_columns=True)
    left, right = _planes(pair, model)
    right_pass = model.pass_named("right")
    machine = pass_machine(model, disparity_machine(model, counter_max=4), "right")
    grid = pass_grid(right_pass, OutputRegion.of_features(left.shape, model.dmax))
    words = pass_words(right_pass, left, right, machine, rows=slice(0, 1), above=np.full(grid.width, -1))
    fused_words = words[..., -1].astype(np.int64)  # the right pass: left prior fed back, above, fused
    # Right image as reference: the last columns see fewer match pixels; their missing lanes read 0, the
    # best of the others (or the no-match row) 2^W.
    assert grid.valid is not None and not grid.valid.all()
    assert (fused_words[:, :-1][~grid.valid] == 0).all()
    assert (fused_words.max(axis=1) == 1 << machine.word_bits).all()


def test_float_reference_is_the_per_column_posterior(pair) -> None:
    """The float64 reference of the fused model is the per-column model's (the members' product): what
    the words approximate."""
    a = ModelParams(name="census", dmax=6, fuse_columns=True)
    b = ModelParams(name="census", dmax=6, fuse_columns=False)
    assert [c.name for c in b.columns] == ["left-prior", "above-prior", "m", "gh", "gv", "census"]
    ra = reference_fast(*_planes(pair, a), a)
    rb = reference_fast(*_planes(pair, b), b)
    np.testing.assert_array_equal(ra.map, rb.map)
    np.testing.assert_allclose(ra.posterior, rb.posterior, rtol=1e-12, atol=1e-300)


def test_float_words_are_the_members_product(pair) -> None:
    """With no word width its words are float64 factors: the members' product, the no-match row the
    rule's floor times the other members' no-match entries (as the per-column machine's columns)."""
    model = ModelParams(name="census", dmax=6, neighbour_prior=False, fuse_columns=True)
    per_column = ModelParams(name="census", dmax=6, neighbour_prior=False, fuse_columns=False)
    left, right = _planes(pair, model)
    got = model.column(Fused).words(pass_context(model.passes[-1], left, right, None))
    ctx = pass_context(per_column.passes[-1], left, right, None)
    parts = [c.words(ctx) for c in per_column.columns]
    parts[0][:, -1] = per_column.nomatch.floor(ctx)  # the rule in the first column's no-match row
    np.testing.assert_allclose(got, np.prod(parts, axis=0), rtol=1e-12)


def test_fused_halves_the_operators() -> None:
    fused_m = disparity_machine(ModelParams(name="census", fuse_columns=True))
    per_column = disparity_machine(ModelParams(name="census", fuse_columns=False))
    assert (fused_m.operator_columns, per_column.operator_columns) == (3, 6)
    assert fused_m.operators == 3 * fused_m.rows


def test_model_engine_and_pysim_agree_on_fused_words() -> None:
    left, right, gt = random_dot_stereogram(height=12, width=24, background=1, square=3, seed=11)
    model = ModelParams(name="census", dmax=4, neighbour_prior=False, fuse_columns=True)
    prep = prepare(left, right, model, gt)
    machine = disparity_machine(prep.model, counter_max=2, word_bits=8, words_per_beat=6)
    a = run_machine(prep, machine, "model", progress=False)
    b = run_machine(prep, machine, "pysim", progress=False)
    for name in ("map", "counts", "cycles", "timeout", "nomatch"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_fused_kind_is_one_per_member_list_and_checks_its_members() -> None:
    assert fused(Mean, GradH, GradV, Census) is fused(Mean, GradH, GradV, Census)
    assert fused(Mean, GradH) is not fused(Mean, GradH, GradV)
    with pytest.raises(TypeError, match="member 1 = .* is not a FEATURES column kind"):
        fused(Mean, LeftPrior)
    with pytest.raises(ValueError, match="needs members"):
        fused()
    with pytest.raises(ValueError, match="member m is listed twice"):
        fused(Mean, Mean)


def test_a_fused_column_takes_every_features_column_of_its_pass() -> None:
    with pytest.raises(ValueError, match="a fused column beside other FEATURES columns"):
        ModelDef(name="fused-and-census", description="x", columns=(fused(Mean, GradH, GradV), Census))
    with pytest.raises(ValueError, match="column m is listed twice"):
        ModelDef(name="m-twice", description="x", columns=(Mean, GradH, Mean))


# --- The models: census and census-lr fused by default, per column with fuse_columns off ---

def test_defaults_and_the_per_column_option() -> None:
    assert [c.name for c in ModelParams(name="census-lr").columns] == [
        "left-prior", "above-prior", "fused", "lr"]
    assert [c.name for c in ModelParams(name="census-lr").pass_named("right").columns] == [
        "left-prior", "above-prior", "fused"]
    assert [c.name for c in ModelParams(name="census-lr", fuse_columns=False).columns] == [
        "left-prior", "above-prior", "m", "gh", "gv", "census", "lr"]
    assert [c.name for c in ModelParams(name="census").columns] == ["left-prior", "above-prior", "fused"]
    assert [c.name for c in ModelParams(name="census", fuse_columns=False).columns] == [
        "left-prior", "above-prior", "m", "gh", "gv", "census"]
    assert ModelParams(name="census-lr").to_dict()["fuse_columns"] is True
    assert ModelParams(name="census").to_dict()["fuse_columns"] is True
    assert "fuse_columns" not in ModelParams(name="paper").to_dict()
    with pytest.raises(ParameterError, match="fuse_columns"):
        ModelParams(name="paper", fuse_columns=True)


def _crop() -> tuple[np.ndarray, ...]:
    left, right, gt = bundled_pair()
    return tuple(np.ascontiguousarray(a[200:224, 300:420]) for a in (left, right, gt))


@pytest.mark.parametrize(("keywords", "left", "right", "nomatch", "timeouts"), [
    ({}, 35483, 39033, 105, 15),
    ({"fuse_columns": False}, 46225, 47462, 105, 37),
    # No no-match row in the left pass: the fused column's minimum leaves it out (else a pixel whose
    # best row is the no-match row would have every word 0 after the consistency column).
    ({"lr_nomatch": False}, 34537, 39033, 0, 9),
])
def test_census_lr_on_a_crop(keywords: dict, left: int, right: int, nomatch: int, timeouts: int) -> None:
    """Measured: the bundled pair's rows 200..223, columns 300..419, Dmax 64 (the default's cycles)."""
    model = ModelParams(name="census-lr", dmax=64, **keywords)
    left_image, right_image, gt = _crop()
    prep = prepare(left_image, right_image, model, gt)
    run = run_machine(prep, disparity_machine(model), progress=False)
    assert (int(run.cycles.sum()), int(run.passes["right"].cycles.sum())) == (left, right)
    assert (int(run.nomatch.sum()), int(run.timeout.sum())) == (nomatch, timeouts)


def test_no_match_row_that_cannot_win_reads_zero(pair) -> None:
    model = ModelParams(name="census-lr", dmax=6, lr_nomatch=False)
    left, right = _planes(pair, model)
    q = reference_quantized(left, right, model, 8, results={"right": declared_maps(model, left, right, 8)[
        "right"]})
    assert np.isfinite(q.posterior).all() and (q.map >= 0).all()


# --- What the work costs on chip: operators (synth); operator samples: tests/host/test_records.py ---

def test_synth_counts_every_machines_operators() -> None:
    from bayesmachine.fpga.synth import design_operators
    from bayesmachine.hdl.frontend.stereo import stereo_machine_params

    fused_model, per_column = ModelParams(name="census-lr"), ModelParams(name="census-lr", fuse_columns=False)
    a, b = stereo_machine_params(80, model=fused_model), stereo_machine_params(80, model=per_column)
    assert design_operators(a, fused_model, 1, stereo=True) == 82 * 4 + 82 * 3
    assert design_operators(b, per_column, 1, stereo=True) == 82 * 7 + 82 * 6
    assert design_operators(b, per_column, 1, stereo=False) == 82 * 7
    paper = ModelParams(name="paper")
    assert design_operators(stereo_machine_params(80, model=paper), paper, 4, stereo=True) == 4 * 82 * 3


@pytest.fixture
def five_fused():
    """A model of one's own: census's image columns and the gradient magnitude, fused (five members)."""
    definition = register_model(ModelDef(
        name="fused-five", description="five image columns fused",
        columns=(fused(Mean, GradH, GradV, Census, GradMag),), defaults={"census_window": 5}))
    yield ModelParams(name=definition.name, dmax=5)
    MODELS.pop(definition.name, None)


def test_a_fused_column_of_ones_own_members(pair, five_fused) -> None:
    model = five_fused
    left, right = _planes(pair, model)
    machine = disparity_machine(model, counter_max=4)
    assert machine.columns == 1
    words = memory_words(left, right, model, machine)[..., 0].astype(np.int64)
    lik, nm = likelihoods_plain(left, right, model)
    assert lik.shape[-1] == 5
    census = model.column(Fused).members[3]
    np.testing.assert_array_equal(words, _oracle(lik, nm, [census.nomatch_values()[0]], 10))
