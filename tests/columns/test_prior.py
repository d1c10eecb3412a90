# amaranth: UnusedElaboratable=no
"""The neighbour prior's feedback column (``prior = "neighbour"``), held to an independent oracle;
the RTL (pysim and Verilator) held to the model, and what cannot run it refusing it; the above
column's words (``AbovePrior``, bayesmachine/columns/prior.py) against the formula.

A neighbour-prior machine has the operator matrix of a loaded-prior machine with one more data
column: its column 0 is formed from its previous result instead of loaded. So the oracle runs
that loaded-prior machine one pixel at a time, writing column 0 itself from the rule in
``MachineParams``'s docstring, and the two must give the same results bit for bit (same random
numbers: the sources depend on the operator matrix's shape and the seed only).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bayesmachine.columns import AbovePrior, neighbour_words, quantize
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.engines import get_engine
from bayesmachine.sim.results import MachineResult

from .test_census import census_pair

FEEDBACK = (1024, 900, 600, 300, 120, 60)
NOMATCH = 641


def neighbour_params(**kw: object) -> MachineParams:
    kw.setdefault("counter_max", 3)
    return MachineParams.for_disparity(7, columns=2, prior="neighbour", feedback_words=FEEDBACK,
                                       feedback_nomatch_word=NOMATCH, **kw)


def oracle_params(p: MachineParams) -> MachineParams:
    return dataclasses.replace(p, prior="loaded", columns=p.columns + 1, feedback_words=(),
                               feedback_nomatch_word=None)


def feedback_column(p: MachineParams, prev: int | None, start: bool) -> np.ndarray:
    """The rule, written out: flat after a line start or a non-hypothesis result."""
    one = p.word_one
    if start or prev is None:
        return np.full(p.rows, one)
    col = np.array([FEEDBACK[min(abs(r - prev), len(FEEDBACK) - 1)] for r in range(p.rows)])
    col[p.rows - 1] = NOMATCH
    return col


def words_and_starts(p: MachineParams, pixels: int, width: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    words = rng.integers(0, 300, size=(pixels, p.rows, p.loaded_columns))
    good = rng.integers(0, p.rows - 1, size=pixels)  # a likely hypothesis per pixel, runs of equal ones
    good[1::3] = good[::3][: len(good[1::3])]
    words[np.arange(pixels), good] = rng.integers(700, p.word_one + 1, size=(pixels, p.loaded_columns))
    words[::7, p.rows - 1] = p.word_one  # some no-match calls
    starts = (np.arange(pixels) % width) == 0
    return words, starts


def run_oracle(p: MachineParams, words: np.ndarray, starts: np.ndarray, numbers: np.ndarray | None):
    q = oracle_params(p)
    eng = get_engine("model", q)
    prev: int | None = None
    out = []
    used = 0
    for i in range(len(words)):
        full = np.empty((1, p.rows, q.operator_columns), np.int64)
        full[0, :, 0] = feedback_column(p, prev, bool(starts[i]) or i == 0)
        full[0, :, 1:] = words[i]
        if numbers is None:
            res = eng.run(full)
        else:
            res = eng.run(full, numbers[used:])
            used += int(res.cycles[0])
        out.append(res)
        nm = bool(res.nomatch[0]) or bool(res.timeout[0])
        prev = None if nm else int(res.map[0])
    return out


def assert_same(res: MachineResult, oracle: list[MachineResult]) -> None:
    for name in ("map", "nomatch", "timeout", "cycles", "counts"):
        got = np.asarray(getattr(res, name))
        want = np.concatenate([np.asarray(getattr(o, name)) for o in oracle])
        np.testing.assert_array_equal(got, want, err_msg=name)


@pytest.mark.parametrize("rng", ["sobol", "lfsr", "lfsr-shared"])
def test_feedback_column_follows_the_previous_result(rng: str) -> None:
    p = neighbour_params(rng=rng, seed=5)
    words, starts = words_and_starts(p, 60, 9, seed=1)
    res = get_engine("model", p).run(words, line_start=starts)
    oracle = run_oracle(p, words, starts, None)
    assert_same(res, oracle)
    # The prior matters: the same words with every pixel flagged as a line start differ.
    flat = get_engine("model", p).run(words, line_start=np.ones(len(words), bool))
    assert not np.array_equal(flat.map, res.map)


def test_feedback_with_numbers_from_a_port_and_timeouts() -> None:
    p = neighbour_params(rng="external", max_cycles=12)
    words, starts = words_and_starts(p, 40, 6, seed=2)
    words[5] = 0  # nothing fires: a timeout, after which the prior is flat
    numbers = np.random.default_rng(3).integers(0, p.word_one, size=(40 * 12, p.operators))
    res = get_engine("model", p).run(words, numbers, line_start=starts)
    assert res.timeout[5]
    assert_same(res, run_oracle(p, words, starts, numbers))


def test_previous_result_carries_over_calls_and_reset_forgets_it() -> None:
    p = neighbour_params()
    words, starts = words_and_starts(p, 30, 30, seed=4)
    whole = get_engine("model", p).run(words, line_start=starts)
    eng = get_engine("model", p)
    parts = [eng.run(words[i:i + 7], line_start=starts[i:i + 7]) for i in range(0, 30, 7)]
    for name in ("map", "counts", "cycles"):
        np.testing.assert_array_equal(np.concatenate([getattr(r, name) for r in parts]), getattr(whole, name))
    eng.reset()
    again = eng.run(words, line_start=starts)
    np.testing.assert_array_equal(again.map, whole.map)


def test_params_and_contract_errors() -> None:
    with pytest.raises(ParameterError, match="feedback_words"):
        MachineParams.for_disparity(3, prior="neighbour")
    with pytest.raises(ParameterError, match="feedback_nomatch_word"):
        MachineParams.for_disparity(3, prior="neighbour", feedback_words=(1024,))
    with pytest.raises(ParameterError, match=r"feedback_words\[1\]"):
        MachineParams.for_disparity(3, prior="neighbour", feedback_words=(1024, 1025),
                                    feedback_nomatch_word=1)
    with pytest.raises(ParameterError, match="belong to prior"):
        MachineParams.for_disparity(3, feedback_words=(1024,))
    p = neighbour_params()
    assert (p.operator_columns, p.loaded_columns, p.words_per_pixel) == (4, 3, 27)
    assert p.to_dict()["feedback_words"] == list(FEEDBACK)
    assert "feedback_words" not in MachineParams.for_disparity(3).to_dict()
    eng = get_engine("model", p)
    words = np.zeros((2, p.rows, p.loaded_columns), np.int64)
    with pytest.raises(ValueError, match="needs line_start"):
        eng.run(words)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        eng.run(words, line_start=np.zeros(3, bool))
    with pytest.raises(ValueError, match="loaded columns"):
        eng.run(np.zeros((2, p.rows, p.operator_columns), np.int64), line_start=np.zeros(2, bool))
    with pytest.raises(ValueError, match="only taken by a machine with prior = 'neighbour'"):
        get_engine("model", MachineParams.for_disparity(3)).run(
            np.zeros((1, 5, 3), np.int64), line_start=np.zeros(1, bool))


@pytest.mark.parametrize("rng", ["sobol", "lfsr", "external"])
def test_rtl_equals_the_model_under_pysim(rng: str) -> None:
    """The RTL forms the feedback column as the model does: pysim equals the model bit for bit,
    with back-pressure on both streams (a swap waits for the bubble's registered result)."""
    from bayesmachine.sim.pysim import PysimEngine

    p = neighbour_params(rng=rng, words_per_beat=5, max_cycles=40)
    words, starts = words_and_starts(p, 24, 7, seed=6)
    words[9] = 0  # a timeout
    numbers = (np.random.default_rng(8).integers(0, p.word_one, size=(24 * 40, p.operators))
               if rng == "external" else None)
    want = get_engine("model", p).run(words, numbers, line_start=starts)
    eng = PysimEngine(p, load_stall=0.3, result_stall=0.3, stall_seed=2)
    got = eng.run(words[:10], numbers, line_start=starts[:10])
    used = int(got.cycles.sum())
    rest = eng.run(words[10:], None if numbers is None else numbers[used:], line_start=starts[10:])
    for name in ("map", "nomatch", "timeout", "cycles", "counts"):
        np.testing.assert_array_equal(np.concatenate([getattr(got, name), getattr(rest, name)]),
                                      getattr(want, name), err_msg=name)


def test_rtl_wall_cycles_follow_the_timing_rule() -> None:
    """Back to back with loads keeping up, each pixel takes max(k + 2, beats + 1) + 1 cycles."""
    from bayesmachine.hdl.machine import pixel_wall_cycles
    from bayesmachine.sim.pysim import PysimEngine

    p = neighbour_params(words_per_beat=27)  # one beat per pixel: compute-bound
    words, starts = words_and_starts(p, 20, 5, seed=9)
    eng = PysimEngine(p)
    res = eng.run(words, line_start=starts)
    per_pixel = pixel_wall_cycles(p, res.cycles)
    assert (per_pixel == np.maximum(res.cycles + 2, p.beats_per_pixel + 1) + 1).all()
    # The first pixel waits for its load (beat + write + swap); the results leave a cycle after.
    total = eng.wall_cycles
    assert abs(total - int(per_pixel.sum())) <= 4, (total, int(per_pixel.sum()))


def _run_in_chunks(eng, words: np.ndarray, starts: np.ndarray, numbers: np.ndarray | None,
                   cuts: tuple[int, ...]) -> list[MachineResult]:
    """The stream in calls cut at ``cuts``, each call's numbers from where the last one stopped."""
    parts, used = [], 0
    for lo, hi in zip((0, *cuts), (*cuts, len(words)), strict=True):
        res = eng.run(words[lo:hi], None if numbers is None else numbers[used:], line_start=starts[lo:hi])
        used += int(res.cycles.sum())
        parts.append(res)
    return parts


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("rng", ["sobol", "lfsr", "external"])
def test_verilator_equals_the_model_with_back_pressure_in_chunks(rng: str, verilator_cache) -> None:
    """The Verilator harness carries each pixel's line_start flag into every beat of it: equal to
    the model bit for bit, with random stalls on both streams and a stream cut into calls (the
    previous result carries over)."""
    from bayesmachine.sim.verilator import VerilatorEngine

    p = neighbour_params(rng=rng, words_per_beat=5, max_cycles=40)
    words, starts = words_and_starts(p, 120, 11, seed=12)
    words[9] = 0  # a timeout: the next pixel's feedback prior is flat
    numbers = (np.random.default_rng(13).integers(0, p.word_one, size=(120 * 40, p.operators))
               if rng == "external" else None)
    want = get_engine("model", p).run(words, numbers, line_start=starts)
    assert want.timeout[9] and want.nomatch.any() and (~want.nomatch).any()
    with VerilatorEngine(p, build_dir=verilator_cache, load_stall=0.3, result_stall=0.3, stall_seed=4,
                         verbose=False) as eng:
        parts = _run_in_chunks(eng, words, starts, numbers, (10, 11, 57))
        for name in ("map", "nomatch", "timeout", "cycles", "counts"):
            np.testing.assert_array_equal(np.concatenate([getattr(r, name) for r in parts]),
                                          getattr(want, name), err_msg=name)
        # The flags reach the machine: every pixel flagged as a line start gives other results.
        eng.reset()
        flat = eng.run(words, numbers, line_start=np.ones(len(words), bool))
        assert not np.array_equal(flat.map, want.map)
        np.testing.assert_array_equal(
            flat.map, get_engine("model", p).run(words, numbers, line_start=np.ones(len(words), bool)).map)


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_verilator_wall_cycles_follow_the_timing_rule(verilator_cache) -> None:
    """The clock cycles of a compute-bound stream, derived from the timing rules of
    docs/architecture.md ("Timing"): a neighbour prior's swap comes two cycles after the bubble."""
    from bayesmachine.hdl.machine import pixel_wall_cycles
    from bayesmachine.sim.verilator import VerilatorEngine

    p = neighbour_params(words_per_beat=27, rng="sobol")  # one beat per pixel: compute-bound
    words, starts = words_and_starts(p, 50, 5, seed=9)
    with VerilatorEngine(p, build_dir=verilator_cache, verbose=False) as eng:
        got = eng.run(words, line_start=starts)
        assert got.equal(get_engine("model", p).run(words, line_start=starts))
        beats = p.beats_per_pixel
        # Cycle 0 carries pixel 0's first beat; the shadow is complete beats + 1 cycles later and the
        # idle machine swaps it in at once. A run of k compute cycles ends with its bubble (cycle
        # swap + k + 1); the swap of a neighbour prior comes two cycles later (the bubble registers
        # the result, the next cycle the feedback words), or when the next pixel's load (which
        # starts the cycle after the swap) is written, whichever is later.
        swaps = [beats + 1]
        for k in got.cycles[:-1].tolist():
            swaps.append(max(swaps[-1] + k + 3, swaps[-1] + 1 + beats + 1))
        # The last pixel's result is valid the cycle after its bubble and taken in it.
        assert eng.last_wall_cycles == swaps[-1] + int(got.cycles[-1]) + 2 + 1
        assert pixel_wall_cycles(p, got.cycles)[:-1].tolist() == np.diff(swaps).tolist()
        assert (got.cycles[:-1] + 3 > beats + 2).all()  # compute-bound: every swap waits for a run


def test_lanes_of_machines_and_the_front_end_refuse_it() -> None:
    """Round-robin lanes would feed each lane pixel i - k's result: they refuse a neighbour-prior
    machine up front, naming the prior; the on-chip front end feeds one only with the model whose
    prior it is (the census model's: tests/hdl/frontend/test_census.py)."""
    from bayesmachine.hdl.frontend.stereo import StereoMachine, check_stereo_machine
    from bayesmachine.hdl.machines import ParallelMachines
    from bayesmachine.models import ModelParams

    p = neighbour_params(rng="sobol")
    with pytest.raises(ParameterError, match=r"prior = 'neighbour' cannot run on K machines.*i - 2"):
        ParallelMachines(params=p, machines=2)
    ParallelMachines(params=dataclasses.replace(p, prior="loaded", columns=3, feedback_words=(),
                                            feedback_nomatch_word=None), machines=2)  # the same shape, loaded
    # A paper-model machine (three data columns) whose lanes suit the front end, with a neighbour prior.
    q = MachineParams.for_disparity(7, columns=3, prior="neighbour", feedback_words=FEEDBACK,
                                    feedback_nomatch_word=NOMATCH, words_per_beat=15)
    model = ModelParams(name="paper", dmax=7)
    refused = r"^prior: the machine has a neighbour prior \(prior='neighbour'\) but the paper model has none"
    with pytest.raises(ParameterError, match=refused):
        check_stereo_machine(q, model, 40)
    with pytest.raises(ParameterError, match=refused):
        StereoMachine(params=q, model=model, width=40)


@pytest.mark.slow
@pytest.mark.usefixtures("verilator_toolchain")
def test_census_model_on_the_whole_bundled_pair_verilator_equals_the_model(tmp_path, verilator_cache,
                                                                            monkeypatch) -> None:
    """``run --model census``: the full Dmax 80 neighbour machine under Verilator gives the model's
    result.npz on the whole bundled pair (each engine feeding back its own results)."""
    from bayesmachine.cli import main

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(verilator_cache.parent))
    for engine in ("model", "verilator"):
        assert main(["run", "--model", "census", "--engine", engine, "--quiet", "-o",
                     str(tmp_path / engine)]) == 0
    a, b = np.load(tmp_path / "model" / "result.npz"), np.load(tmp_path / "verilator" / "result.npz")
    for name in ("map", "counts", "cycles", "timeout"):
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


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


def test_words_with_the_neighbour_prior():
    fl, fr, model = census_pair(6, fuse_columns=False)
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
