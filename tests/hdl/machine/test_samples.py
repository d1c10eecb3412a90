# amaranth: UnusedElaboratable=no
"""B random samples per clock (``samples_per_clock``) and the watchdog's leading-row answer
(``timeout_answer = "leading"``): the results of B > 1 are B = 1's in ceil(k / B) clocks, in the
model and in the RTL (pysim), with every source that takes B; a timed-out run answers with the
row of the largest count by the tie rule; the parameters and the command line refuse what is not
built, with one line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import assert_same_results, small_params

from bayesmachine.hdl.machine.counters import (
    overflow_counter_twin,
    overflow_flags_twin,
    sample_counter_twin,
)
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.pysim import PysimEngine
from bayesmachine.sim.results import MachineResult, disparities

NEIGHBOUR = dict(prior="neighbour", feedback_words=(16, 10, 4), feedback_nomatch_word=6)


def _words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    """Random loaded words, a third of the pixels weak (many long runs and timeouts), some exact 0
    and 2^W words, and a pixel where every row fires (a tie of all rows at the first overflow)."""
    rng = np.random.default_rng(seed)
    shape = (pixels, params.rows, params.loaded_columns)
    words = rng.integers(0, params.word_one + 1, size=shape)
    words[::3] //= 4
    pick = rng.random(shape)
    words[pick < 0.1] = 0
    words[pick > 0.85] = params.word_one
    words[1] = params.word_one
    return words.astype(np.int32)


def _line_start(params: MachineParams, pixels: int) -> dict[str, np.ndarray]:
    if not params.feedback_columns:
        return {}
    flags = np.zeros(pixels, bool)
    flags[::7] = True
    return {"line_start": flags}


def _clocks(result: MachineResult, samples: int) -> MachineResult:
    """``result`` with its cycles in clocks of ``samples``: what B samples per clock must give."""
    return dataclasses.replace(result, cycles=-(-result.cycles // samples))


# --- the definitions (twins) ---------------------------------------------------------------------

def test_sample_counter_twin_is_the_one_sample_counter_run_b_times() -> None:
    """Every row state and clock of bits: the flags say at which sample the one-sample counter
    overflows, and the counter stopped at a sample holds the one-sample counter's count there."""
    rng = np.random.default_rng(0)
    for _ in range(3000):
        b = int(rng.choice([2, 4, 8]))
        n_max = int(rng.integers(1, 20))
        count = int(rng.integers(0, n_max + 1))
        bits = rng.integers(0, 2, b).tolist()
        room = min(n_max - count, 2 * b)
        flags = overflow_flags_twin(bits, room)
        c, over_at = count, None
        for i, bit in enumerate(bits):
            over, c = overflow_counter_twin(bit, c, n_max)
            if over and over_at is None:
                over_at = i
            assert flags[i] == int(over_at is not None), (bits, count, n_max)
        stop = int(rng.integers(0, b))
        counted = [int(i <= stop) for i in range(b)]
        c = count
        for bit in bits[: stop + 1]:
            c = overflow_counter_twin(bit, c, n_max)[1]
        assert sample_counter_twin(bits, count, counted, n_max) == (c, min(n_max - c, 2 * b))
        # The prefetch: a clock's flags after an earlier clock's 1s, from the earlier room.
        earlier = int(rng.integers(0, b + 1))
        if earlier <= n_max - count:
            later = min(n_max - count - earlier, 2 * b)
            assert overflow_flags_twin(bits, room, earlier) == overflow_flags_twin(bits, later)


# --- the model ------------------------------------------------------------------------------------

@pytest.mark.parametrize("samples", [2, 4, 8, 16])
@pytest.mark.parametrize(
    "variant",
    [dict(), dict(timeout_answer="leading"), dict(tie_break="lowest-index", max_cycles=37),
     dict(counter_max=1, max_cycles=45), dict(**NEIGHBOUR, timeout_answer="leading", max_cycles=33)],
    ids=["default", "leading", "lowest-index", "n1", "neighbour"],
)
def test_model_samples_give_the_one_sample_results(samples: int, variant: dict[str, object]) -> None:
    """``sobol``, W = 5 (blocks of 32 points: runs span several blocks, and the pixels after them start
    new ones), watchdogs that are not multiples of B: the same counts, maps, flags as B = 1 and
    ceil(k / B) clocks, over pixels run in two calls."""
    base = dict(rng="sobol", word_bits=5, lfsr_bits=12, counter_max=6, max_cycles=61)
    one = small_params(**{**base, **variant})
    many = dataclasses.replace(one, samples_per_clock=samples)
    words = _words(one, 120, seed=samples)
    flags = _line_start(one, 120)
    want = _clocks(MachineModel(one).run(words, **flags), samples)
    model = MachineModel(many)
    part = {k: v[:50] for k, v in flags.items()}
    rest = {k: v[50:] for k, v in flags.items()}
    got = MachineResult.concatenate([model.run(words[:50], **part), model.run(words[50:], **rest)], many.rows)
    assert want.timeout.any() and (~want.timeout).any()
    assert_same_results(got, want)


@pytest.mark.parametrize("samples", [2, 4])
def test_external_numbers_a_clock_at_a_time(samples: int) -> None:
    """``external``: a clock takes B rows of numbers (a number per operator and sample); the rows of
    the samples after a run's stop are used by no one. So the results are B = 1's on the same rows
    without those, in ceil(k / B) clocks; a stream that ends inside a clock runs out there."""
    one = small_params(rng="external", counter_max=3, max_cycles=21, timeout_answer="leading")
    many = dataclasses.replace(one, samples_per_clock=samples)
    words = _words(one, 40, seed=samples)
    numbers = np.random.default_rng(samples).integers(0, 1 << one.word_bits, size=(4000, one.operators))
    got = MachineModel(many).run(words, numbers)
    used = got.cycles * samples  # the rows each pixel's clocks took
    starts = np.concatenate([[0], np.cumsum(used)[:-1]])
    k = [_samples_run(one, w, numbers[s:s + u]) for w, s, u in zip(words, starts, used, strict=True)]
    kept = np.concatenate([numbers[s:s + n] for s, n in zip(starts, k, strict=True)])
    want = MachineModel(one).run(words, kept)
    assert_same_results(got, _clocks(want, samples))
    short = numbers[: int(used[:3].sum()) + samples - 1]  # three pixels, then part of a clock
    with pytest.raises(ValueError, match="ran out"):
        MachineModel(many).run(words[:4], short)


def _samples_run(params: MachineParams, words: np.ndarray, rows: np.ndarray) -> int:
    """The samples one pixel's run takes on ``rows`` (B = 1)."""
    return int(MachineModel(params).run(words[None], rows).cycles[0])


def test_leading_answer_is_the_largest_count_by_the_tie_rule() -> None:
    """A timed-out run's map is the row of the largest count (under nomatch-first the no-match row
    when it is among them, else the lowest index), flagged timeout, no match when that row is the
    no-match row; ``disparities`` answers it, where ``timeout_answer = "none"`` answers no match."""
    for tie_break in ("nomatch-first", "lowest-index"):
        none = small_params(max_cycles=9, counter_max=7, tie_break=tie_break)
        leading = dataclasses.replace(none, timeout_answer="leading")
        words = _words(none, 300, seed=5) // 3
        a, b = MachineModel(none).run(words), MachineModel(leading).run(words)
        assert np.array_equal(a.counts, b.counts) and np.array_equal(a.timeout, b.timeout)
        t = b.timeout
        assert t.sum() > 50
        top = b.counts[t].max(axis=1, keepdims=True)
        lowest = (b.counts[t] == top).argmax(axis=1)
        want = lowest
        if tie_break == "nomatch-first":
            want = np.where(b.counts[t][:, -1] == top[:, 0], none.rows - 1, lowest)
        assert np.array_equal(b.map[t], want) and (a.map[t] == 0).all()
        assert np.array_equal(b.nomatch, b.map == none.rows - 1) and not a.nomatch[t].any()
        assert (b.map[~t] == a.map[~t]).all()
        assert np.array_equal(disparities(b.map, b.nomatch, b.timeout, leading),
                              np.where(b.map == none.rows - 1, -1, b.map))
        assert (disparities(a.map, a.nomatch, a.timeout, none)[t] == -1).all()
        if tie_break == "nomatch-first":
            assert (b.map[t] == none.rows - 1).any() and (b.map[t] < none.rows - 1).any()


# --- the RTL --------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "variant",
    [dict(rng="sobol", samples_per_clock=2),
     dict(rng="sobol", samples_per_clock=4, timeout_answer="leading", max_cycles=29),
     dict(rng="sobol", samples_per_clock=8, word_bits=5, lfsr_bits=12, counter_max=16, max_cycles=70),
     dict(rng="sobol", samples_per_clock=4, counter_max=2, max_cycles=23),  # a first clock can overflow
     dict(rng="sobol", samples_per_clock=2, prior="loaded", tie_break="lowest-index"),
     dict(rng="sobol", samples_per_clock=4, counter_max=5, max_cycles=27, timeout_answer="leading",
          **NEIGHBOUR),
     dict(rng="lfsr", counter_max=6, max_cycles=17, timeout_answer="leading"),
     dict(rng="sobol", counter_max=6, max_cycles=17, timeout_answer="leading")],
    ids=["b2", "b4-leading", "b8-w5", "b4-n2", "b2-loaded", "b4-neighbour", "lfsr-leading", "sobol-leading"],
)
def test_rtl_matches_the_model(variant: dict[str, object]) -> None:
    """pysim against the model, with random load and result stalls: B samples per clock, the leading
    answer (its search in the bubble) and both together, with each prior."""
    params = small_params(**variant)
    words = _words(params, 30, seed=len(str(variant)))
    flags = _line_start(params, 30)
    got = PysimEngine(params, load_stall=0.2, result_stall=0.3, stall_seed=3).run(words, **flags)
    want = MachineModel(params).run(words, **flags)
    assert_same_results(got, want)
    if params.timeout_answer == "leading" and not params.feedback_columns:
        assert want.timeout.any()


@pytest.mark.parametrize("samples", [1, 2, 4])
def test_rtl_external_numbers_per_clock(samples: int) -> None:
    """``external``: the entropy port carries B numbers per operator, a clock's; pysim equals the model."""
    params = small_params(rng="external", counter_max=3, max_cycles=21, samples_per_clock=samples,
                          timeout_answer="leading")
    words = _words(params, 25, seed=1)
    numbers = np.random.default_rng(2).integers(0, 1 << params.word_bits, size=(3000, params.operators))
    got = PysimEngine(params, result_stall=0.2).run(words, numbers)
    assert_same_results(got, MachineModel(params).run(words, numbers))


# --- what is refused ------------------------------------------------------------------------------

@pytest.mark.parametrize(
    ("kwargs", "message"),
    [(dict(samples_per_clock=3), "samples_per_clock must be one of"),
     (dict(samples_per_clock=8, max_cycles=8, counter_max=3), "must exceed samples_per_clock"),
     (dict(samples_per_clock=2, rng="lfsr"), "rng = 'lfsr' gives one number per operator per clock"),
     (dict(samples_per_clock=2, rng="lfsr-shared"), "rng = 'lfsr-shared' gives one number"),
     (dict(samples_per_clock=2, rng="smtj"), "rng = 'smtj' gives one number"),
     (dict(samples_per_clock=16, rng="sobol", word_bits=4), "at least two clocks"),
     (dict(timeout_answer="argmax"), "timeout_answer must be one of")],
)
def test_refused_with_one_line(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ParameterError, match=message) as info:
        small_params(**kwargs)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("value", [True, 2.0, "2"])
def test_samples_per_clock_of_a_wrong_type(value: object) -> None:
    with pytest.raises(TypeError, match="samples_per_clock must be an integer"):
        small_params(samples_per_clock=value)


def test_timeout_answer_of_a_wrong_type() -> None:
    with pytest.raises(TypeError, match="timeout_answer must be one of"):
        small_params(timeout_answer=1)


def test_defaults_keep_fingerprints_and_census_answers_leading() -> None:
    """B = 1 and the "none" answer are left out of ``to_dict`` (fingerprints, build caches and reports
    of the machines before them stay); the census models' machines answer timeouts with the leading
    row, the paper's does not."""
    from bayesmachine.models import ModelParams, disparity_machine

    p = small_params()
    assert "samples_per_clock" not in p.to_dict() and "timeout_answer" not in p.to_dict()
    assert dataclasses.replace(p, samples_per_clock=2).to_dict()["samples_per_clock"] == 2
    assert disparity_machine(ModelParams(dmax=8, name="paper")).timeout_answer == "none"
    for name in ("census", "census-lr"):
        assert disparity_machine(ModelParams(dmax=8, name=name)).timeout_answer == "leading"
    given = disparity_machine(ModelParams(dmax=8, name="census"), timeout_answer="none")
    assert given.timeout_answer == "none"


# --- Verilator and the host ---------------------------------------------------------------------

@pytest.mark.eda
@pytest.mark.parametrize(
    "variant",
    [dict(rng="sobol", samples_per_clock=8, word_bits=5, lfsr_bits=12, counter_max=16, max_cycles=75,
          timeout_answer="leading"),
     dict(rng="external", samples_per_clock=2, counter_max=3, max_cycles=21, timeout_answer="leading")],
    ids=["sobol-b8", "external-b2"],
)
def test_verilator_matches_the_model(verilator_builds, variant: dict[str, object]) -> None:  # noqa: ANN001
    """The emitted Verilog under Verilator: bit for bit the model, B samples per clock and the leading
    answer; its wall cycles are ``pixel_wall_cycles`` plus the first load and the last hand-over."""
    from bayesmachine.hdl.machine import pixel_wall_cycles
    from bayesmachine.sim.verilator import VerilatorEngine

    params = small_params(**variant)
    words = _words(params, 300, seed=8)
    numbers = {}
    if params.rng == "external":
        rows = np.random.default_rng(3).integers(0, 1 << params.word_bits, (30000, params.operators))
        numbers["numbers"] = rows
    engine = VerilatorEngine(params, build_dir=verilator_builds)
    try:
        got = engine.run(words, **numbers)
        assert_same_results(got, MachineModel(params).run(words, **numbers))
        assert got.timeout.any()
        want = int(pixel_wall_cycles(params, got.cycles, got.timeout).sum())
        assert 0 <= engine.last_wall_cycles - want <= params.beats_per_pixel + 4
    finally:
        engine.close()


@pytest.mark.eda
def test_census_lr_crop_at_eight_samples_per_clock(verilator_builds) -> None:  # noqa: ANN001
    """census-lr (both passes) on a crop of the bundled pair at B = 8: the
    Verilator engine equals the model array for array, and both are the B = 1 run's maps, no-match
    flags, timeouts and counts, in ceil(k / 8) clocks."""
    from bayesmachine.host.images import Crop, bundled_pair, crop_image
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.models import ModelParams, disparity_machine

    # A crop where census-lr (its columns fused) has timeouts (4 of 204 pixels): the watchdog path too.
    left, right, gt = (crop_image(a, Crop(250, 150, 64, 12)) for a in bundled_pair())
    model = ModelParams(dmax=24, name="census-lr")
    prep = prepare(left, right, model, gt)
    one = run_machine(prep, disparity_machine(model), "model", progress=False)
    eight = disparity_machine(model, samples_per_clock=8)
    runs = [run_machine(prep, eight, engine, progress=False) for engine in ("model", "verilator")]
    for run in runs:
        for field in ("map", "nomatch", "timeout", "counts"):
            np.testing.assert_array_equal(getattr(run, field), getattr(one, field), err_msg=field)
        np.testing.assert_array_equal(run.cycles, -(-one.cycles // 8))
        np.testing.assert_array_equal(run.passes["right"].map, one.passes["right"].map)
        np.testing.assert_array_equal(run.passes["right"].cycles, -(-one.passes["right"].cycles // 8))
    assert one.timeout.any() and one.map.size > 100


def test_run_command_reports_samples_per_clock(tmp_path, capsys) -> None:  # noqa: ANN001
    """``bayesmachine run --samples-per-clock 8``: report.json has the machine's samples per clock and
    its cycles in clocks; a B the machine refuses is one line and exit 2."""
    import json

    from bayesmachine.cli import main

    crop = ["--crop", "300,200,64,12", "--model", "census", "--no-fuse-columns", "--dmax", "24"]
    for b in (1, 8):
        assert main(["run", *crop, "--samples-per-clock", str(b), "-o", str(tmp_path / f"b{b}")]) == 0
    one, eight = (json.loads((tmp_path / f"b{b}" / "report.json").read_text()) for b in (1, 8))
    assert (one["samples_per_clock"], eight["samples_per_clock"]) == (1, 8)
    assert eight["machine"]["samples_per_clock"] == 8
    assert eight["cycles_per_pixel_mean"] < one["cycles_per_pixel_mean"] / 6
    assert eight["machine_bad2"] == one["machine_bad2"]
    capsys.readouterr()
    for bad, message in ((["--samples-per-clock", "3"], "samples_per_clock must be one of"),
                         (["--samples-per-clock", "2", "--rng", "lfsr"], "gives one number per operator")):
        assert main(["run", *crop, *bad, "-o", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) <= 2 and message in err[-1]
        assert not (tmp_path / "bad").exists()


@pytest.mark.slow
def test_whole_pair_under_verilator_at_eight_samples_per_clock(verilator_builds) -> None:  # noqa: ANN001
    """The issue's figure: census-lr's run (Dmax 80) on the whole bundled pair with
    ``--samples-per-clock 8`` under Verilator gives exactly the B = 1 model's maps, no-match flags,
    timeouts and counts (both passes), in at most a sixth of its cycles per pixel."""
    from bayesmachine.host.images import bundled_pair
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.models import ModelParams, disparity_machine

    left, right, gt = bundled_pair()
    model = ModelParams(name="census-lr")
    prep = prepare(left, right, model, gt, reference=False)
    one = run_machine(prep, disparity_machine(model), "model", progress=False)
    eight = run_machine(prep, disparity_machine(model, samples_per_clock=8), "verilator", progress=False)
    for field in ("map", "nomatch", "timeout", "counts"):
        np.testing.assert_array_equal(getattr(eight, field), getattr(one, field), err_msg=field)
    np.testing.assert_array_equal(eight.cycles, -(-one.cycles // 8))
    np.testing.assert_array_equal(eight.passes["right"].map, one.passes["right"].map)
    np.testing.assert_array_equal(eight.passes["right"].cycles, -(-one.passes["right"].cycles // 8))

    def per_pixel(run) -> float:  # noqa: ANN001  # both passes' compute cycles per output pixel
        return (run.cycles.sum() + run.passes["right"].cycles.sum()) / run.cycles.size

    print(f"\ncensus-lr, whole pair: {per_pixel(one):.2f} cycles per pixel at B = 1, {per_pixel(eight):.2f} "
          f"at B = 8 under Verilator")
    assert per_pixel(eight) <= per_pixel(one) / 6


@pytest.mark.eda
def test_front_end_at_four_samples_per_clock(verilator_builds, tmp_path) -> None:  # noqa: ANN001
    """``--feed pixels``: the census model's StereoMachine (front end, neighbour prior from its own
    results) at B = 4 with a short watchdog (timeouts answered by their leading row, which the above
    column does not follow) gives the model's B = 1 maps, counts and timeouts, in ceil(k / 4) clocks."""
    from bayesmachine.cli import main

    crop = ["--crop", "250,200,40,12", "--dmax", "8", "--quiet", "--no-sgbm", "--model", "census",
            "--max-cycles", "20"]
    assert main(["run", "--engine", "verilator", "--feed", "pixels", "--samples-per-clock", "4", *crop,
                 "-o", str(tmp_path / "px")]) == 0
    assert main(["run", "--engine", "model", *crop, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "px" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    for key in ("map", "counts", "timeout"):
        assert np.array_equal(got[key], want[key]), key
    assert np.array_equal(got["cycles"], -(-want["cycles"] // 4))
    assert want["timeout"].any() and (want["map"][want["timeout"]] >= 0).any()
