"""The semi-global column (bayesmachine.columns.semiglobal): the path recursion against a plain Python twin
(saturation included), bands carried, its words, codes and float64 factors by the rule of
docs/architecture.md ("The semi-global column"), the reference's factor, the kind's and the options'
checks, and the machine on its words (model engine and pysim)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayesmachine.columns import SemiGlobal, exp_table, fused, semiglobal
from bayesmachine.columns.energy import INFINITE_CODE
from bayesmachine.columns.features import GradH, GradV, Mean
from bayesmachine.columns.semiglobal import aggregate
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import memory_words, pass_context, pass_grid, pass_words
from bayesmachine.host.reference import pass_reference, reference_fast, reference_quantized
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine, pass_machine
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion

STEPS = {"left": (0, -1), "top": (-1, 0), "top-left": (-1, -1), "top-right": (-1, 1)}


def _twin(e: np.ndarray, paths: int, p1, p2, cap) -> np.ndarray:
    """The rule pixel by pixel in plain Python: each path's costs from q = p - r, the path starting where q
    is outside the grid, saturated at ``cap``, summed over the first ``paths`` paths."""
    rows, w, d1 = e.shape
    total = [[[0] * d1 for _ in range(w)] for _ in range(rows)]
    for name in list(STEPS)[:paths]:
        dy, dx = STEPS[name]
        cost: dict[tuple[int, int], list] = {}
        for y in range(rows):
            for x in range(w):
                here = [e[y, x, d].item() for d in range(d1)]
                qy, qx = y + dy, x + dx
                if 0 <= qy < rows and 0 <= qx < w:
                    q = cost[qy, qx]
                    m = min(q)
                    out = []
                    for d in range(d1):
                        best = min([q[d], m + p2] + [q[k] + p1 for k in (d - 1, d + 1) if 0 <= k < d1])
                        out.append(min(cap, here[d] + best - m))
                else:
                    out = here
                cost[y, x] = out
                for d in range(d1):
                    total[y][x][d] += out[d]
    return np.array(total, dtype=e.dtype)


@pytest.mark.parametrize("paths", [1, 2, 3, 4])
def test_the_recursion_is_the_twins(paths: int) -> None:
    rng = np.random.default_rng(paths)
    e = rng.integers(0, 60, size=(5, 7, 6)).astype(np.int64)
    got, _ = aggregate(e, None, paths, 16, 96, 255)
    np.testing.assert_array_equal(got, _twin(e, paths, 16, 96, 255))


def test_path_costs_saturate() -> None:
    """A small cap binds: every path cost stays at most C, as the twin's."""
    rng = np.random.default_rng(7)
    e = rng.integers(0, 63, size=(4, 6, 5)).astype(np.int64)
    got, state = aggregate(e, None, 4, 5, 40, 63)
    want = _twin(e, 4, 5, 40, 63)
    np.testing.assert_array_equal(got, want)
    assert state.max() <= 63 and got.max() <= 4 * 63
    unsaturated, _ = aggregate(e, None, 4, 5, 40, 1 << 20)
    assert (unsaturated > got).any()  # the cap bound somewhere


def test_float_recursion_is_the_twins() -> None:
    rng = np.random.default_rng(3)
    e = rng.random((4, 5, 6)) * 4
    e[1, 2, 3] = np.inf  # a lane without a match pixel
    got, _ = aggregate(e, None, 4, 1.0, 6.0, np.inf)
    np.testing.assert_allclose(got, _twin(e, 4, 1.0, 6.0, math.inf), rtol=1e-12)


def test_bands_continue_from_the_row_above() -> None:
    rng = np.random.default_rng(5)
    e = rng.integers(0, 60, size=(6, 7, 5)).astype(np.int64)
    whole, _ = aggregate(e, None, 4, 16, 96, 255)
    top, state = aggregate(e[:2], None, 4, 16, 96, 255)
    rest, _ = aggregate(e[2:], state, 4, 16, 96, 255)
    np.testing.assert_array_equal(np.concatenate([top, rest]), whole)


@pytest.fixture(scope="module")
def pair():
    return random_dot_stereogram(height=22, width=44, background=2, square=7, seed=5)


def _model(**kw) -> ModelParams:
    return ModelParams(name="census-sg", dmax=6, neighbour_prior=False, **kw)


def _planes(pair, model):
    left, right, _ = pair
    return model_planes(left, model), model_planes(right, model)


def _tempered(column: SemiGlobal, ctx) -> tuple[np.ndarray, np.ndarray]:
    """T and T_nm by the rule, from the member's sums (the fused column's, tested apart) and the twin."""
    d, d_nm, valid = column.member._relative(ctx)
    cap = column.cap
    e = np.where(valid, np.minimum(d, cap), cap).reshape(ctx.rows, ctx.columns.size, -1)
    p1, p2 = column.penalties
    s = _twin(e, len(column.paths), p1, p2, cap).reshape(d.shape)
    s_nm = len(column.paths) * np.minimum(d_nm, cap)
    low = np.minimum(np.where(valid, s, 1 << 40).min(axis=1), s_nm)
    a = round(256 * column.values["sgm_temperature"])
    return (a * (s - low[:, None]) + 128) >> 8, (a * (s_nm - low) + 128) >> 8


@pytest.mark.parametrize(("keywords", "word_bits"), [({}, 10), ({"sgm_paths": 4, "sgm_temperature": 0.4}, 8),
                                                    ({"sgm_paths": 3}, 10), ({"sgm_paths": 1}, 10)])
def test_words_and_codes_are_the_rule(pair, keywords: dict, word_bits: int) -> None:
    model = _model(**keywords)
    column = model.column(SemiGlobal)
    assert column is not None and [c.name for c in model.columns] == ["semiglobal"]
    left, right = _planes(pair, model)
    ctx = pass_context(model.passes[-1], left, right, word_bits)
    t, t_nm = _tempered(column, ctx)
    x = exp_table(word_bits).astype(np.int64)
    words = memory_words(left, right, model, disparity_machine(model, word_bits=word_bits))[..., 0]
    np.testing.assert_array_equal(words[:, :-1], x[np.minimum(t, x.size - 1)])
    np.testing.assert_array_equal(words[:, -1], x[np.minimum(t_nm, x.size - 1)])
    assert (words.max(axis=1) == 1 << word_bits).all()  # the best row fires every cycle
    log = disparity_machine(model, integrator="log")
    codes = memory_words(left, right, model, log)[..., 0]
    np.testing.assert_array_equal(codes[:, :-1], np.minimum(t, INFINITE_CODE - 1))
    np.testing.assert_array_equal(codes[:, -1], np.minimum(t_nm, INFINITE_CODE - 1))
    assert (codes.min(axis=1) == 0).all()


def test_row_by_row_with_carry_is_the_frame(pair) -> None:
    """One map row per call, the path costs carried, gives the whole frame's words; a band below row 0
    without them is refused, naming carry."""
    model = _model()
    left, right = _planes(pair, model)
    machine = disparity_machine(model)
    whole = memory_words(left, right, model, machine)
    carry: dict = {}
    rows = OutputRegion.of_features(left.shape, model.dmax).shape[0]
    parts = [memory_words(left, right, model, machine, rows=slice(y, y + 1), carry=carry)
             for y in range(rows)]
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    with pytest.raises(ParameterError, match="carry") as err:
        memory_words(left, right, model, machine, rows=slice(3, 4))
    assert err.value.parameter == "carry"
    with pytest.raises(ParameterError, match="carry"):
        memory_words(left, right, model, machine, rows=slice(5, 6), carry=carry)  # not the next band


def test_right_pass_lanes_without_a_match_pixel(pair) -> None:
    model = ModelParams(name="census-sgm", dmax=6)
    left, right = _planes(pair, model)
    p = model.pass_named("right")
    machine = pass_machine(model, disparity_machine(model, counter_max=4), "right")
    grid = pass_grid(p, OutputRegion.of_features(left.shape, model.dmax))
    words = pass_words(p, left, right, machine, rows=slice(0, 1), above=np.full(grid.width, -1), carry={})
    sgm = words[..., -1].astype(np.int64)
    assert grid.valid is not None and (sgm[:, :-1][~grid.valid] == 0).all()
    assert (sgm.max(axis=1) == 1 << machine.word_bits).all()


def test_float_factors_and_the_reference(pair) -> None:
    """Its float64 factors are exp(-t (S - S_min)) of the recursion on the members' energies in nats, and
    the float64 reference is their normalization (the column holds the no-match rule)."""
    model = _model()
    column = model.column(SemiGlobal)
    left, right = _planes(pair, model)
    ctx = pass_context(model.passes[-1], left, right, None)
    f = column.member._factors(ctx)
    energy = -np.log(f)
    low = energy.min(axis=1)
    e = (energy[:, :-1] - low[:, None]).reshape(ctx.rows, ctx.columns.size, -1)
    n = len(column.paths)
    s = _twin(e, n, 1.0, 6.0, math.inf).reshape(energy[:, :-1].shape)
    s_nm = n * (energy[:, -1] - low)
    s_min = np.minimum(s.min(axis=1), s_nm)
    want = np.exp(-(1 / n) * (np.concatenate([s, s_nm[:, None]], axis=1) - s_min[:, None]))
    np.testing.assert_allclose(column.words(ctx), want, rtol=1e-9)
    ref = reference_fast(left, right, model)
    np.testing.assert_allclose(ref.posterior.reshape(want.shape), want / want.sum(axis=1, keepdims=True),
                               rtol=1e-9)
    banded = pass_reference(model.passes[-1], left, right, None, rows=slice(0, 3), carry={})
    np.testing.assert_array_equal(banded.map, ref.map[:3])


def test_quantized_reference_reads_its_words(pair) -> None:
    model = _model()
    left, right = _planes(pair, model)
    machine = disparity_machine(model)
    words = memory_words(left, right, model, machine)[..., 0].astype(np.float64)
    ref = reference_quantized(left, right, model, machine.word_bits)
    np.testing.assert_allclose(ref.posterior.reshape(words.shape), words / words.sum(axis=1, keepdims=True))


@pytest.mark.parametrize("integrator", ["stochastic", "log"])
def test_model_engine_and_pysim_agree(integrator: str) -> None:
    """Both passes of census-sgm on a crop: the model engine and the RTL under pysim, fed the host's words
    (or codes), every result equal."""
    left, right, gt = random_dot_stereogram(height=12, width=24, background=1, square=3, seed=11)
    model = ModelParams(name="census-sgm", dmax=4)
    prep = prepare(left, right, model, gt)
    kw = {"integrator": "log"} if integrator == "log" else {"counter_max": 2}
    machine = disparity_machine(prep.model, word_bits=8, **kw)
    a = run_machine(prep, machine, "model", progress=False)
    b = run_machine(prep, machine, "pysim", progress=False)
    for name in ("map", "counts", "cycles", "timeout", "nomatch"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for name in ("map", "cycles", "timeout"):  # the right pass's too
        np.testing.assert_array_equal(getattr(a.passes["right"], name), getattr(b.passes["right"], name))
    assert (a.map >= 0).sum() > a.map.size // 2


def test_the_kind_and_its_options() -> None:
    member = fused(Mean, GradH, GradV)
    assert semiglobal(member) is semiglobal(member)
    with pytest.raises(TypeError, match="fused column kind"):
        semiglobal(Mean)
    off = _model(semiglobal=False)
    assert [c.name for c in off.columns] == ["fused"]  # the member itself
    for keywords, parameter in [({"sgm_paths": 0}, "sgm_paths"), ({"sgm_p1": 2.0, "sgm_p2": 1.0}, "sgm_p2"),
                                ({"sgm_cost_bits": 6, "sgm_p2": 6.0}, "sgm_cost_bits"),
                                ({"sgm_temperature": 0.0}, "sgm_temperature"),
                                ({"fuse_columns": False}, "semiglobal")]:
        with pytest.raises(ParameterError) as err:
            _model(**keywords)
        assert err.value.parameter == parameter
    with pytest.raises(TypeError):
        _model(sgm_paths=2.5)
    assert _model().sgm_paths == 2 and _model().sgm_temperature == 0.5  # 1 / paths by default
    assert _model(sgm_paths=4).sgm_temperature == 0.25
    assert _model().column(SemiGlobal).penalties == (16, 96)
