# amaranth: UnusedElaboratable=no
"""census-lr on chip: the right pass and the consistency column in the front end.

Blocks against their twins in ``bayesmachine.columns.consistency`` (``ConsistencyTest`` against
``lr_consistent``), and the census-lr ``StereoMachine`` (two machines: the right pass's and the left
pass's) against the model run as the host runs census-lr (``host.run.run_machine``: per map row the
right pass's row, then the left pass's with the consistency column of the right MAPs), left and right
results alike, with random stalls on both streams.
"""

from __future__ import annotations

import random

import numpy as np
import pytest
from conftest import assert_same_results, run_sim

from bayesmachine.columns import Consistency, lr_consistent, lr_unknown
from bayesmachine.hdl.frontend.filters import feature_layout
from bayesmachine.hdl.frontend.lr import ConsistencyTest, RightPassFeeder, right_pass_params
from bayesmachine.hdl.frontend.stereo import (
    FrontEnd,
    StereoMachine,
    check_stereo_machine,
    stereo_machine_params,
)
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words, pass_grid, pass_words
from bayesmachine.models import ModelParams, pass_machine
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.results import MachineResult
from bayesmachine.sim.stereo_testbench import run_frontend_lr, run_stereo_lr


def _noisy_pair(height: int, width: int, seed: int, shift: int = 2) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    left = rng.integers(0, 256, (height, width), dtype=np.uint8)
    right = np.roll(left, -shift, axis=1).astype(np.int64) + rng.integers(-3, 4, (height, width))
    return left, right.clip(0, 255).astype(np.uint8)


def _lr(dmax: int, **fields: object) -> ModelParams:
    return ModelParams(dmax=dmax, name="census-lr", **fields)


# --- Blocks against their twins ---

@pytest.mark.parametrize(("dmax", "tolerance"), [(6, 1), (4, 0), (0, 2)])
def test_consistency_test_equals_lr_consistent(dmax: int, tolerance: int) -> None:
    """Shift in one row of right MAPs (-1: none) column by column; after column x the lanes' bits are
    ``lr_consistent`` of that row at left map column x (x >= Dmax), and ``any`` their OR."""
    rng = np.random.default_rng(dmax + 10 * tolerance)
    width = 3 * dmax + 12
    row = rng.integers(-1, dmax + 3, width)  # MAPs past Dmax + 1 too: map_width holds them
    row[rng.random(width) < 0.3] = -1
    map_width = max(1, (dmax + 4).bit_length())
    dut = ConsistencyTest(dmax=dmax, map_width=map_width, tolerance=tolerance)
    want = lr_consistent(row, 0, np.arange(dmax, width), dmax, tolerance)
    want_unknown = lr_unknown(row, 0, np.arange(dmax, width), dmax)
    rnd = random.Random(dmax)

    async def bench(ctx):
        for x in range(width):
            ctx.set(dut.entry.map, max(0, int(row[x])))
            ctx.set(dut.entry.hit, int(row[x] >= 0))
            ctx.set(dut.shift, 1)
            await ctx.tick()
            ctx.set(dut.shift, 0)
            for _ in range(rnd.choice([0, 1])):
                await ctx.tick()  # no shift: the test holds
            if x >= dmax:
                bits = ctx.get(dut.consistent)
                got = [(bits >> d) & 1 for d in range(dmax + 1)]
                assert got == want[x - dmax].astype(int).tolist(), x
                assert ctx.get(dut.any) == int(want[x - dmax].any()), x
                unknown = ctx.get(dut.unknown)
                got_unknown = [(unknown >> d) & 1 for d in range(dmax + 1)]
                assert got_unknown == want_unknown[x - dmax].astype(int).tolist(), x

    run_sim(dut, bench)


@pytest.mark.parametrize("dmax", [1, 2, 3, 5])
def test_right_pass_feeder_delays_the_reference_and_flushes_each_output_row(dmax: int) -> None:
    """Per input pixel one output pixel whose reference (``left``) is the right features Dmax pixels
    back; after an output row's last pixel, Dmax flush pixels k = 1..Dmax continuing the delay line
    (its circular buffer wraps several times, write-through at Dmax 1)."""
    bits = 24
    dut = RightPassFeeder(dmax=dmax, features=feature_layout(bits))
    n = 14
    line_end = {6, 13}
    rnd = random.Random(1 + dmax)
    got: list[tuple[int, int, int, int]] = []

    async def feeder(ctx):
        for k in range(n):
            ctx.set(dut.i.valid, 1)
            ctx.set(dut.i.payload, {"left": {"m25": 100 + k}, "right": {"m25": k + 1, "census": k},
                                    "output": int(k % 7 >= dmax), "line_end": int(k in line_end)})
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)
            for _ in range(rnd.choice([0, 0, 1])):
                await ctx.tick()

    async def sink(ctx):
        while len(got) < n + 2 * dmax:
            ready = rnd.random() < 0.7
            ctx.set(dut.o.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            if valid and ready:
                got.append((payload.left.m25, payload.right.m25, payload.output, payload.flush))

    from amaranth.sim import Simulator

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(sink)
    sim.run()
    want: list[tuple[int | None, int, int, int]] = []
    refs: list[int] = []
    for k in range(n):
        refs.append(k + 1)
        want.append((refs[-1 - dmax] if len(refs) > dmax else None, 100 + k, int(k % 7 >= dmax), 0))
        if k in line_end:
            for f in range(1, dmax + 1):
                refs.append(0)
                want.append((refs[-1 - dmax], 0, 1, f))
    for (g, w) in zip(got, want, strict=True):
        assert w[0] is None or g[0] == w[0]
        assert g[1:] == w[1:]
    with pytest.raises(TypeError, match="dmax"):
        RightPassFeeder(dmax=2.0, features=feature_layout(24))
    with pytest.raises(TypeError, match="features"):
        RightPassFeeder(dmax=2, features=24)


# --- The front end's words of both passes equal the host's ---

@pytest.mark.parametrize(("model", "width", "delay"), [
    (_lr(3), 15, 6),
    (_lr(7), 16, 6),  # Dmax >= 6 lanes: the right pass's entry 0 (its newest pixel) in beat 1
    (_lr(2, lr_right_nomatch=False, lr_neutral=False, lr_nomatch=False, lr_tolerance=0), 11, 25),  # 2 per row
])
def test_lr_frontend_words_equal_host_words(model: ModelParams, width: int, delay: int) -> None:
    """With stand-in results for both machines (given late, up to ``delay`` cycles after a pixel's
    words), the right pass's words are ``pass_words`` (its above column from the stand-in right
    results of the row before) and the left pass's ``memory_words`` with the consistency column of the
    stand-in right MAPs of its row (``Consistency.loaded``)."""
    params = stereo_machine_params(model.dmax, model=model, counter_max=2)
    rp = right_pass_params(model, params)
    frames = [_noisy_pair(9, width, seed=4), _noisy_pair(8, width, seed=5)]
    rng = np.random.default_rng(3)
    wo, wr = width - 6 - model.dmax, width - 6
    rows = [f[0].shape[0] - 6 for f in frames]
    maps = rng.integers(-1, model.dmax + 1, sum(rows) * wo)
    right_maps = rng.integers(-1, model.dmax + 1, sum(rows) * wr)
    front = FrontEnd(params=params, model=model, width=width)
    got, flags, got_r, flags_r = run_frontend_lr(front, frames, maps, right_maps, in_stall=0.2, out_stall=0.2,
                                                 result_delay=delay, seed=3)
    w = params.word_bits
    lr = model.column(Consistency)
    want, want_r, k, kr = [], [], 0, 0
    for (lf, rf), h in zip(frames, rows, strict=True):
        fl, fr = model_planes(lf, model), model_planes(rf, model)
        cols = pass_grid(model.pass_named("right"), OutputRegion.of_features(fl.shape, model.dmax)).columns
        for y in range(h):
            r_above = np.full(wr, -1) if y == 0 else right_maps[kr - wr : kr]
            want_r.append(pass_words(model.pass_named("right"), fl, fr, rp, rows=slice(y, y + 1),
                                     above=r_above))
            column = lr.loaded(lr.table(w), right_maps[kr : kr + wr], int(cols[0]), cols[model.dmax:])
            above = np.full(wo, -1) if y == 0 else maps[k - wo : k]
            want.append(memory_words(fl, fr, model, params, rows=slice(y, y + 1),
                                     above=above, results={"right": right_maps[kr : kr + wr][None]}))
            assert np.array_equal(want[-1][:, :, -1], column)
            k += wo
            kr += wr
    want_r_all, want_all = np.concatenate(want_r), np.concatenate(want)
    assert got_r.shape == want_r_all.shape and got.shape == want_all.shape
    assert np.array_equal(got_r, want_r_all), np.argwhere(got_r != want_r_all)[:5]
    assert np.array_equal(got, want_all), np.argwhere(got != want_all)[:5]
    assert (flags == np.array(([1] + [0] * (wo - 1)) * sum(rows))[:, None]).all()
    assert (flags_r == np.array(([1] + [0] * (wr - 1)) * sum(rows))[:, None]).all()
    assert (want_r_all[:, : model.dmax + 1, 1:] == 0).any()  # lanes past the last output column: word 0


# --- The census-lr StereoMachine against the model run as the host runs it ---

def _model_run(frames: list[tuple[np.ndarray, np.ndarray]], model: ModelParams,
               params) -> tuple[MachineResult, MachineResult]:
    """Both passes on the model as ``host.run.run_machine`` runs census-lr, frames back to back (one
    engine per pass, so the random sources carry over as on chip): per map row, the right pass's row
    (its above column from its own previous row), then the left pass's with the consistency words."""
    rparams = pass_machine(model, params, "right")
    left_eng, right_eng = MachineModel(params), MachineModel(rparams)
    w = params.word_bits
    lr = model.column(Consistency)
    left, right = [], []
    for lf, rf in frames:
        fl, fr = model_planes(lf, model), model_planes(rf, model)
        region = OutputRegion.of_features(fl.shape, model.dmax)
        cols = pass_grid(model.pass_named("right"), region).columns
        ho, wo = region.shape
        above, right_above = np.full(wo, -1), np.full(cols.size, -1)
        for y in range(ho):
            rows = slice(y, y + 1)
            rw = pass_words(model.pass_named("right"), fl, fr, rparams, rows=rows, above=right_above)
            starts = np.zeros(cols.size, bool)
            starts[0] = True
            res_r = right_eng.run(rw, line_start=starts)
            right_above = np.where(res_r.nomatch | res_r.timeout, -1, res_r.map)
            cw = lr.loaded(lr.table(w), right_above, int(cols[0]), region.map_columns)
            words = memory_words(fl, fr, model, params, rows=rows,
                                 above=above, results={"right": right_above[None]})
            assert np.array_equal(words[:, :, -1], cw)
            starts = np.zeros(wo, bool)
            starts[0] = True
            res = left_eng.run(words, line_start=starts)
            above = np.where(res.nomatch | res.timeout, -1, res.map)
            left.append(res)
            right.append(res_r)
    return MachineResult.concatenate(left, params.rows), MachineResult.concatenate(right, rparams.rows)


CASES = {
    # name: (model, frames (height, width) or "bundled", fifo pixels, counter max)
    "bundled-crop": (_lr(3), [(9, 18), "noisy"], 2, 6),
    "narrow-deep-fifo": (_lr(2, lr_tolerance=0), [(8, 11)], 8, 4),
    "no-nomatch-row-right-watchdog": (_lr(3, lr_nomatch=False, lr_right_max_cycles=9), [(8, 14)], 3, 6),
    "census5": (_lr(2, census_window=5), [(7, 12), "noisy"], 2, 5),
    # The rules: no right no-match row, a lane without a right MAP gets beta (not neutral).
    "issue-rules": (_lr(3, lr_right_nomatch=False, lr_neutral=False), [(9, 16)], 2, 6),
    "dmax0": (_lr(0), [(8, 8)], 2, 4),
}


@pytest.mark.parametrize("name", list(CASES))
def test_census_lr_stereo_machine_equals_the_model(name: str) -> None:
    model, shapes, fifo_pixels, counter_max = CASES[name]
    height, width = shapes[0]
    left, right, _ = bundled_pair()
    crop = (slice(150, 150 + height), slice(400, 400 + width))
    frames = [(np.ascontiguousarray(left[crop]), np.ascontiguousarray(right[crop]))]
    if len(shapes) > 1:
        frames.append(_noisy_pair(height - 1, width, seed=1))
    params = stereo_machine_params(model.dmax, model=model, counter_max=counter_max, max_cycles=400)
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=fifo_pixels)
    got, got_right, _ = run_stereo_lr(top, frames, in_stall=0.2, out_stall=0.3, seed=6)
    want, want_right = _model_run(frames, model, params)
    assert_same_results(got_right, want_right)
    assert_same_results(got, want)
    assert (want_right.timeout.any() or name != "no-nomatch-row-right-watchdog")  # the watchdog fires


def test_census_lr_on_chip_parameters() -> None:
    model = _lr(4)
    params = stereo_machine_params(4, model=model)
    assert params.columns == 5 and params.loaded_columns == 6 and params.words_per_beat % 6 == 0
    rp = right_pass_params(model, params)
    assert rp.columns == 4 and rp.seed != params.seed and rp.words_per_beat % rp.loaded_columns == 0
    check_stereo_machine(params, model, 11)
    with pytest.raises(ParameterError, match="rng"):
        check_stereo_machine(stereo_machine_params(4, model=model, rng="smtj"), model, 11)
    with pytest.raises(ParameterError, match="width"):
        FrontEnd(params=params, model=model, width=10)
