# amaranth: UnusedElaboratable=no
"""Per-pixel column normalization (``MachineParams.normalize``, ``--normalize-columns``): each loaded
column's operators compare their words w with ``(r * m) >> W``, m the column's largest word for the
pixel: w fires when w * 2^W > r * m, the run on the words w * 2^W / m. The model does so operator by
operator, the scales' component (``hdl.machine.ColumnScales``) equals its twin (``column_scales``)
beat by beat, and the RTL (pysim, Verilator) equals the model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import assert_same_results, run_sim, small_params

from bayesmachine.hdl.machine import ColumnScales, hides_bubble
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel, column_scales
from bayesmachine.sim.pysim import PysimEngine

NEIGHBOUR = dict(prior="neighbour", feedback_words=(16, 10, 4), feedback_nomatch_word=6)
VARIANT_IDS = {
    "sobol": dict(rng="sobol"),  # no bubble (hides_bubble)
    "sobol-bubble": dict(rng="sobol", counter_max=1),
    "lfsr": dict(rng="lfsr"),
    "lfsr-shared": dict(rng="lfsr-shared"),
    "sobol-b2": dict(rng="sobol", samples_per_clock=2, counter_max=4),
    "loaded-prior": dict(rng="sobol", prior="loaded"),
    "neighbour": dict(rng="sobol", **NEIGHBOUR),
    "leading": dict(rng="sobol", timeout_answer="leading", max_cycles=30),
    # Loading bounds the runs: a swap follows the last beat's write at once (its word in the OR).
    "load-bound": dict(rng="sobol", words_per_beat=1, counter_max=1),
    "load-bound-hidden": dict(rng="sobol", words_per_beat=1, counter_max=2),
    "load-bound-lfsr": dict(rng="lfsr", words_per_beat=1, counter_max=1),
}
VARIANTS = list(VARIANT_IDS.values())


def _weak_words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    """Loaded words whose columns are scaled down per pixel by 2^0 .. 2^W (a column of zeros
    included), so most columns shift; some words exactly 2^W (no shift). In every other pixel the
    last loaded word (the last beat's) is its column's largest alone."""
    rng = np.random.default_rng(seed)
    shape = (pixels, params.rows, params.loaded_columns)
    words = rng.integers(0, params.word_one + 1, size=shape)
    words[rng.random(shape) > 0.95] = params.word_one
    scale = rng.integers(0, params.word_bits + 1, size=(pixels, 1, params.loaded_columns))
    words >>= scale
    words[1::2, -1, -1] = np.minimum(params.word_one, 2 * words[1::2, :, -1].max(axis=1) + 1)
    return words.astype(np.int32)


def _line_start(params: MachineParams, pixels: int) -> dict[str, np.ndarray]:
    if not params.feedback_columns:
        return {}
    flags = np.zeros(pixels, bool)
    flags[::5] = True
    return {"line_start": flags}


def test_scale_is_the_columns_largest_word() -> None:
    params = small_params(normalize=True)
    words = _weak_words(params, 200, seed=3)
    scales = column_scales(params, words.reshape(200, -1))
    np.testing.assert_array_equal(scales, words.max(axis=1))
    assert (scales == 0).any() and (scales == params.word_one).any()
    plain = column_scales(dataclasses.replace(params, normalize=False), words.reshape(200, -1))
    assert (plain == params.word_one).all()  # numbers unchanged


SCALE_VARIANTS = {
    "bubble": dict(rng="lfsr"),
    "hidden": dict(rng="sobol"),  # a swap may take the next pixel's first beat
    "neighbour": dict(rng="sobol", **NEIGHBOUR),
    "one-word-beats": dict(rng="sobol", words_per_beat=1),
    "four-word-beats": dict(rng="lfsr", words_per_beat=4),  # a column's word in different lanes
    "loaded-prior": dict(rng="sobol", prior="loaded", words_per_beat=4),
}


@pytest.mark.parametrize("variant", list(SCALE_VARIANTS.values()), ids=list(SCALE_VARIANTS))
def test_column_scales_component_equals_the_twin(variant: dict[str, object]) -> None:
    """``ColumnScales`` beat by beat against ``column_scales``: after each beat taken, the shadow's
    scales are the twin's on the pixel's words so far (the others 0); a cycle without a handshake and
    the last beat's unused lanes change nothing; the swap takes the pixel's scales as the active ones
    (``active_next`` in the swap) and clears the shadow; without the bubble a beat taken in the swap is
    the next pixel's first."""
    params = small_params(normalize=True, **variant)
    pixels, per_beat, nbeats = 40, params.words_per_beat, params.beats_per_pixel
    fb, loaded = params.feedback_columns, params.loaded_columns
    words = _weak_words(params, pixels, seed=6).reshape(pixels, -1)
    rng = np.random.default_rng(2)
    dut = ColumnScales(params=params)

    def twin(pixel: int, beats: int) -> list[int]:  # the scales of the pixel's first ``beats`` beats
        q = words[pixel].copy()
        q[beats * per_beat:] = 0
        ops = np.zeros((params.rows, params.operator_columns), np.int64)  # the feedback column: 0
        ops[:, fb:] = q.reshape(params.rows, loaded)
        return column_scales(params, ops.reshape(1, -1))[0, fb:].tolist()

    async def bench(ctx):
        def scales(port) -> list[int]:  # noqa: ANN001
            return [ctx.get(x) for x in port]

        async def swap(pixel: int) -> None:
            ctx.set(dut.start, 1)
            assert scales(dut.active_next) == twin(pixel, nbeats)
            await ctx.tick()
            ctx.set(dut.start, 0)
            assert scales(dut.active) == twin(pixel, nbeats), f"pixel {pixel}: the active scales"

        assert scales(dut.shadow) == scales(dut.active) == [0] * loaded
        for i in range(pixels):
            in_beat = i > 0 and hides_bubble(params) and rng.random() < 0.5
            if i > 0 and not in_beat:
                await swap(i - 1)
                assert scales(dut.shadow) == [0] * loaded, "the swap clears the shadow's scales"
            for b in range(nbeats):
                for _ in range(int(rng.integers(0, 2))):  # no handshake: any words
                    ctx.set(dut.accept, 0)
                    for lane in range(per_beat):
                        ctx.set(dut.words[lane], int(rng.integers(params.word_one + 1)))
                    await ctx.tick()
                    held = twin(i - 1, nbeats) if in_beat and b == 0 else twin(i, b)  # not swapped yet
                    assert scales(dut.shadow) == held, f"pixel {i}: a cycle without a handshake"
                ctx.set(dut.accept, 1)
                ctx.set(dut.beat, 1 << b)
                for lane in range(per_beat):
                    w = b * per_beat + lane
                    ctx.set(dut.words[lane], int(words[i, w]) if w < params.words_per_pixel
                            else params.word_one)  # an unused lane of the last beat
                if in_beat and b == 0:
                    await swap(i - 1)
                else:
                    await ctx.tick()
                ctx.set(dut.accept, 0)
                assert scales(dut.shadow) == twin(i, b + 1), f"pixel {i}, beat {b}"

    run_sim(dut, bench)


def test_column_scales_checks_its_arguments() -> None:
    with pytest.raises(TypeError, match="MachineParams"):
        ColumnScales(params=None)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="normalize") as err:
        ColumnScales(params=small_params())
    assert err.value.parameter == "normalize"
    with pytest.raises(TypeError):
        ColumnScales(small_params(normalize=True))  # type: ignore[misc]  # keyword-only
    dut = ColumnScales(params=small_params(normalize=True))
    with pytest.raises(AttributeError):
        dut.params = small_params()  # type: ignore[misc]  # read-only


def test_model_fires_when_w_times_2w_exceeds_r_times_m() -> None:
    """The exactness claim, operator by operator: over T cycles (no counter can overflow earlier;
    one that fires every cycle reads counter max), each row's count is the number of cycles in which
    w * 2^W > r * m holds for all its columns (r the operator's number, m its column's largest word);
    a column of zeros never fires."""
    t = 40
    params = small_params(rng="external", normalize=True, counter_max=t - 1, max_cycles=t,
                          timeout_answer="leading", words_per_beat=10)
    pixels, w = 50, params.word_bits
    words = _weak_words(params, pixels, seed=11)
    numbers = np.random.default_rng(12).integers(0, 1 << w, size=(pixels * t, params.operators))
    got = MachineModel(params).run(words, numbers)
    per_pixel = numbers.reshape(pixels, t, params.rows, params.operator_columns).astype(np.int64)
    scale = words.max(axis=1)[:, None, None, :].astype(np.int64)
    fires = (words[:, None].astype(np.int64) << w) > per_pixel * scale  # (pixels, t, rows, columns)
    expected = np.minimum(fires.all(axis=3).sum(axis=1), t - 1)  # an overflowing counter reads t - 1
    np.testing.assert_array_equal(got.counts, expected)
    assert (got.cycles == t).all() and (scale == 0).any()


@pytest.mark.parametrize("variant", VARIANTS, ids=list(VARIANT_IDS))
def test_power_of_two_columns_are_the_run_on_shifted_words(variant: dict[str, object]) -> None:
    """Every on-chip source's kernel: a column whose largest word is 2^(W - s) scales its numbers by
    2^-s, exactly the plain machine on the words w << s."""
    params = small_params(normalize=True, **variant)
    words = _weak_words(params, 120, seed=4)
    top = words.max(axis=1, keepdims=True)
    shift = np.where(top > 0, params.word_bits - np.floor(np.log2(np.maximum(top, 1))).astype(int), 0)
    words[:, -1:, :] = np.where(top > 0, params.word_one >> shift, 0)  # each column's largest: 2^(W-s)
    words = np.minimum(words, words[:, -1:, :])
    start = _line_start(params, 120)
    plain = dataclasses.replace(params, normalize=False)
    got = MachineModel(params).run(words, **start)
    assert_same_results(got, MachineModel(plain).run(words << shift, **start))
    assert got.cycles.mean() < MachineModel(plain).run(words, **start).cycles.mean()


@pytest.mark.parametrize("samples", [2, 8])
def test_model_normalized_b_samples_equal_one_sample(samples: int) -> None:
    """B samples per clock with normalize: the one-sample normalized machine's results, in whole clocks."""
    params = small_params(rng="sobol", normalize=True, samples_per_clock=samples, counter_max=12)
    words = _weak_words(params, 80, seed=5)
    one = MachineModel(dataclasses.replace(params, samples_per_clock=1)).run(words)
    got = MachineModel(params).run(words)
    for field in ("map", "nomatch", "timeout", "counts"):
        np.testing.assert_array_equal(getattr(got, field), getattr(one, field), err_msg=field)
    np.testing.assert_array_equal(got.cycles, (one.cycles + samples - 1) // samples)


@pytest.mark.slow
def test_posterior_ratios_unchanged() -> None:
    """Statistically: over T cycles each row fires in proportion to the product of its words, with
    or without normalize (the rows' ratios, the posterior, unchanged), while normalize fires more."""
    t, pixels = 200, 400
    params = small_params(rng="external", counter_max=t - 1, max_cycles=t, timeout_answer="leading",
                          words_per_beat=10)
    rng = np.random.default_rng(13)
    one = rng.integers(1, params.word_one // 2, size=(1, params.rows, params.loaded_columns))
    words = np.repeat(one, pixels, axis=0).astype(np.int32)
    numbers = rng.integers(0, 1 << params.word_bits, size=(pixels * t, params.operators))
    posterior = one[0].prod(axis=1) / one[0].prod(axis=1).sum()
    totals = []
    for normalize in (False, True):
        run = MachineModel(dataclasses.replace(params, normalize=normalize)).run(words, numbers)
        counts = run.counts.sum(axis=0)
        totals.append(counts.sum())
        np.testing.assert_allclose(counts / counts.sum(), posterior, atol=0.03)
    assert totals[1] > 2 * totals[0]


def test_normalize_off_keeps_fingerprints_and_refuses_a_wrong_type() -> None:
    assert "normalize" not in small_params().to_dict()
    assert small_params(normalize=True).to_dict()["normalize"] is True
    with pytest.raises(TypeError, match="normalize must be True or False"):
        small_params(normalize=1)


@pytest.mark.parametrize("variant", VARIANTS, ids=list(VARIANT_IDS))
def test_pysim_equals_the_model(variant: dict[str, object]) -> None:
    """The RTL: the columns' ORs over the load, the shifts at the swap, the shifted numbers."""
    params = small_params(normalize=True, **variant)
    words = _weak_words(params, 30, seed=7)
    start = _line_start(params, 30)
    got = PysimEngine(params, result_stall=0.2).run(words, **start)
    assert_same_results(got, MachineModel(params).run(words, **start))


def test_pysim_equals_the_model_external_numbers() -> None:
    params = small_params(rng="external", normalize=True, samples_per_clock=2, counter_max=4)
    words = _weak_words(params, 25, seed=8)
    numbers = np.random.default_rng(9).integers(0, 1 << params.word_bits, size=(3000, params.operators))
    got = PysimEngine(params, result_stall=0.2).run(words, numbers)
    assert_same_results(got, MachineModel(params).run(words, numbers))


@pytest.mark.eda
@pytest.mark.parametrize("variant", [VARIANT_IDS["neighbour"], VARIANT_IDS["load-bound-hidden"]],
                         ids=["neighbour", "load-bound-hidden"])
def test_verilator_equals_the_model(verilator_builds, variant: dict[str, object]) -> None:  # noqa: ANN001
    from bayesmachine.sim.verilator import VerilatorEngine

    params = small_params(normalize=True, **variant)
    words = _weak_words(params, 300, seed=10)
    start = _line_start(params, 300)
    engine = VerilatorEngine(params, build_dir=verilator_builds)
    try:
        assert_same_results(engine.run(words, **start), MachineModel(params).run(words, **start))
    finally:
        engine.close()


@pytest.mark.eda
def test_census_lr_crop_under_verilator(verilator_builds) -> None:  # noqa: ANN001
    """census-lr (both passes normalized) on a crop of the bundled pair: Verilator equals the model
    array for array."""
    from bayesmachine.host.images import Crop, bundled_pair, crop_image
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.models import ModelParams, disparity_machine, pass_machine

    left, right, gt = (crop_image(a, Crop(300, 200, 64, 12)) for a in bundled_pair())
    model = ModelParams(dmax=24, name="census-lr")
    prep = prepare(left, right, model, gt)
    machine = disparity_machine(model, normalize=True, max_cycles=256)
    assert pass_machine(model, machine, "right").normalize
    runs = [run_machine(prep, machine, engine, progress=False) for engine in ("model", "verilator")]
    for field in ("map", "nomatch", "timeout", "counts", "cycles"):
        np.testing.assert_array_equal(getattr(runs[1], field), getattr(runs[0], field), err_msg=field)
    np.testing.assert_array_equal(runs[1].passes['right'].map, runs[0].passes['right'].map)
    np.testing.assert_array_equal(runs[1].passes['right'].cycles, runs[0].passes['right'].cycles)


def test_command_line_flag() -> None:
    """``--normalize-columns`` through the machine-option registry: the census models' default (both
    passes of the default model), off with ``--no-normalize-columns`` (left out of the report's
    machine) and for the paper model unless given."""
    from bayesmachine.cli import build_parser
    from bayesmachine.cliargs import machine_params_from_args
    from bayesmachine.models import ModelParams, pass_machine

    parser = build_parser()
    model = ModelParams(dmax=8)
    on = machine_params_from_args(parser.parse_args(["run", "-o", "x"]), 8, model)
    assert on.normalize and pass_machine(model, on, "right").normalize
    off = machine_params_from_args(parser.parse_args(["run", "--no-normalize-columns", "-o", "x"]), 8, model)
    assert not off.normalize and "normalize" not in off.to_dict()
    assert not pass_machine(model, off, "right").normalize
    paper = ModelParams(dmax=8, name="paper")
    assert not machine_params_from_args(parser.parse_args(["run", "--model", "paper", "-o", "x"]), 8,
                                        paper).normalize
    assert machine_params_from_args(parser.parse_args(["run", "--model", "paper", "--normalize-columns",
                                                       "-o", "x"]), 8, paper).normalize
    sweep = parser.parse_args(["sweep", "--normalize-columns", "-o", "x"])
    assert sweep.normalize is True
