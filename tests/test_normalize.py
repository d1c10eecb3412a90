# amaranth: UnusedElaboratable=no
"""Per-pixel column normalization (``MachineParams.normalize``, ``--normalize-columns``): each loaded
column's operators compare their words with the random number shifted right by s = max(0, W - L)
(L: the bit length of the OR of the column's words). That is exactly the machine run on the words
``w << s`` (the model on host-shifted words), and the RTL (pysim, Verilator) equals the model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import assert_same_results, small_params

from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineModel, column_shifts
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
    last loaded word (the last beat's) sets its column's bit length alone."""
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


def _host_shifted(params: MachineParams, words: np.ndarray) -> np.ndarray:
    """The loaded words shifted left by their column's shift: what the normalized machine runs."""
    full = np.zeros((words.shape[0], params.rows, params.operator_columns), np.int64)
    full[:, :, params.feedback_columns:] = words
    shifts = column_shifts(params, full.reshape(words.shape[0], -1))[:, params.feedback_columns:]
    return (words.astype(np.int64) << shifts[:, None, :]).astype(np.int32)


def test_shift_puts_the_largest_word_in_the_top_octave() -> None:
    params = small_params(normalize=True)
    words = _weak_words(params, 200, seed=3)
    shifted = _host_shifted(params, words)
    top = shifted.max(axis=1)  # per pixel and column
    w = params.word_bits
    assert ((top == 0) | ((top >= 1 << (w - 1)) & (top <= 1 << w))).all()
    assert (shifted <= params.word_one).all() and (shifted != words).any()
    assert (column_shifts(dataclasses.replace(params, normalize=False), shifted.reshape(200, -1)) == 0).all()


@pytest.mark.parametrize(
    "variant",
    VARIANTS, ids=list(VARIANT_IDS),
)
def test_model_normalized_is_the_model_on_shifted_words(variant: dict[str, object]) -> None:
    """The exactness claim: comparing w with r >> s is the machine on words w << s."""
    params = small_params(normalize=True, **variant)
    words = _weak_words(params, 120, seed=4)
    start = _line_start(params, 120)
    got = MachineModel(params).run(words, **start)
    plain = dataclasses.replace(params, normalize=False)
    assert_same_results(got, MachineModel(plain).run(_host_shifted(params, words), **start))
    assert got.cycles.mean() < MachineModel(plain).run(words, **start).cycles.mean()


def test_model_normalized_external_numbers() -> None:
    params = small_params(rng="external", normalize=True)
    words = _weak_words(params, 60, seed=5)
    numbers = np.random.default_rng(6).integers(0, 1 << params.word_bits, size=(4000, params.operators))
    plain = dataclasses.replace(params, normalize=False)
    assert_same_results(MachineModel(params).run(words, numbers),
                        MachineModel(plain).run(_host_shifted(params, words), numbers))


def test_normalize_off_keeps_fingerprints_and_refuses_a_wrong_type() -> None:
    assert "normalize" not in small_params().to_dict()
    assert small_params(normalize=True).to_dict()["normalize"] is True
    with pytest.raises(TypeError, match="normalize must be a bool"):
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
    from bayesmachine.models import ModelParams, disparity_machine, right_machine

    left, right, gt = (crop_image(a, Crop(300, 200, 64, 12)) for a in bundled_pair())
    model = ModelParams(dmax=24, name="census-lr")
    prep = prepare(left, right, model, gt)
    machine = disparity_machine(model, normalize=True, max_cycles=256)
    assert right_machine(model, machine).normalize
    runs = [run_machine(prep, machine, engine, progress=False) for engine in ("model", "verilator")]
    for field in ("map", "nomatch", "timeout", "counts", "cycles"):
        np.testing.assert_array_equal(getattr(runs[1], field), getattr(runs[0], field), err_msg=field)
    np.testing.assert_array_equal(runs[1].right.map, runs[0].right.map)
    np.testing.assert_array_equal(runs[1].right.cycles, runs[0].right.cycles)


def test_command_line_flag() -> None:
    """``--normalize-columns`` through the machine-option registry: on when given, the model's
    machine (both census-lr passes) keeps it; off (left out of the report's machine) otherwise."""
    from bayesmachine.cli import build_parser
    from bayesmachine.cliargs import machine_params_from_args
    from bayesmachine.models import ModelParams, right_machine

    parser = build_parser()
    model = ModelParams(dmax=8)
    on = machine_params_from_args(parser.parse_args(["run", "--normalize-columns", "-o", "x"]), 8, model)
    assert on.normalize and right_machine(model, on).normalize
    off = machine_params_from_args(parser.parse_args(["run", "-o", "x"]), 8, model)
    assert not off.normalize and "normalize" not in off.to_dict()
    sweep = parser.parse_args(["sweep", "--normalize-columns", "-o", "x"])
    assert sweep.normalize is True
