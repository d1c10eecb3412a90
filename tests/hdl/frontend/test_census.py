# amaranth: UnusedElaboratable=no
"""The census model in the on-chip front end: census filters, census words, the neighbour prior.

Blocks against their twins (``CensusFilter`` against ``host.features.census_codes``, the 7-high
line buffer against ``column_windows``, the lagged feature filter against the host's sums on the
7x7 grid), the ``FrontEnd``'s words against ``host.likelihoods.memory_words`` (with the above
neighbour's words from ``neighbour_words`` of stand-in results), and ``StereoMachine`` against
the model run row by row as the host runs it (``host.run.run_machine``).
"""

from __future__ import annotations

import random

import numpy as np
import pytest
from conftest import assert_same_results, noisy_pair, run_sim

from bayesmachine.columns import Census
from bayesmachine.hdl.frontend.census import CensusFilter
from bayesmachine.hdl.frontend.filters import FeatureFilter
from bayesmachine.hdl.frontend.linebuffer import LineBuffer, column_windows
from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine, stereo_machine_params
from bayesmachine.hdl.frontend.tables import frontend_tables
from bayesmachine.host.features import census_codes, model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams
from bayesmachine.params import ParameterError
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.results import MachineResult
from bayesmachine.sim.stereo_testbench import run_frontend, run_frontend_passes, run_stereo


def _census(dmax: int, window: int = 7, **fields: object) -> ModelParams:
    return ModelParams(dmax=dmax, name="census", census_window=window, **fields)


# --- Blocks against their twins ---

@pytest.mark.parametrize("window", [5, 7])
def test_census_filter_equals_host_census_codes(window: int) -> None:
    image = np.random.default_rng(window).integers(0, 256, (window + 3, 14), dtype=np.uint8)
    image[1:5, 2:9] = 90  # equal neighbours: bit 0
    want = census_codes(image, window)  # on the grid of margin window // 2
    cols = column_windows(image, window)
    dut = CensusFilter(window=window)
    rnd = random.Random(window)

    async def bench(ctx):
        order = [(y, x) for y in range(cols.shape[0]) for x in range(cols.shape[1])]
        for k in range(len(order) + 1):
            ctx.set(dut.load, k < len(order))
            if k < len(order):
                for i in range(window):
                    ctx.set(dut.column[i], int(cols[order[k]][i]))
            ctx.set(dut.en, k > 0)
            await ctx.tick()
            ctx.set(dut.load, 0)
            ctx.set(dut.en, 0)
            for _ in range(rnd.choice([0, 0, 1, 2])):
                await ctx.tick()
            if k > 0 and order[k - 1][1] >= window - 1:
                y, x = order[k - 1]
                assert ctx.get(dut.code) == int(want[y, x - window + 1]), (y, x)

    run_sim(dut, bench)


def test_seven_high_line_buffer_and_lagged_filter_give_the_census_grid_features() -> None:
    """The 7-high column's middle 5 lines through a filter with lag 1: the 5x5 sums around the
    7x7 windows' centres (``model_planes`` of a 7x7 census model)."""
    height, width = 10, 12
    image = np.random.default_rng(8).integers(0, 256, (height, width), dtype=np.uint8)
    want = model_planes(image, _census(1))
    lines, filt = LineBuffer(width=width, height=7), FeatureFilter(lag=1)
    from amaranth.hdl import Module

    top = Module()
    top.submodules.lines, top.submodules.filt = lines, filt
    for i in range(5):
        top.d.comb += filt.column[i].eq(lines.column[1 + i].left)

    async def bench(ctx):
        for y in range(height):
            for x in range(width):
                ctx.set(lines.en, 1)
                ctx.set(lines.col, x)
                ctx.set(lines.pixel, {"left": int(image[y, x]), "right": 0})
                ctx.set(filt.en, 0)
                await ctx.tick()
                ctx.set(lines.en, 0)
                ctx.set(filt.load, 1)  # the column's partial sums
                await ctx.tick()
                ctx.set(filt.load, 0)
                ctx.set(filt.en, 1)  # into the window
                await ctx.tick()
                ctx.set(filt.en, 0)
                if y >= 6 and x >= 6:
                    f = filt.features
                    got = (ctx.get(f.m25), ctx.get(f.gh20), ctx.get(f.gv20))
                    assert got == (want.m25[y - 6, x - 6], want.gh20[y - 6, x - 6], want.gv20[y - 6, x - 6])

    run_sim(top, bench)


def test_census_table_is_clamped_host_table() -> None:
    model = _census(4, fuse_columns=False)
    census = model.column(Census)
    full = census.table(10).values
    clamped = frontend_tables(model, 10)
    h = np.arange(census.bits + 1)
    assert np.array_equal(clamped.lookup("census", h), full[h])
    assert len(clamped["census"]) <= len(full)
    with pytest.raises(ValueError, match="census"):
        frontend_tables(ModelParams(name="paper", dmax=4), 10).lookup("census", h)


# --- The front end's words equal the host's ---

CASES = {
    # name: (model, machine options, frames (height, width))
    "census7": (_census(3, neighbour_prior=False, fuse_columns=False), dict(words_per_beat=8), [(9, 14)]),
    "census7-loaded-prior": (_census(2, neighbour_prior=False, fuse_columns=False),
                             dict(words_per_beat=10, prior="loaded"), [(8, 12)]),
    "census5-two-frames": (_census(3, window=5, neighbour_prior=False), dict(words_per_beat=4), [(6, 11), (7,
                                                                                                           11)]),
    "census7-dmax0": (_census(0, neighbour_prior=False), {}, [(7, 7)]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_census_frontend_words_equal_host_memory_words(name: str) -> None:
    model, options, shapes = CASES[name]
    params = stereo_machine_params(model.dmax, model=model, counter_max=2, **options)
    frames = [noisy_pair(h, w, seed=i) for i, (h, w) in enumerate(shapes)]
    got = run_frontend(FrontEnd(params=params, model=model, width=shapes[0][1]), frames,
                       in_stall=0.2, out_stall=0.3, seed=2)
    want = np.concatenate([memory_words(model_planes(lf, model), model_planes(rf, model), model, params)
                           for lf, rf in frames])
    assert got.shape == want.shape
    assert np.array_equal(got, want), np.argwhere(got != want)[:5]


@pytest.mark.parametrize(("width", "delay"), [(13, 6), (9, 30)])  # 9: output rows of 2 pixels
def test_neighbour_frontend_words_equal_host_words_with_the_above_prior(width: int, delay: int) -> None:
    """The loaded column is ``neighbour_words`` of the results of the row above (stand-ins given
    late, up to ``delay`` cycles after a pixel's words: a narrow image must wait for them), the
    first pixel of each output row carries ``line_start``."""
    model = _census(2, prior_s=1.5)
    params = stereo_machine_params(2, model=model, counter_max=2)
    assert params.words_per_beat % params.loaded_columns == 0 and params.feedback_columns == 1
    frames = [noisy_pair(10, width, seed=4), noisy_pair(8, width, seed=5)]
    wo = width - 6 - model.dmax
    rows = [f[0].shape[0] - 6 for f in frames]
    rng = np.random.default_rng(9)
    maps = rng.integers(-1, model.dmax + 1, sum(rows) * wo)
    front = FrontEnd(params=params, model=model, width=width)
    got, flags = run_frontend_passes(front, frames, {"left": maps}, in_stall=0.2, out_stall=0.2,
                                     result_delay=delay, seed=3)["left"]
    want, starts, k = [], [], 0
    for (lf, rf), h in zip(frames, rows, strict=True):
        fl, fr = model_planes(lf, model), model_planes(rf, model)
        for y in range(h):
            above = np.full(wo, -1) if y == 0 else maps[k - wo : k]
            want.append(memory_words(fl, fr, model, params, rows=slice(y, y + 1),
                                     above=above))
            starts += [1] + [0] * (wo - 1)
            k += wo
    want = np.concatenate(want)
    assert got.shape == want.shape
    assert np.array_equal(got, want), np.argwhere(got != want)[:5]
    assert (flags == np.array(starts)[:, None]).all()


# --- The whole StereoMachine against the model run as the host runs it ---

def _model_run(frames: list[tuple[np.ndarray, np.ndarray]], model: ModelParams, params) -> MachineResult:
    """The model fed as ``host.run.run_machine`` feeds it: map row by map row, the above column from
    its own results of the row before, ``line_start`` on each row's first pixel; frames back to back."""
    engine = MachineModel(params)
    parts = []
    for lf, rf in frames:
        fl, fr = model_planes(lf, model), model_planes(rf, model)
        ho, wo = fl.m25.shape[0], fl.m25.shape[1] - model.dmax
        above = np.full(wo, -1)
        for y in range(ho):
            words = memory_words(fl, fr, model, params, rows=slice(y, y + 1), above=above)
            starts = np.zeros(wo, bool)
            starts[0] = True
            res = engine.run(words, line_start=starts)
            above = np.where(res.nomatch | res.timeout, -1, res.map)
            parts.append(res)
    return MachineResult.concatenate(parts, params.rows)


@pytest.mark.parametrize(("width", "fifo"), [(16, 2), (11, 8)])  # 11: output rows of 3 pixels, deep FIFO
def test_census_stereo_machine_equals_the_model(width: int, fifo: int) -> None:
    left, right, _ = bundled_pair()
    crop = (slice(150, 159), slice(400, 400 + width))
    frames = [(np.ascontiguousarray(left[crop]), np.ascontiguousarray(right[crop])),
              noisy_pair(8, width, seed=1)]
    model = _census(2)
    params = stereo_machine_params(2, model=model, counter_max=8, max_cycles=3000)
    got, _ = run_stereo(StereoMachine(params=params, model=model, width=width, fifo_pixels=fifo), frames,
                        in_stall=0.2, out_stall=0.3, seed=6)
    assert_same_results(got, _model_run(frames, model, params))


def test_census_parameters_are_validated() -> None:
    model = _census(4, fuse_columns=False)
    ok = stereo_machine_params(4, model=model)
    assert ok.words_per_beat == 30 and ok.beats_per_pixel == 1  # 6 rows of 5 loaded words
    with pytest.raises(ParameterError, match="width"):
        StereoMachine(params=ok, model=model, width=10)  # 4 + 7 needed
    StereoMachine(params=ok, model=model, width=11)
    with pytest.raises(ParameterError, match="words_per_beat"):
        FrontEnd(params=stereo_machine_params(4, model=model, words_per_beat=12), model=model, width=20)
    with pytest.raises(ParameterError, match="dmax"):
        stereo_machine_params(5, model=model)
