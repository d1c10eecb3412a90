# amaranth: UnusedElaboratable=no
"""The logarithmic machine on the models (issue 41): MachineParams.integrator, the energy-coded columns,
the model engine (sim.log_model) against the rule, its clocks against the blocks' latency, the CLI."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.columns.energy import INFINITE_CODE, log_codes
from bayesmachine.errors import ParameterError
from bayesmachine.hdl.log import ArgminTree
from bayesmachine.hdl.log import machine as log_machine
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import likelihoods_plain, memory_words
from bayesmachine.integrators import log as log_definition
from bayesmachine.integrators.log import ARGMIN_LEVELS_PER_STAGE, log_params, pixel_clocks, pixel_wall_cycles
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import get_engine
from bayesmachine.sim.log_model import log_integrate


def test_paper_codes_are_the_energy_form() -> None:
    """The host's codes of the paper model = log_codes of the plain likelihoods (the oracle's)."""
    left, right, _ = bundled_pair()
    left, right = left[200:230, 300:400], right[200:230, 300:400]
    model = ModelParams(name="paper", dmax=16)
    planes = (model_planes(left, model), model_planes(right, model))
    machine = disparity_machine(model, integrator="log")
    codes = memory_words(*planes, model, machine)
    lik, nm = likelihoods_plain(*planes, model)
    n = lik.shape[0] * lik.shape[1]
    assert np.array_equal(codes[:, :17], log_codes(lik).reshape(n, 17, 3))
    assert np.array_equal(codes[:, 17, 0], log_codes(nm).reshape(n))
    assert (codes[:, 17, 1:] == 0).all()  # the other columns' no-match entry is 1.0: code 0
    assert codes.max() < INFINITE_CODE  # every lane of the left pass has a match pixel


def _random_codes(rng: np.random.Generator, machine: MachineParams, pixels: int) -> np.ndarray:
    codes = rng.integers(0, 40, (pixels, machine.rows, machine.loaded_columns))
    codes[rng.random(codes.shape) < 0.05] = INFINITE_CODE
    codes[rng.random(codes.shape[:2]) < 0.02] = 300  # saturated-looking, finite
    return codes


def test_engine_equals_the_rule() -> None:
    rng = np.random.default_rng(5)
    machine = disparity_machine(ModelParams(name="paper", dmax=12), integrator="log")
    codes = _random_codes(rng, machine, 400)
    codes[0] = INFINITE_CODE  # every row excluded: no answer
    res = get_engine("model", machine).run(codes)
    rule = log_integrate(codes, log_params(machine))
    assert np.array_equal(res.map, rule.map) and np.array_equal(res.counts, rule.weights)
    assert np.array_equal(res.nomatch, rule.nomatch) and np.array_equal(res.timeout, rule.all_excluded)
    assert res.timeout[0] and res.timeout.sum() == 1 and (res.cycles == 1).all()
    assert res.counts.max() == 1024  # the MAP's weight, 2^W


def test_engine_feedback_loop() -> None:
    """With the neighbour prior each pixel's feedback column follows the previous MAP, across calls."""
    rng = np.random.default_rng(6)
    machine = disparity_machine(ModelParams(name="census", dmax=10, fuse_columns=False), integrator="log")
    p = log_params(machine)
    fb, nm = np.array(machine.feedback_words), machine.feedback_nomatch_word
    codes = _random_codes(rng, machine, 60)
    starts = np.zeros(30, bool)
    starts[[0, 17]] = True
    eng = get_engine("model", machine)
    got = [eng.run(codes[:30], line_start=starts), eng.run(codes[30:], line_start=np.zeros(30, bool))]
    prev = -1
    for i in range(60):
        full = np.zeros((1, machine.rows, machine.operator_columns), np.int64)
        full[0, :, 1:] = codes[i]
        if not (i < 30 and starts[i]) and prev >= 0:
            full[0, :-1, 0] = fb[np.minimum(np.abs(np.arange(machine.rows - 1) - prev), len(fb) - 1)]
            full[0, -1, 0] = nm
        want = log_integrate(full, p)
        res = got[i // 30]
        assert int(res.map[i % 30]) == int(want.map[0])
        assert np.array_equal(res.counts[i % 30], want.weights[0])
        prev = -1 if want.nomatch[0] or want.all_excluded[0] else int(want.map[0])
    bound = ArgminTree(params=p, levels_per_stage=ARGMIN_LEVELS_PER_STAGE, feedback=True).latency
    # 12 rows: the feedback codes' adders and 4 argmin levels, 2 stages at 4 levels per stage (the
    # next pixel issues as the MAP is registered at the output). The row adders are not in the loop.
    assert pixel_clocks(machine) == (1, bound) == (1, 2)
    assert got[0].cycles[0] == got[0].cycles[17] == 1 and (np.delete(got[0].cycles, [0, 17]) == 2).all()
    # Dmax 80 (82 rows: 7 levels and the adders): 2 clocks, the loop of census and census-lr.
    assert pixel_clocks(disparity_machine(ModelParams(name="census-lr"), integrator="log")) == (1, 2)


def test_engine_refusals() -> None:
    machine = disparity_machine(ModelParams(name="paper", dmax=4), integrator="log")
    with pytest.raises(ParameterError, match="rng"):
        disparity_machine(ModelParams(name="paper", dmax=4), integrator="log", rng="external")
    with pytest.raises(ParameterError, match="word_bits"):
        disparity_machine(ModelParams(name="paper", dmax=4), integrator="log", word_bits=7)
    eng = get_engine("model", machine)
    with pytest.raises(ValueError, match=r"energy codes .* \[0, 511\]"):
        eng.run(np.full((1, 6, 3), 512))
    with pytest.raises(ValueError, match="no random numbers"):
        eng.run(np.zeros((1, 6, 3), np.int64), numbers=np.zeros((4, 18), np.int64))






@pytest.mark.parametrize("name", ["paper", "census"])
def test_pysim_equals_the_model(name) -> None:
    """The log machine's RTL (hdl.log.machine.LogMachine) under pysim, with back-pressure on both
    streams, gives the model engine's results bit for bit (the feedback loop across calls included)."""
    from bayesmachine.hdl.log.machine import LogMachine

    rng = np.random.default_rng(7)
    machine = disparity_machine(ModelParams(name=name, dmax=6), integrator="log", word_bits=8)
    codes = _random_codes(rng, machine, 40)
    codes[3] = INFINITE_CODE
    runs = [(codes[:25], np.arange(25) % 9 == 0), (codes[25:], np.zeros(15, bool))]
    model = get_engine("model", machine)
    sim = get_engine("pysim", machine, load_stall=0.3, result_stall=0.3, stall_seed=2)
    for part, starts in runs:
        kw = {"line_start": starts} if machine.feedback_columns else {}
        want, got = model.run(part, **kw), sim.run(part, **kw)
        for field in ("map", "nomatch", "timeout", "cycles", "counts"):
            assert np.array_equal(getattr(want, field), getattr(got, field)), field
    assert want.counts.max() == 256 and isinstance(sim.dut, LogMachine)


def test_pysim_issue_interval_is_the_loop() -> None:
    """Without back-pressure and with one beat per pixel, pixels with a left neighbour issue every
    loop's clocks: the wall cycles of P such pixels grow by loop clocks per pixel."""
    machine = disparity_machine(ModelParams(name="census", dmax=10), integrator="log", word_bits=8)
    machine = dataclasses.replace(machine, words_per_beat=machine.words_per_pixel)
    assert machine.beats_per_pixel == 1 and pixel_clocks(machine)[1] > 1
    codes = np.zeros((40, machine.rows, machine.loaded_columns), np.int64)
    walls = []
    for pixels in (20, 40):
        eng = get_engine("pysim", machine)
        eng.run(codes[:pixels], line_start=np.arange(pixels) == 0)
        walls.append(eng.wall_cycles)
    assert walls[1] - walls[0] == 20 * pixel_clocks(machine)[1]


@pytest.mark.parametrize("words_per_beat", [None, 1])
def test_pysim_wall_cycles_are_pixel_wall_cycles(words_per_beat: int | None) -> None:
    """Fed without stalls, the machine's wall cycles grow per pixel by :func:`pixel_wall_cycles` of the
    pixels' cycles: the loop where the loading is shorter (one beat), the beats where they are longer
    (one word per beat), lines of 5 pixels (their first pixels issue without the loop)."""
    machine = disparity_machine(ModelParams(name="census", dmax=10), integrator="log", word_bits=8)
    machine = dataclasses.replace(machine, words_per_beat=words_per_beat or machine.words_per_pixel)
    loop = pixel_clocks(machine)[1]
    assert (machine.beats_per_pixel < loop) == (words_per_beat is None)
    line_start = np.arange(40) % 5 == 0
    walls, want = _pysim_walls(machine, line_start)
    assert walls == int(want.sum())


def _pysim_walls(machine: MachineParams, line_start: np.ndarray) -> tuple[int, np.ndarray]:
    """The wall cycles of pysim's last 20 of 40 pixels, unstalled, and their pixel_wall_cycles."""
    rng = np.random.default_rng(3)
    codes = rng.integers(0, 40, (40, machine.rows, machine.loaded_columns))
    cycles = get_engine("model", machine).run(codes, line_start=line_start).cycles
    walls = []
    for pixels in (20, 40):
        eng = get_engine("pysim", machine)
        eng.run(codes[:pixels], line_start=line_start[:pixels])
        walls.append(eng.wall_cycles)
    return walls[1] - walls[0], pixel_wall_cycles(machine, cycles[20:])


def test_pysim_wall_cycles_between_one_beat_and_the_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    """With more than one beat per pixel but fewer than the loop's clocks pixel_wall_cycles is exact
    where every pixel has the loop's clocks, and an upper bound with lines of 5 pixels: a line's first
    pixel, loaded into the row adders during the loops before it, issues sooner. (At 1 argmin level
    per stage: a loop of 6 clocks at Dmax 10, room for 2 to 5 beats.)"""
    monkeypatch.setattr(log_machine, "ARGMIN_LEVELS_PER_STAGE", 1)  # the RTL's setting and the definition's
    monkeypatch.setattr(log_definition, "ARGMIN_LEVELS_PER_STAGE", 1)
    machine = disparity_machine(ModelParams(name="census", dmax=10), integrator="log", word_bits=8)
    loop = pixel_clocks(machine)[1]
    machine = dataclasses.replace(machine, words_per_beat=-(-machine.words_per_pixel // (loop - 1)))
    assert 1 < machine.beats_per_pixel < loop
    walls, want = _pysim_walls(machine, np.arange(40) == 0)
    assert walls == int(want.sum()) == 20 * loop
    walls, want = _pysim_walls(machine, np.arange(40) % 5 == 0)
    assert walls < int(want.sum())


@pytest.mark.eda
@pytest.mark.slow
@pytest.mark.parametrize("name", ["paper", "census", "census-lr"])
def test_verilator_equals_the_model_on_a_crop(tmp_path, name) -> None:
    """run --integrator log: the Verilator engine's results (census-lr's two passes) are the model's."""
    outs = {}
    for engine in ("model", "verilator"):
        out = tmp_path / engine
        assert main(["run", "--integrator", "log", "--crop", "250,200,80,14", "--dmax", "24", "--model",
                     name, "--engine", engine, "--quiet", "--no-sgbm", "-o", str(out)]) == 0
        outs[engine] = np.load(out / "result.npz")
    for key in ("map", "counts", "cycles", "timeout", "confidence"):
        assert np.array_equal(outs["model"][key], outs["verilator"][key]), key


