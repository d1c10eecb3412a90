# amaranth: UnusedElaboratable=no
"""The on-chip front end against the host: every word it writes equals ``memory_words``.

Blocks against their twins (line buffer, filters, clamped tables), the whole ``FrontEnd`` against
``host.likelihoods.memory_words`` on small crops and edge cases, and ``StereoMachine`` against the
model fed with the host's words, with back-pressure on both streams.
"""

from __future__ import annotations

import dataclasses
import random
from typing import Any

import numpy as np
import pytest
from amaranth.hdl import Fragment, Module, Signal, signed, unsigned
from amaranth.sim import Simulator
from conftest import assert_same_results, noisy_pair, run_sim

from bayesmachine.columns import GradH, GradV, Mean
from bayesmachine.hdl.frontend.filters import FeatureFilter
from bayesmachine.hdl.frontend.linebuffer import LineBuffer, column_windows
from bayesmachine.hdl.frontend.lookup import clamped_magnitude, table_depth
from bayesmachine.hdl.frontend.pipeline import PipelineNets
from bayesmachine.hdl.frontend.stereo import (
    MAX_WIDTH,
    FeaturePipeline,
    FrontEnd,
    StereoMachine,
    stereo_machine_params,
)
from bayesmachine.hdl.frontend.tables import clamp_table, frontend_tables, padded_table
from bayesmachine.hdl.frontend.words import WordGenerator
from bayesmachine.hdl.machine import LOAD_LATENCY, BayesianMachine, pixel_wall_cycles
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import bundled_pair, random_dot_stereogram
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.stereo_testbench import run_frontend, run_stereo


def _host_words(frames: list[tuple[np.ndarray, np.ndarray]], model: ModelParams,
                params: MachineParams) -> np.ndarray:
    return np.concatenate([memory_words(feature_sums(lf), feature_sums(rf), model, params)
                           for lf, rf in frames])


# --- Blocks against their twins ---

@pytest.mark.parametrize("model", [ModelParams(name="paper"),
                                   ModelParams(name="paper", dmax=4, p0=0.1, sigma_m=3.0, sigma_gh=40.0,
                                               sigma_gv=1000.0, p_nm0=0.3, sigma_nm=2.0)])
@pytest.mark.parametrize("word_bits", [4, 10, 15])
def test_clamped_tables_give_the_host_word_for_every_difference(model: ModelParams, word_bits: int) -> None:
    full = {c.name: c.table(word_bits).values for c in (model.column(Mean), model.column(GradH),
                                                         model.column(GradV), model.nomatch)}
    clamped = frontend_tables(model, word_bits)
    for name in ("m", "gh", "gv", "nomatch"):
        table = full[name]
        deltas = np.arange(-len(table) + 1, len(table))
        assert np.array_equal(clamped.lookup(name, deltas), table[np.abs(deltas)]), name
        assert len(clamped[name]) <= len(table)
    if word_bits == 10 and model == ModelParams(name="paper"):
        assert len(clamped["m"]) < len(full["m"]) // 4  # the paper's tables decay well before the end


def test_clamp_table_edge_cases() -> None:
    assert clamp_table(np.array([7, 7, 7])).tolist() == [7]
    assert clamp_table(np.array([9, 5, 3])).tolist() == [9, 5, 3]
    assert clamp_table(np.array([9, 3, 5, 5])).tolist() == [9, 3, 5]
    with pytest.raises(ValueError, match="non-empty"):
        clamp_table(np.array([]))


def test_padded_table_repeats_the_last_word() -> None:
    assert padded_table(np.array([9, 3, 5]), 4).tolist() == [9, 3, 5, 5]
    assert padded_table(np.array([9, 3, 5]), 3).tolist() == [9, 3, 5]
    with pytest.raises(ValueError, match="cannot be padded"):
        padded_table(np.array([9, 3, 5]), 2)


@pytest.mark.parametrize(("entries", "width", "depth"), [
    (1065, 6, 2048), (852, 6, 1024), (683, 6, 1024), (1165, 11, 2048),  # block RAM: no more blocks
    (27, 6, 32), (16, 6, 16), (100, 11, 128), (1, 6, 1),  # logic, staying logic
    (5000, 9, 5000), (3000, 18, 3000), (129, 11, 256)])  # 3 blocks of 2048x9, not 4; 3 of 1024x18, not 4
def test_table_depth_pads_to_a_power_of_two_without_more_block_ram(entries: int, width: int,
                                                                    depth: int) -> None:
    assert table_depth(entries, width) == depth


def test_clamped_magnitude_is_the_absolute_value_clamped() -> None:
    m = Module()
    cases = []
    for shape in (signed(2), signed(4), signed(5), signed(6), unsigned(1), unsigned(3), unsigned(5)):
        for last in (0, 1, 2, 3, 5, 7, 8, 15, 16, 20, 31):
            x, y = Signal(shape), Signal(range(last + 1))
            m.d.comb += y.eq(clamped_magnitude(x, last))
            cases.append((x, y, last))
    wrong = []

    async def bench(ctx: Any) -> None:
        for x, y, last in cases:
            shape = x.shape()
            low = -(1 << (shape.width - 1)) if shape.signed else 0
            for v in range(low, low + (1 << shape.width)):
                ctx.set(x, v)
                if ctx.get(y) != min(abs(v), last):
                    wrong.append((shape, last, v, ctx.get(y)))

    sim = Simulator(m)
    sim.add_testbench(bench)
    sim.run()
    assert wrong == []


def test_line_buffer_gives_each_pixels_column() -> None:
    height, width = 9, 7
    rng = np.random.default_rng(1)
    left = rng.integers(0, 256, (height, width), dtype=np.uint8)
    right = rng.integers(0, 256, (height, width), dtype=np.uint8)
    want_l, want_r = column_windows(left), column_windows(right)
    dut = LineBuffer(width=width)
    rnd = random.Random(2)

    async def bench(ctx):
        for y in range(height):
            for x in range(width):
                ctx.set(dut.en, 1)
                ctx.set(dut.col, x)
                ctx.set(dut.pixel, {"left": int(left[y, x]), "right": int(right[y, x])})
                await ctx.tick()
                ctx.set(dut.en, 0)
                for _ in range(rnd.choice([0, 0, 1, 3])):  # gaps: the column holds until the next pixel
                    if y >= 4:
                        assert [ctx.get(dut.column[i].left) for i in range(5)] == want_l[y - 4, x].tolist()
                    await ctx.tick()
                if y >= 4:
                    assert [ctx.get(dut.column[i].left) for i in range(5)] == want_l[y - 4, x].tolist()
                    assert [ctx.get(dut.column[i].right) for i in range(5)] == want_r[y - 4, x].tolist()

    run_sim(dut, bench)


def test_feature_filter_equals_host_feature_sums() -> None:
    image = np.random.default_rng(3).integers(0, 256, (7, 12), dtype=np.uint8)
    image[0:5, 0:5] = 255  # the extreme sums fit the widths
    image[2:7, 7:12] = 0
    image[5:7, 7:12] = 255
    want = feature_sums(image)
    cols = column_windows(image)
    dut = FeatureFilter()
    rnd = random.Random(4)

    async def bench(ctx):
        # As in a pipeline: each column is loaded, then shifted in while the next is loaded, with
        # random idle cycles (neither load nor shift) that must change nothing.
        order = [(y, x) for y in range(cols.shape[0]) for x in range(cols.shape[1])]
        for k in range(len(order) + 1):
            ctx.set(dut.load, k < len(order))
            if k < len(order):
                for i in range(5):
                    ctx.set(dut.column[i], int(cols[order[k]][i]))
            ctx.set(dut.en, k > 0)
            await ctx.tick()
            ctx.set(dut.load, 0)
            ctx.set(dut.en, 0)
            for _ in range(rnd.choice([0, 0, 1, 2])):
                await ctx.tick()
            if k > 0 and order[k - 1][1] >= 4:
                y, x = order[k - 1]
                got = (ctx.get(dut.features.m25), ctx.get(dut.features.gh20), ctx.get(dut.features.gv20))
                assert got == (want.m25[y, x - 4], want.gh20[y, x - 4], want.gv20[y, x - 4]), (y, x)

    run_sim(dut, bench)


# --- The front end's words equal the host's ---

CASES = {
    # name: (dmax, machine options, frames as (height, width) list)
    "multi-beat": (8, dict(words_per_beat=6), [(8, 17)]),
    "odd-width": (3, dict(words_per_beat=9), [(6, 13)]),
    "narrowest-dmax0": (0, {}, [(5, 5)]),
    "narrowest-dmax4": (4, dict(words_per_beat=9), [(5, 9)]),
    "loaded-prior": (5, dict(words_per_beat=8, prior="loaded"), [(6, 11)]),
    "two-frames": (2, dict(words_per_beat=6), [(6, 9), (7, 9)]),
    "word-bits-6": (6, dict(words_per_beat=9, word_bits=6), [(6, 14)]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_frontend_words_equal_host_memory_words(name: str) -> None:
    dmax, options, shapes = CASES[name]
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, counter_max=2, **options)
    frames = [noisy_pair(h, w, seed=i) for i, (h, w) in enumerate(shapes)]
    got = run_frontend(FrontEnd(params=params, model=model, width=shapes[0][1]), frames)
    want = _host_words(frames, model, params)
    assert got.shape == want.shape
    assert np.array_equal(got, want), np.argwhere(got != want)[:5]


def test_frontend_words_on_a_crop_of_the_bundled_pair_with_back_pressure() -> None:
    left, right, _ = bundled_pair()
    y, x, h, w = 200, 300, 8, 24
    frames = [(left[y : y + h, x : x + w], right[y : y + h, x : x + w])]
    model = ModelParams(name="paper", dmax=10)
    params = stereo_machine_params(10, model=model, counter_max=4)
    got = run_frontend(FrontEnd(params=params, model=model, width=w),
                       frames, in_stall=0.3, out_stall=0.4, seed=5)
    assert np.array_equal(got, _host_words(frames, model, params))


def test_frontend_frame_start_marker_restarts_position() -> None:
    """A frame right after another, of another height: the ``first`` marker restarts the counters."""
    model = ModelParams(name="paper", dmax=3, sigma_m=4.0, p_nm0=0.05)
    params = stereo_machine_params(3, model=model, words_per_beat=6)
    frames = [noisy_pair(9, 10, seed=7), noisy_pair(5, 10, seed=8), noisy_pair(6, 10, seed=9)]
    got = run_frontend(FrontEnd(params=params, model=model, width=10),
                       frames, in_stall=0.2, out_stall=0.2, seed=1)
    assert np.array_equal(got, _host_words(frames, model, params))


# --- The whole StereoMachine against the model fed with the host's words ---

@pytest.mark.parametrize("counter_max", [1, 16])
def test_stereo_machine_results_equal_the_model(counter_max: int) -> None:
    left, right, _ = random_dot_stereogram(height=8, width=20, background=2, square=4, seed=3)
    frames = [(left, right), noisy_pair(6, 20, seed=4)]
    model = ModelParams(name="paper", dmax=5)
    params = stereo_machine_params(5, model=model, counter_max=counter_max, max_cycles=3000)
    got, _ = run_stereo(StereoMachine(params=params, model=model, width=20, fifo_pixels=2), frames,
                        in_stall=0.2, out_stall=0.3, seed=6)
    assert_same_results(got, MachineModel(params).run(_host_words(frames, model, params)))


def test_stereo_machine_hides_loading_and_filtering() -> None:
    """Without stalls the wall clock is the machine's per-pixel cycles (compute cycles and each
    run's bubble, ``pixel_wall_cycles``) plus the line ends' pixels that no run covers: the front
    end keeps the shadow memory full."""
    height, width, dmax = 6, 30, 6
    frames = [noisy_pair(height, width, seed=11)]
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, counter_max=16, max_cycles=3000)
    got, wall = run_stereo(StereoMachine(params=params, model=model, width=width), frames)
    compute = int(got.cycles.sum())
    per_pixel = int(pixel_wall_cycles(params, got.cycles, got.timeout).sum())
    # Lines 0-3 (4 x width pixels) and the first dmax + 4 pixels of a line run no machine; plus
    # the pipeline's latency to the first result (4 front-end stages, the word generator's
    # difference and address registers; the machine writes a beat the cycle after its
    # handshake). Everything else must overlap the runs.
    startup = 4 * width + dmax + 4 + 4 + 2 + params.beats_per_pixel + LOAD_LATENCY + 2
    print(f"\nwall {wall}, compute {compute}, per pixel {per_pixel}, startup bound {startup}")
    assert compute + len(got) <= wall <= per_pixel + startup + (height - 4) * (dmax + 4)


# --- Parameters ---

def test_parameters_are_validated_up_front() -> None:
    model = ModelParams(name="paper", dmax=4)
    ok = stereo_machine_params(4, model=model)
    with pytest.raises(ParameterError, match="words_per_beat"):
        FrontEnd(params=MachineParams.for_disparity(4, words_per_beat=16), model=model, width=20)
    with pytest.raises(ParameterError, match="width"):
        StereoMachine(params=ok, model=model, width=8)
    with pytest.raises(ParameterError, match="width"):
        StereoMachine(params=ok, model=model, width=MAX_WIDTH + 1)
    with pytest.raises(ParameterError, match="rows"):
        StereoMachine(params=stereo_machine_params(5, model=model.replace(dmax=5)), model=model, width=20)
    with pytest.raises(ParameterError, match="fifo_pixels"):
        StereoMachine(params=ok, model=model, width=20, fifo_pixels=0)
    with pytest.raises(ParameterError, match="p_nm0"):
        StereoMachine(params=dataclasses.replace(ok, word_bits=3),
                      model=ModelParams(name="paper", dmax=4, p_nm0=0.01), width=20)
    with pytest.raises(TypeError, match="model"):
        StereoMachine(params=ok, model={"dmax": 4}, width=20)  # type: ignore[arg-type]
    top = StereoMachine(params=ok, model=model, width=9)
    assert (top.params, top.model, top.width, top.fifo_pixels) == (ok, model, 9, 8)


@pytest.mark.parametrize("machines", [1, 2])
def test_blocks_build_and_return_their_nets(machines: int) -> None:
    """The hooks the formal wrappers read instead of Amaranth's internals: each block's ``build`` gives its
    module and the nets it built (the blocks' own signals, new ones each time: no block keeps them), and
    the pipeline class ``FrontEnd`` builds (a subclass's ``build`` is what elaborates)."""
    model = ModelParams(name="paper", dmax=4)
    params = stereo_machine_params(4, model=model)
    built: list[PipelineNets] = []

    class Recorded(FeaturePipeline):
        def build(self, platform: object) -> tuple[Module, PipelineNets]:
            m, nets = super().build(platform)
            built.append(nets)
            return m, nets

    class Front(FrontEnd):
        feature_pipeline = Recorded

    top = StereoMachine(params=params, model=model, width=20, machines=machines)
    gen = WordGenerator(params=params, model=model)
    pipe = FeaturePipeline(model=model, width=20)
    for block in (top, gen, pipe):
        assert not hasattr(block, "nets")
        (m1, n1), (m2, n2) = block.build(None), block.build(None)
        assert isinstance(m1, Module) and n1 is not n2
        Fragment.get(m1, None), Fragment.get(m2, None)  # (their submodules elaborated: none left unused)
    top_module, n = top.build(None)
    Fragment.get(top_module, None)
    assert len(n.machines) == len(n.loads) == machines
    assert all(isinstance(mc, BayesianMachine) for mc in n.machines)
    assert isinstance(n.frontend, FrontEnd if machines == 1 else FeaturePipeline)
    fifo = n.loads[0]
    assert fifo.buffer.depth == top.fifo_pixels * params.beats_per_pixel + 1
    assert [s.name for s in (fifo.used, fifo.write, fifo.read)] == (
        ["used", "write", "read"] if machines == 1 else ["beats0_used", "beats0_write", "beats0_read"])
    (gen_module, words), (pipe_module, counters) = gen.build(None), pipe.build(None)
    Fragment.get(gen_module, None), Fragment.get(pipe_module, None)
    assert (words.beat.name, words.active.name, words.take.name) == ("beat", "active", "take")
    assert counters.cur_col.name == "cur_col"
    Fragment.get(Front(params=params, model=model, width=20), None)
    assert len(built) == 1
    pos = built[0]
    names = [s.name for s in (pos.col, pos.line, pos.cur_col, pos.cur_line)]
    assert names == ["col", "line", "cur_col", "cur_line"]


def test_back_pressure_reaches_the_pixel_input() -> None:
    """With the result stream blocked, the machine, the FIFO and then the pixel input stop; once it
    is released every result arrives, equal to the model's."""
    from amaranth.sim import Simulator

    from bayesmachine.sim.results import decode_results
    from bayesmachine.sim.stereo_testbench import frame_beats

    dmax, width, height = 2, 12, 7
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, counter_max=2, max_cycles=500)
    left, right = noisy_pair(height, width, seed=12)
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=1)
    beats = frame_beats(left, right)
    taken: list[int] = []
    results: list[int] = []

    async def feeder(ctx):
        raw = top.pixels.payload.as_value()
        for i, beat in enumerate(beats):
            ctx.set(top.pixels.valid, 1)
            ctx.set(raw, beat)
            await ctx.tick().until(top.pixels.ready)
            taken.append(i)
        ctx.set(top.pixels.valid, 0)

    async def collector(ctx):
        ctx.set(top.result.ready, 0)
        await ctx.tick().repeat(400)  # blocked long enough for everything upstream to fill
        stalled_at = len(taken)
        await ctx.tick().repeat(100)
        assert len(taken) == stalled_at < len(beats)  # the input has stopped
        # Held from the first output pixel (index 4 * width + dmax + 4) on, at most: 9 output pixels
        # (one beat each here) in the result register, the running pixel, the shadow memory, the
        # FIFO (one pixel and its output register), the word generator's stream, address and
        # difference registers and its pixel; past the line's 6 output pixels, the next line's non-output
        # start; then the front end's three pipeline stages.
        first_output = 4 * width + dmax + 4
        per_line = width - 4 - dmax
        assert params.beats_per_pixel == 1 and per_line < 9
        assert first_output + 3 <= stalled_at <= first_output + 9 + (width - per_line) + 3
        raw = top.result.payload.as_value()
        ctx.set(top.result.ready, 1)
        while len(results) < (height - 4) * (width - 4 - dmax):
            _, _, valid, payload = await ctx.tick().sample(top.result.valid, raw)
            if valid:
                results.append(payload)

    sim = Simulator(top)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    want = MachineModel(params).run(_host_words([(left, right)], model, params))
    assert_same_results(decode_results(params, results), want)


@pytest.mark.parametrize("rng", ["external", "smtj"])
def test_stereo_machine_with_external_random_numbers(rng: str) -> None:
    """An off-chip source (``external``, and ``smtj``, whose inner port was once left undriven): the
    machine's entropy port is the StereoMachine's, sampled on compute cycles."""
    from amaranth.sim import Simulator

    from bayesmachine.sim.packing import pack_numbers
    from bayesmachine.sim.results import decode_results
    from bayesmachine.sim.stereo_testbench import frame_beats

    dmax, width, height = 3, 11, 6
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, counter_max=3, rng=rng, max_cycles=400)
    left, right = noisy_pair(height, width, seed=13)
    numbers = np.random.default_rng(14).integers(0, params.word_one, size=(4000, params.operators))
    top = StereoMachine(params=params, model=model, width=width)
    n_out = (height - 4) * (width - 4 - dmax)
    results: list[int] = []

    async def feeder(ctx):
        raw = top.pixels.payload.as_value()
        for beat in frame_beats(left, right):
            ctx.set(top.pixels.valid, 1)
            ctx.set(raw, beat)
            await ctx.tick().until(top.pixels.ready)
        ctx.set(top.pixels.valid, 0)

    packed = pack_numbers(params, top.entropy.shape(), numbers)

    async def entropy(ctx):
        t = 0
        while True:
            ctx.set(top.entropy.as_value(), packed[t])
            _, _, taken = await ctx.tick().sample(top.entropy_ready)
            t += int(taken)

    async def collector(ctx):
        ctx.set(top.result.ready, 1)
        raw = top.result.payload.as_value()
        while len(results) < n_out:
            _, _, valid, payload = await ctx.tick().sample(top.result.valid, raw)
            if valid:
                results.append(payload)

    sim = Simulator(top)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(entropy, background=True)
    sim.add_testbench(collector)
    sim.run()
    want = MachineModel(params).run(_host_words([(left, right)], model, params), numbers)
    assert_same_results(decode_results(params, results), want)


def test_a_truncated_frame_leaves_nothing_behind() -> None:
    """A frame cut off in the middle of a line, then a whole frame: the cut frame's output pixels so
    far are the host's, and the next frame's words are as if it came first (the ``first`` marker)."""
    from bayesmachine.sim.stereo_testbench import frame_beats, run_frontend_beats

    dmax, width = 2, 10
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, words_per_beat=6)
    cut_left, cut_right = noisy_pair(7, width, seed=15)
    whole = noisy_pair(6, width, seed=16)
    keep = 6 * width + 8  # line 6 (map row 2) stops after image column 7: map columns 2..3 done
    beats = frame_beats(cut_left, cut_right)[:keep] + frame_beats(*whole)
    cut_words = _host_words([(cut_left, cut_right)], model, params)
    per_line = width - 4 - dmax
    want = np.concatenate([cut_words[: 2 * per_line + 2], _host_words([whole], model, params)])
    got = run_frontend_beats(FrontEnd(params=params, model=model, width=width), beats, len(want),
                              in_stall=0.2, out_stall=0.2)
    assert np.array_equal(got, want)


def test_front_end_takes_the_census_model_on_whole_rows_per_lane():
    from bayesmachine.hdl.frontend.words import check_frontend_params

    model = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    check_frontend_params(MachineParams.for_disparity(6, columns=4, words_per_beat=8),
                          model)  # 2 rows per beat
    with pytest.raises(ParameterError, match=r"words_per_beat \(6\) must be a multiple of the loaded"):
        check_frontend_params(MachineParams.for_disparity(6, columns=4, words_per_beat=6), model)
