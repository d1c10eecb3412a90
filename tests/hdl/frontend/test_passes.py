# amaranth: UnusedElaboratable=no
"""A model's passes on chip: every pass a word generator and a machine of its own, fed from the one
feature pipeline (``hdl.frontend.passes``), and the consistency column's test.

Blocks against their twins (``ConsistencyTest`` against ``lr_consistent``, ``PassFeeder`` against the
delay and flush order), the front end's words of every pass against the host's (``pass_words``), and
``StereoMachine`` against the model run as the host runs the passes (``conftest.passes_model``), every
pass's results, with random stalls on every stream: census-lr, and a census-lr-like model defined in
the tests (``conftest.lr_like``: its passes and columns from its definition, a right-reference pass
named ``mirror`` its consistency column reads and a left-reference pass nothing reads).
"""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Iterator
from types import SimpleNamespace

import numpy as np
import pytest
from amaranth.hdl import Fragment
from conftest import (
    assert_passes_equal_the_model,
    assert_same_results,
    noisy_pair,
    own_options,
    passes_model,
    registered,
    run_sim,
)

from bayesmachine.columns import (
    Census,
    GradH,
    GradV,
    Mean,
    Source,
    consistency,
    lr_consistent,
    lr_unknown,
)
from bayesmachine.hdl.frontend import passes
from bayesmachine.hdl.frontend.delayline import tapped_line
from bayesmachine.hdl.frontend.filters import feature_layout
from bayesmachine.hdl.frontend.lanes.consistency import ConsistencyTest
from bayesmachine.hdl.frontend.passes import PassFeeder, fused_shares
from bayesmachine.hdl.frontend.shared import SharedSums
from bayesmachine.hdl.frontend.stereo import (
    FrontEnd,
    StereoMachine,
    check_stereo_machine,
    stereo_machine_params,
)
from bayesmachine.hdl.frontend.words import WordGenerator, generator_signature, pass_params
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import pass_grid, pass_words
from bayesmachine.models import CENSUS, ModelDef, ModelParams, PassDef
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion
from bayesmachine.sim.stereo_testbench import pass_pixels, run_frontend_passes, run_stereo_passes

# Whole StereoMachines under Amaranth's simulator: the pysim tier (tests/conftest.py).
pytestmark = pytest.mark.pysim


def _crop_and_noise(model: ModelParams, width: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Two frames of ``width`` pixels back to back: 3 output rows of the bundled pair, 2 of noise."""
    left, right, _ = bundled_pair()
    crop = (slice(250, 250 + 2 * model.margin + 3), slice(200, 200 + width))
    return [(np.ascontiguousarray(left[crop]), np.ascontiguousarray(right[crop])),
            noisy_pair(2 * model.margin + 2, width, seed=seed)]


def _lr(dmax: int, **fields: object) -> ModelParams:
    return ModelParams(dmax=dmax, name="census-lr", **fields)


# A consistency column reading a pass with the left image as reference: not on chip.
LEFT_FED = ModelDef(name="left-fed", description="a consistency column of a left-reference pass",
                    columns=(Mean, GradH, GradV, Census, consistency("right")),
                    passes=(PassDef(name="right", model="census", reference="left", machine_index=1),))

# census's both ways, nothing reading the right pass's MAPs: the own pass's scans may run right behind the
# right pass's sums (census-lr's wait for the right pass's MAPs).
BOTH_WAYS = ModelDef(name="both-ways", description="census with the right image as reference beside it",
                     columns=CENSUS.columns, switches=CENSUS.switches,
                     passes=(PassDef(name="right", model="census", reference="right", machine_index=1),))


@pytest.fixture
def defined(lr_like: ModelDef) -> Iterator[None]:
    """The models defined here and ``lr-like`` (conftest), known by name for the test."""
    with registered(LEFT_FED, BOTH_WAYS):
        yield


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


def _feed(dut: PassFeeder, inputs: list[dict], seed: int, stall: float) -> list:
    """``inputs`` through the feeder, each side stalled at random with probability ``stall``; its outputs
    until, every input taken, it offers none."""
    from amaranth.sim import Simulator

    rnd = random.Random(seed)
    got: list = []
    fed = [False]

    async def feeder(ctx):
        for payload in inputs:
            ctx.set(dut.i.valid, 1)
            ctx.set(dut.i.payload, payload)
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)
            while rnd.random() < stall:
                await ctx.tick()
        fed[0] = True

    async def sink(ctx):
        idle = 0
        while idle < 2:
            ready = rnd.random() >= stall
            ctx.set(dut.o.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            if valid and ready:
                got.append(payload)
            idle = idle + 1 if fed[0] and not valid else 0

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(sink)
    sim.run()
    return got


def _feeder_twin(inputs: list[dict], got: list, dmax: int) -> int:
    """The right feeder's rule, checked on its outputs ``got`` (``_feed``'s): every input pixel once, in
    order, each on a step of its own or (outside the output region) with a flush pixel; after an output
    row's last pixel Dmax flush pixels k = 1..Dmax, ``row_start`` 0, the row's ``first_row``; each step
    writes the right features of its pixel (0: a flush pixel alone) into the delay line, and its
    reference is the entry written Dmax steps back; once a flush pixel has taken a pixel, every later one
    of the flush does (no flush entry between the next row's pixels). Returns the pixels that went with
    a flush pixel."""
    refs: list[int] = []
    k, flush, row_first, absorbed, taking = 0, 0, 0, 0, False
    for g in got:
        if flush:  # the flush pixel of the row just ended, with the next pixel if one came
            with_pixel = g.right.m25 != 0
            assert (g.output, g.flush, g.row_start, g.first_row) == (1, dmax + 1 - flush, 0, row_first)
            assert with_pixel or not taking, "a flush pixel without one after one with one"
            taking = with_pixel
            if with_pixel:
                assert g.right.m25 == 100 + k and not inputs[k]["output"], k
                refs.append(inputs[k]["right"]["m25"])
                k, absorbed = k + 1, absorbed + 1
            else:
                refs.append(0)
            flush -= 1
        else:
            x = inputs[k]
            assert (g.right.m25, g.output, g.flush, g.row_start, g.first_row) == (
                100 + k, x["output"], 0, x["row_start"], x["first_row"]), k
            refs.append(x["right"]["m25"])
            if x["output"] and x["line_end"]:
                flush, row_first, taking = dmax, x["first_row"], False
            k += 1
        if len(refs) > dmax:
            assert g.left.m25 == refs[-1 - dmax], len(refs)
    assert k == len(inputs) and not flush
    return absorbed


@pytest.mark.parametrize("stall", [0.0, 0.3])
@pytest.mark.parametrize("dmax", [1, 2, 3, 5])
def test_right_reference_feeder_delays_the_reference_and_flushes_each_output_row(dmax: int,
                                                                                  stall: float) -> None:
    """Per input pixel one step whose reference (``left``) is the right features Dmax pixels back; after
    an output row's last pixel, Dmax flush pixels k = 1..Dmax continuing the delay line (its circular
    buffer wraps several times, write-through at Dmax 1), ``row_start`` 0 and the row's ``first_row``,
    each taking the next row's pixel outside the output region with it when one is there (without
    stalls: every one of them)."""
    dut = PassFeeder(reference="right", dmax=dmax, features=feature_layout(24),
                     flags={"row_start": 1, "first_row": 1})
    n, line_end = 21, {6, 13, 20}
    inputs = [{"left": {"m25": 100 + k}, "right": {"m25": k + 1, "census": k}, "output": int(k % 7 >= dmax),
               "line_end": int(k in line_end), "row_start": int(k % 7 == dmax), "first_row": int(k < 7)}
              for k in range(n)]
    absorbed = [_feeder_twin(inputs, _feed(dut, inputs, seed=1 + dmax + s, stall=stall), dmax)
                for s in range(3)]
    # Without stalls the first two rows' flushes take the next rows' Dmax pixels outside the output
    # region (the last row's has none); with them, some.
    assert absorbed == [2 * dmax] * 3 if not stall else 0 < sum(absorbed) <= 6 * dmax


def test_left_reference_feeder_passes_the_pixels_on() -> None:
    """The left image as reference: the pixel as it is (combinational), the handshake passed through."""
    dut = PassFeeder(reference="left", dmax=3, features=feature_layout(24), flags={"first_row": 1})
    assert "flush" not in dut.o.payload.shape().members

    async def bench(ctx):
        for k in range(6):
            ctx.set(dut.i.payload, {"left": {"m25": k}, "right": {"gv20": -k}, "output": k % 2,
                                    "first_row": k % 3 == 0, "line_end": k == 5})
            ctx.set(dut.i.valid, k % 4 != 1)
            ctx.set(dut.o.ready, k % 3 != 2)
            await ctx.delay(1e-9)
            o = ctx.get(dut.o.payload)
            assert (o.left.m25, o.right.gv20, o.output, o.first_row) == (k, -k, k % 2, int(k % 3 == 0))
            assert (ctx.get(dut.o.valid), ctx.get(dut.i.ready)) == (int(k % 4 != 1), int(k % 3 != 2))

    run_sim(dut, bench, clock=False)


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"reference": "up"}, ParameterError, "reference must be one of left, right"),
    ({"reference": 1}, TypeError, "reference"),
    ({"dmax": 2.0}, TypeError, "dmax"),
    ({"dmax": 4095}, ParameterError, "dmax"),
    ({"features": 24}, TypeError, "features"),
    ({"flags": {"consult": 1}}, ParameterError, "flags: a right-reference pass's pixels carry row_start"),
    ({"flags": {"flush": 1}}, ParameterError, "not flush"),
])
def test_pass_feeder_checks_its_parameters(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        PassFeeder(**{"reference": "right", "dmax": 2, "features": feature_layout(24), **kwargs})


# --- The front end's words of every pass equal the host's ---

def _host_words(model: ModelParams, params, frames, maps: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every pass's words, row by row, each column fed from the stand-in MAPs ``maps`` (by pass name)."""
    out: dict[str, list] = {p.name: [] for p in model.passes}
    at = dict.fromkeys(out, 0)
    for lf, rf in frames:
        fl, fr = model_planes(lf, model), model_planes(rf, model)
        region = OutputRegion.of_features(fl.shape, model.dmax)
        grids = {p.name: pass_grid(p, region) for p in model.passes}
        for y in range(region.shape[0]):
            for p in model.passes:
                pp, w = pass_params(model, params, p.name), grids[p.name].width
                above = None if p.name not in maps else (
                    np.full(w, -1) if y == 0 else maps[p.name][at[p.name] - w: at[p.name]])
                results = {src: maps[src][at[src]: at[src] + grids[src].width][None]
                           for src in grids if src != p.name and src in maps}
                out[p.name].append(pass_words(p, fl, fr, pp, rows=slice(y, y + 1), above=above,
                                              results=results))
            for p in model.passes:
                at[p.name] += grids[p.name].width
    return {name: np.concatenate(words) for name, words in out.items()}


@pytest.mark.parametrize(("name", "fields", "width", "delay"), [
    ("census-lr", {"dmax": 3}, 15, 6),
    ("census-lr", {"dmax": 7}, 16, 6),  # Dmax >= 6 lanes: the right pass's entry 0 (newest pixel) in beat 1
    ("census-lr", {"dmax": 2, "lr_right_nomatch": False, "lr_neutral": False, "lr_nomatch": False,
                   "lr_tolerance": 0}, 11, 25),  # 2 output pixels per row
    ("lr-like", {"dmax": 3}, 14, 8),
    ("both-ways", {"dmax": 16}, 30, 0),  # the own pass's scans right behind the right pass's sums
])
@pytest.mark.usefixtures("defined")
def test_every_pass_words_equal_the_host_words(name: str, fields: dict, width: int, delay: int) -> None:
    """With stand-in results for every machine whose MAPs the front end reads (given late, up to
    ``delay`` cycles after a pixel's words), every pass's words are the host's (``pass_words``: an above
    column from the stand-in MAPs of the pass's row before, a pass column from those of the row of the
    pass it reads), and a row's first pixel carries ``line_start`` where the machine has a feedback
    column."""
    model = ModelParams(name=name, **fields)
    params = stereo_machine_params(model.dmax, model=model, counter_max=2)
    frames = [noisy_pair(9, width, seed=4), noisy_pair(8, width, seed=5)]
    rng = np.random.default_rng(3)
    maps = {p.name: rng.integers(-1, model.dmax + 1, pass_pixels(frames, model, p.name))
            for p in model.passes}
    front = FrontEnd(params=params, model=model, width=width)
    # The MAPs the front end reads: a line of MAPs' pass's own, a pass column's pass's.
    read = {q.name for q in model.passes if any(c.source is Source.ABOVE for c in q.columns)}
    read |= {c.feeds_from for q in model.passes for c in q.columns if c.source is Source.PASS}
    got = run_frontend_passes(front, frames, {n: maps[n] for n in maps if n in read},
                              in_stall=0.2, out_stall=0.2, result_delay=delay, seed=3)
    want = _host_words(model, params, frames, maps)
    assert set(got) == {p.name for p in model.passes}
    for p in model.passes:
        words, flags = got[p.name]
        assert words.shape == want[p.name].shape, p.name
        assert np.array_equal(words, want[p.name]), (p.name, np.argwhere(words != want[p.name])[:5])
        if pass_params(model, params, p.name).feedback_columns:
            row = pass_grid(p, OutputRegion.of_model(frames[0][0].shape, model)).width
            assert (flags[:, 0] == (np.arange(len(flags)) % row == 0)).all()
    right = want[next(q.name for q in model.passes if q.reference == "right")]
    assert (right[:, : model.dmax + 1, 1:] == 0).any()  # lanes past the last output column: word 0


# --- StereoMachine against the model run as the host runs the passes ---

CASES = {
    # name: (model, frames (height, width) or "noisy", fifo pixels, counter max)
    "bundled-crop": (("census-lr", {"dmax": 3}), [(9, 18), "noisy"], 2, 6),
    "narrow-deep-fifo": (("census-lr", {"dmax": 2, "lr_tolerance": 0}), [(8, 11)], 8, 4),
    # Per column: the fused column's best row fires every cycle, so its right pass never reaches 9 cycles.
    "no-nomatch-row-right-watchdog": (("census-lr", {"dmax": 3, "lr_nomatch": False, "fuse_columns": False,
                                                     "lr_right_max_cycles": 9}), [(8, 14)], 3, 6),
    "per-column": (("census-lr", {"dmax": 3, "fuse_columns": False}), [(9, 18), "noisy"], 2, 6),
    "census5": (("census-lr", {"dmax": 2, "census_window": 5}), [(7, 12), "noisy"], 2, 5),
    # The rules: no right no-match row, a lane without a right MAP gets beta (not neutral).
    "issue-rules": (("census-lr", {"dmax": 3, "lr_right_nomatch": False, "lr_neutral": False}),
                    [(9, 16)], 2, 6),
    "dmax0": (("census-lr", {"dmax": 0}), [(8, 8)], 2, 4),
    # Two beats per pixel in both passes (8 rows, 6 a beat: the last beat half empty); the cases above
    # take a pixel in one beat.
    "two-beats": (("census-lr", {"dmax": 6}), [(9, 20), "noisy"], 2, 6),
    "lr-like": (("lr-like", {"dmax": 3}), [(8, 14)], 2, 4),
}


# The default tier keeps the cases of each mechanism it alone exercises; these three, the longest to
# simulate, run in the slow tier.
SLOW_CASES = ("no-nomatch-row-right-watchdog", "issue-rules", "lr-like")


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c
                                  for c in CASES])
@pytest.mark.usefixtures("defined")
def test_stereo_machine_passes_equal_the_model(case: str) -> None:
    (name, fields), shapes, fifo_pixels, counter_max = CASES[case]
    model = ModelParams(name=name, **fields)
    height, width = shapes[0]
    left, right, _ = bundled_pair()
    crop = (slice(150, 150 + height), slice(400, 400 + width))
    frames = [(np.ascontiguousarray(left[crop]), np.ascontiguousarray(right[crop]))]
    if len(shapes) > 1:
        frames.append(noisy_pair(height - 1, width, seed=1))
    params = stereo_machine_params(model.dmax, model=model, counter_max=counter_max, max_cycles=400)
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=fifo_pixels)
    assert set(top.signature.members) >= {f"{p.name}_result" for p in model.passes[:-1]}
    want = assert_passes_equal_the_model(top, frames, model, params, seed=6)
    assert case != "no-nomatch-row-right-watchdog" or want["right"].timeout.any()  # the watchdog fires


def test_census_lr_on_chip_parameters() -> None:
    model = _lr(4)
    params = stereo_machine_params(4, model=model)
    # Fused: the data columns are the fused column and lr; loaded, the above prior too.
    assert params.columns == 2 and params.loaded_columns == 3 and params.words_per_beat % 3 == 0
    rp = pass_params(model, params, "right")
    assert rp.columns == 1 and rp.seed != params.seed and rp.words_per_beat % rp.loaded_columns == 0
    assert pass_params(model, params, "left") is params
    # The right pass takes the left pass's rows per beat: a pixel in as many beats, one with a whole pixel.
    for words, right_words, beats in ((6 * 3, 6 * 2, 1), (3 * 3, 3 * 2, 2), (2 * 3, 2 * 2, 3)):
        left = stereo_machine_params(4, model=model, words_per_beat=words)
        right = pass_params(model, left, "right")
        assert (right.words_per_beat, right.beats_per_pixel) == (right_words, beats)
        assert left.beats_per_pixel == beats
    check_stereo_machine(params, model, 11)
    with pytest.raises(ParameterError, match="rng must be an on-chip random source"):
        check_stereo_machine(stereo_machine_params(4, model=model, rng="smtj"), model, 11)
    with pytest.raises(ParameterError, match="width"):
        FrontEnd(params=params, model=model, width=10)


@pytest.mark.usefixtures("defined")
def test_what_the_passes_on_chip_cannot_do_is_one_error_naming_the_pass() -> None:
    """A consistency column reading a left-reference pass, two columns of one pass on one stream: each one
    ParameterError naming the pass, never a design (several machines with a declared pass: its rows are
    dealt too)."""
    model = ModelParams(name="left-fed", dmax=3)
    params = stereo_machine_params(3, model=model)
    with pytest.raises(ParameterError, match="reads the right pass's MAPs; on chip it reads a pass with the "
                                             "right image as reference") as e:
        check_stereo_machine(params, model, 16)
    assert e.value.parameter == "model"
    lr = ModelParams(name="lr-like", dmax=3)
    assert check_stereo_machine(stereo_machine_params(3, model=lr), lr, 16, machines=2) is None  # dealt too
    with pytest.raises(ValueError, match="pass name 'left': each pass needs a name of its own"):
        ModelDef(name="same-name", description="a declared pass named left", columns=(Mean, GradH, GradV),
                 passes=(PassDef(name="left", model="paper", reference="right", machine_index=1),))
    own = lr.passes[-1]
    lanes = own.columns[-1]
    twice = SimpleNamespace(name="left", columns=(*own.columns, lanes), model=lr, reference="left")
    with pytest.raises(ParameterError, match="the left pass's lr column takes the port mirror_maps, which "
                                             "its lr column has already"):
        generator_signature(stereo_machine_params(3, model=lr), lr, twice)


# integrator, words per beat (3 loaded columns) -> lane rows per beat, beats per pixel, the delay line's kind
BEATS = {("log", 42): (14, 1, True), ("stochastic", 21): (7, 2, True), ("log", 6): (2, 7, False)}


@pytest.mark.parametrize(("integrator", "words_per_beat"),
                         [pytest.param(*k, marks=pytest.mark.slow) if k == ("log", 42) else k for k in BEATS])
def test_census_lr_at_any_words_per_beat_equals_the_model(integrator: str, words_per_beat: int) -> None:
    """census-lr (fused) with a pixel's every row in one beat, in two beats, or in seven beats of two rows:
    the word generators' delay lines as taps (wide beats) or as banks (``tapped_line``), the left and
    the right reference; every pass's results equal the model's, random stalls on both streams."""
    dmax = 12
    model = ModelParams(name="census-lr", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, integrator=integrator, words_per_beat=words_per_beat,
                                   **own_options(integrator, counter_max=6))
    rows, beats, tapped = BEATS[integrator, words_per_beat]
    assert (params.words_per_beat // params.loaded_columns, params.beats_per_pixel) == (rows, beats)
    assert tapped_line(rows, beats) is tapped
    width = dmax + 2 * model.margin + 6
    frames = _crop_and_noise(model, width, seed=2)
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2)
    want = assert_passes_equal_the_model(top, frames, model, params, seed=2)
    assert set(want) == {"right", "left"} and len(np.unique(want["left"].map)) > 3


def _census_lr_clocks(dmax: int, beats: int, extra_width: int, extra_lines: int) -> int:
    """census-lr (log) at ``beats`` beats a pixel on a crop of the bundled pair (Dmax + 2k + ``extra_width``
    pixels, 2k + ``extra_lines`` lines) with no stalls: every result of both passes the model's; the
    frame's clocks."""
    model = ModelParams(name="census-lr", dmax=dmax)
    wpb = 3 * (dmax + 2) // beats
    params = stereo_machine_params(dmax, model=model, integrator="log", words_per_beat=wpb)
    assert params.beats_per_pixel == beats
    width = dmax + 2 * model.margin + extra_width
    left, right, _ = bundled_pair()
    crop = (slice(250, 250 + 2 * model.margin + extra_lines), slice(200, 200 + width))
    frame = (np.ascontiguousarray(left[crop]), np.ascontiguousarray(right[crop]))
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2)
    got, cycles = run_stereo_passes(top, [frame])
    want = passes_model([frame], model, params)
    for name in want:
        assert_same_results(got[name], want[name])
    print(f"\ncensus-lr, Dmax {dmax}, {width} x {frame[0].shape[0]}, {beats} beat(s) a pixel: {cycles}")
    return cycles


def test_census_lr_at_one_beat_a_pixel_keeps_the_rate() -> None:
    """census-lr (log) with a pixel in one beat: the own pass's pixels wait in a FIFO for the right pass's
    MAPs, which need Dmax pixels more and the right pass's generator and machine; with the FIFO only Dmax
    + 4 deep the pipeline waited for that latency at every pixel. The frame's clocks (no stalls) against
    the figure measured with the deeper FIFO (``PASS_LAG_PIXELS``)."""
    assert _census_lr_clocks(4, 1, 60, 3) <= 758  # measured; with the FIFO only Dmax + 4 deep: 848


def test_census_lr_rows_start_during_the_right_pass_flush() -> None:
    """census-lr (log) at two beats a pixel: the right pass's flush pixels at a row's end take the next
    row's first Dmax pixels (outside the output region) with them, so a row costs the right pass's
    W - 2k pixels of two clocks and about 2k + 5 clocks more, not Dmax + 2k + 5. The frame's clocks (no
    stalls) against the figure measured (885 when the next row waited for the flush)."""
    assert _census_lr_clocks(16, 2, 20, 6) <= 805  # measured


@pytest.mark.slow  # 95 % stalls: twenty times the clocks of a frame
def test_census_lr_equals_the_model_while_the_own_pass_lags() -> None:
    """census-lr (log) with the own pass's results stalled 95 % of the cycles: its FIFO fills, the input
    stops in the middle of the right pass's flushes, and a flush that has taken a pixel of the next row
    waits for the next (a flush entry between the row's pixels made its first pixels' words wrong: row
    5's here). Every result of both passes the model's."""
    dmax = 16
    model = ModelParams(name="census-lr", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, integrator="log", words_per_beat=12)
    left, right, _ = bundled_pair()
    frame = (left[150:166, 300:360].copy(), right[150:166, 300:360].copy())
    top = StereoMachine(params=params, model=model, width=60, fifo_pixels=8)
    got, _ = run_stereo_passes(top, [frame], out_stall={"left": 0.95}, max_cycles=10_000_000)
    want = passes_model([frame], model, params)
    for name in want:
        assert_same_results(got[name], want[name])


# --- The fused sums computed once (hdl.frontend.shared) ---

def _generator_blocks(gen: WordGenerator) -> set[str]:
    return {name for _, name, _ in Fragment.get(gen, None).subfragments}


@pytest.mark.parametrize("integrator", ["stochastic", "log"])
@pytest.mark.parametrize("name", ["census-lr", "census-sgm"])
def test_census_lr_computes_its_fused_sums_once(name: str, integrator: str) -> None:
    """The right pass computes the members' codes of the pairs both passes compare and writes their sums;
    the own pass reads them: its generator has no member energy table, the right pass's has every one
    (census-sgm: the sums its semi-global columns aggregate, each pass in its own direction)."""
    model = ModelParams(dmax=12, name=name)
    params = stereo_machine_params(12, model=model, integrator=integrator, words_per_beat=21)
    shares = fused_shares(model, params)
    assert {n: s.role for n, s in shares.items()} == {"right": "export", "left": "import"}
    assert (shares["left"].rows, shares["left"].beats, shares["left"].dmax) == (7, 2, 12)
    gens = {p.name: WordGenerator(params=pass_params(model, params, p.name), model=model, pass_name=p.name,
                                  output_columns=4, fused_share=shares[p.name]) for p in model.passes}
    tables = {f"table_{m}_energy" for m in ("m", "gh", "gv", "census")}
    assert tables <= _generator_blocks(gens["right"])
    assert not tables & _generator_blocks(gens["left"])
    unfused = _lr(12, fuse_columns=False)
    assert fused_shares(unfused, stereo_machine_params(12, model=unfused)) == {}


def test_fused_share_is_checked() -> None:
    model = _lr(6)
    params = stereo_machine_params(6, model=model, words_per_beat=12)
    share = fused_shares(model, params)
    right = pass_params(model, params, "right")
    with pytest.raises(TypeError, match="fused_share must be a FusedShare, not dict"):
        WordGenerator(params=params, model=model, output_columns=4, fused_share={})
    with pytest.raises(ParameterError, match="the left pass needs role 'import'") as e:
        WordGenerator(params=params, model=model, output_columns=4, fused_share=share["right"])
    assert e.value.parameter == "fused_share"
    with pytest.raises(ParameterError, match="the right pass needs 4 rows per beat and 2 beats"):
        WordGenerator(params=right, model=model, pass_name="right", output_columns=4,
                      fused_share=dataclasses.replace(share["right"], rows=8, beats=1))
    with pytest.raises(ParameterError, match="role must be one of export, import, got 'both'"):
        dataclasses.replace(share["right"], role="both")
    with pytest.raises(ParameterError, match="depth must be a power of two above 21"):
        dataclasses.replace(share["right"], depth=16)
    with pytest.raises(ParameterError, match="reader: a FusedShare of role 'import'"):
        SharedSums(writer=share["right"], reader=share["right"])


# left results stalled: the own pass lags, the right pass waits for room; right results stalled: the own
# pass waits for the right pass's sums
STALLS = {"own-lags": {"left": 0.97}, "right-lags": {"right": 0.9}, "both": {"left": 0.5, "right": 0.5}}


@pytest.mark.parametrize(("name", "stalls"), [
    *(pytest.param("census-lr", k, marks=pytest.mark.slow) if k == "own-lags" else ("census-lr", k)
      for k in STALLS),  # own-lags: 97 % stalls, the slow tier's
    ("census-sgm", "both"),  # the semi-global lanes aggregate the shared sums
])
def test_shared_sums_in_the_smallest_memory_equal_the_model(monkeypatch: pytest.MonkeyPatch, name: str,
                                                            stalls: str) -> None:
    """With the shared memories as small as allowed (32 positions at Dmax 6, 2 beats of 4 rows) each pass
    waits for the other where the memories bind; every pass's results equal the model's."""
    monkeypatch.setattr(passes, "shared_sums_depth",
                        lambda reach, dmax: 1 << (reach + 2 * dmax + 2).bit_length())
    dmax = 6
    model = ModelParams(dmax=dmax, name=name)
    params = stereo_machine_params(dmax, model=model, integrator="log", words_per_beat=12)
    assert fused_shares(model, params)["left"].depth == 32
    width = dmax + 2 * model.margin + 24
    frames = _crop_and_noise(model, width, seed=7)
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2)
    got, _ = run_stereo_passes(top, frames, in_stall=0.1, out_stall=STALLS[stalls], seed=5)
    want = passes_model(frames, model, params)
    for name in want:
        assert_same_results(got[name], want[name])
