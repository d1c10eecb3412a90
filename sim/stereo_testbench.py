"""Driving the front end and ``StereoMachine`` in Amaranth's simulator (tests, debugging).

Frames go in as pixel beats packed from ``pixel_in_layout()``; the front end's load beats and
the machine's results come out decoded from their layouts. Random ``valid`` / ``ready`` stalls on
both streams exercise the handshakes (results must not depend on them).
"""

from __future__ import annotations

import random
from collections.abc import Sequence

import numpy as np
from amaranth.sim import Simulator, SimulatorContext

from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine
from bayesmachine.hdl.signatures import beat_words, load_layout, pixel_in_layout
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sim.results import MachineResult, decode_results

__all__ = ["frame_beats", "line_starts_from_beats", "output_pixels", "run_frontend", "run_frontend_beats",
           "run_frontend_lr", "run_frontend_neighbour", "run_stereo", "run_stereo_lr", "words_from_beats"]


async def feed_stream(ctx: SimulatorContext, stream: object, beats: Sequence[int], rnd: random.Random,
                      in_stall: float) -> None:
    """Drive ``stream`` (valid/ready/payload) with ``beats``, holding valid low before a beat with
    probability ``in_stall`` per cycle (``rnd``): the testbenches' random input stalls."""
    raw = stream.payload.as_value()  # type: ignore[attr-defined]
    for beat in beats:
        while in_stall and rnd.random() < in_stall:
            ctx.set(stream.valid, 0)  # type: ignore[attr-defined]
            await ctx.tick()
        ctx.set(stream.valid, 1)  # type: ignore[attr-defined]
        ctx.set(raw, beat)
        await ctx.tick().until(stream.ready)  # type: ignore[attr-defined]
    ctx.set(stream.valid, 0)  # type: ignore[attr-defined]


async def collect_stream(ctx: SimulatorContext, stream: object, sink: list[int], expected: int,
                         rnd: random.Random, out_stall: float, max_cycles: int) -> int:
    """Take ``expected`` beats of ``stream`` into ``sink``, holding ready low with probability
    ``out_stall`` per cycle (``rnd``): the testbenches' random output stalls. Returns the clock
    cycles it took; more than ``max_cycles`` is an error (a design that never answers)."""
    raw = stream.payload.as_value()  # type: ignore[attr-defined]
    cycles = 0
    while len(sink) < expected:
        ready = not (out_stall and rnd.random() < out_stall)
        ctx.set(stream.ready, ready)  # type: ignore[attr-defined]
        _, _, valid, payload = await ctx.tick().sample(stream.valid, raw)  # type: ignore[attr-defined]
        cycles += 1
        if valid and ready:
            sink.append(payload)
        if cycles > max_cycles:
            raise RuntimeError(f"no complete output after {max_cycles} cycles ({len(sink)}/{expected})")
    return cycles


def frame_beats(left: np.ndarray, right: np.ndarray) -> list[int]:
    """A pair as raw pixel-stream beats in raster order, ``first`` set on the first pixel."""
    if left.shape != right.shape or left.ndim != 2:
        raise ValueError(f"a frame is two 2-D images of one shape, got {left.shape} and {right.shape}")
    layout = pixel_in_layout()
    beats = []
    for i, (lv, rv) in enumerate(zip(left.reshape(-1).tolist(), right.reshape(-1).tolist(), strict=True)):
        beats.append(layout.const({"left": lv, "right": rv, "first": int(i == 0)}).as_bits())
    return beats


def words_from_beats(params: MachineParams, beats: Sequence[int]) -> np.ndarray:
    """Load beats (raw) back into pixels' words, (P, rows, loaded_columns), decoded from the layout."""
    layout = load_layout(params)
    b = params.beats_per_pixel
    if len(beats) % b:
        raise ValueError(f"{len(beats)} beats is not a whole number of pixels ({b} beats each)")
    flat = []
    for raw in beats:
        view = beat_words(params, layout.from_bits(raw))
        flat.extend(int(view[lane]) for lane in range(params.words_per_beat))
    per_pixel = np.array(flat, np.int64).reshape(-1, b * params.words_per_beat)[:, : params.words_per_pixel]
    return per_pixel.reshape(-1, params.rows, params.loaded_columns)


def line_starts_from_beats(params: MachineParams, beats: Sequence[int]) -> np.ndarray:
    """The ``line_start`` flag of each beat of a neighbour-prior machine's load beats,
    (P, beats_per_pixel)."""
    layout = load_layout(params)
    flags = [int(layout.from_bits(raw).line_start) for raw in beats]
    return np.array(flags, np.int64).reshape(-1, params.beats_per_pixel)


def _simulate(dut: object, source: object, sink_stream: object, beats: list[int], expected: int,
              in_stall: float, out_stall: float, seed: int, max_cycles: int) -> tuple[list[int], int]:
    rnd = random.Random(seed)
    got: list[int] = []
    cycles = 0

    async def feeder(ctx: SimulatorContext) -> None:
        await feed_stream(ctx, source, beats, rnd, in_stall)

    async def collector(ctx: SimulatorContext) -> None:
        nonlocal cycles
        cycles = await collect_stream(ctx, sink_stream, got, expected, rnd, out_stall, max_cycles)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    return got, cycles


def output_pixels(frames: Sequence[tuple[np.ndarray, np.ndarray]], model: ModelParams) -> int:
    """The output pixels of ``frames`` for ``model`` (its output region's, ``bayesmachine.region``)."""
    k = model.margin
    return sum((lf.shape[0] - 2 * k) * (lf.shape[1] - 2 * k - model.dmax) for lf, _ in frames)


def run_frontend(front: FrontEnd, frames: Sequence[tuple[np.ndarray, np.ndarray]], *,
                 in_stall: float = 0.0, out_stall: float = 0.0, seed: int = 0,
                 max_cycles: int = 1_000_000) -> np.ndarray:
    """The words the front end writes for ``frames`` (pairs of (H, width) uint8 images), all frames'
    output pixels in order: (P, rows, loaded_columns)."""
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    return run_frontend_beats(front, beats, output_pixels(frames, front.model), in_stall=in_stall,
                              out_stall=out_stall, seed=seed, max_cycles=max_cycles)


def run_frontend_beats(front: FrontEnd, beats: list[int], pixels: int, *, in_stall: float = 0.0,
                       out_stall: float = 0.0, seed: int = 0, max_cycles: int = 1_000_000) -> np.ndarray:
    """The words of the first ``pixels`` output pixels the front end writes for raw pixel ``beats``."""
    expected = pixels * front.params.beats_per_pixel
    got, _ = _simulate(front, front.pixels, front.beats, beats, expected, in_stall, out_stall, seed,
                       max_cycles)
    return words_from_beats(front.params, got)


def run_stereo(top: StereoMachine, frames: Sequence[tuple[np.ndarray, np.ndarray]], *,
               in_stall: float = 0.0, out_stall: float = 0.0, seed: int = 0,
               max_cycles: int = 1_000_000) -> tuple[MachineResult, int]:
    """The machine's results for ``frames`` through ``StereoMachine`` and the clock cycles it took."""
    p = top.params
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    expected = output_pixels(frames, top.model)
    got, cycles = _simulate(top, top.pixels, top.result, beats, expected, in_stall, out_stall, seed,
                            max_cycles)
    res = decode_results(p, got) if got else MachineResult.empty(p.rows)
    return res, cycles


def run_stereo_lr(top: StereoMachine, frames: Sequence[tuple[np.ndarray, np.ndarray]], *,
                  in_stall: float = 0.0, out_stall: float = 0.0, seed: int = 0,
                  max_cycles: int = 1_000_000) -> tuple[MachineResult, MachineResult, int]:
    """A census-lr ``StereoMachine``'s results for ``frames``: the left pass's (the ``result`` stream,
    as :func:`run_stereo`), the right pass's (``right_result``, every right map column of every output
    row, raster order) and the clock cycles it took."""
    from bayesmachine.hdl.frontend.lr import right_pass_params

    p, model = top.params, top.model
    rp = right_pass_params(model, p)
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    expected = output_pixels(frames, model)
    k = model.margin
    right_expected = sum((lf.shape[0] - 2 * k) * (lf.shape[1] - 2 * k) for lf, _ in frames)
    rnd = random.Random(seed)
    got: list[int] = []
    right: list[int] = []
    cycles = 0

    async def feeder(ctx: SimulatorContext) -> None:
        await feed_stream(ctx, top.pixels, beats, rnd, in_stall)

    async def collector(ctx: SimulatorContext) -> None:
        nonlocal cycles
        raw = top.result.payload.as_value()
        right_raw = top.right_result.payload.as_value()
        while len(got) < expected or len(right) < right_expected:
            ready = not (out_stall and rnd.random() < out_stall)
            ctx.set(top.result.ready, ready)
            _, _, valid, payload, r_valid, r_payload = await ctx.tick().sample(
                top.result.valid, raw, top.right_result.valid, right_raw)
            cycles += 1
            if valid and ready:
                got.append(payload)
            if r_valid:
                right.append(r_payload)
            if cycles > max_cycles:
                raise RuntimeError(f"no complete output after {max_cycles} cycles ({len(got)}/{expected}, "
                                   f"right {len(right)}/{right_expected})")

    sim = Simulator(top)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    res = decode_results(p, got) if got else MachineResult.empty(p.rows)
    res_r = decode_results(rp, right) if right else MachineResult.empty(rp.rows)
    return res, res_r, cycles


def run_frontend_lr(front: FrontEnd, frames: Sequence[tuple[np.ndarray, np.ndarray]], maps: np.ndarray,
                    right_maps: np.ndarray, *, in_stall: float = 0.0, out_stall: float = 0.0,
                    result_delay: int = 0, seed: int = 0, max_cycles: int = 1_000_000
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A census-lr front end's words for ``frames``, both passes, with stand-ins for both machines'
    results: ``maps`` (one per output pixel) and ``right_maps`` (one per right pixel: every map column
    of every output row), -1 = none; each given after its pixel's last beat left, up to
    ``result_delay`` random cycles later (a right result only while ``right_room``). Returns the left
    pass's words and ``line_start`` flags, then the right pass's."""
    from bayesmachine.hdl.frontend.lr import right_pass_params

    p, model = front.params, front.model
    rp = right_pass_params(model, p)
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    n = output_pixels(frames, model)
    k = model.margin
    n_right = sum((lf.shape[0] - 2 * k) * (lf.shape[1] - 2 * k) for lf, _ in frames)
    maps, right_maps = np.asarray(maps).reshape(-1), np.asarray(right_maps).reshape(-1)
    if maps.shape != (n,) or right_maps.shape != (n_right,):
        raise ValueError(f"maps must hold one MAP per output pixel ({n}) and right_maps one per right pixel "
                         f"({n_right}), got {maps.shape} and {right_maps.shape}")
    rnd = random.Random(seed)
    got: list[int] = []
    got_right: list[int] = []

    async def feeder(ctx: SimulatorContext) -> None:
        await feed_stream(ctx, front.pixels, beats, rnd, in_stall)

    def results(sink: list[int], params: MachineParams, values: np.ndarray, take: object, map_: object,
                hit: object, room: object | None) -> object:
        async def bench(ctx: SimulatorContext) -> None:
            for i in range(len(values)):
                while len(sink) < (i + 1) * params.beats_per_pixel:  # the pixel's words have left
                    await ctx.tick()
                for _ in range(rnd.randint(0, result_delay)):
                    await ctx.tick()
                if room is not None:
                    while not ctx.get(room):
                        await ctx.tick()
                value = int(values[i])
                ctx.set(map_, max(0, value))
                ctx.set(hit, int(value >= 0))
                ctx.set(take, 1)
                await ctx.tick()
                ctx.set(take, 0)
        return bench

    def collector(stream_: object, sink: list[int], expected: int) -> object:
        async def bench(ctx: SimulatorContext) -> None:
            await collect_stream(ctx, stream_, sink, expected, rnd, out_stall, max_cycles)
        return bench

    sim = Simulator(front)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(results(got, p, maps, front.result_take, front.result_map, front.result_hit, None),
                      background=True)
    sim.add_testbench(results(got_right, rp, right_maps, front.right_take, front.right_map, front.right_hit,
                              front.right_room), background=True)
    sim.add_testbench(collector(front.right_beats, got_right, n_right * rp.beats_per_pixel), background=True)
    sim.add_testbench(collector(front.beats, got, n * p.beats_per_pixel))
    sim.run()
    return (words_from_beats(p, got), line_starts_from_beats(p, got),
            words_from_beats(rp, got_right), line_starts_from_beats(rp, got_right))


def run_frontend_neighbour(front: FrontEnd, frames: Sequence[tuple[np.ndarray, np.ndarray]], maps: np.ndarray,
                           *, in_stall: float = 0.0, out_stall: float = 0.0, result_delay: int = 0,
                           seed: int = 0, max_cycles: int = 1_000_000) -> tuple[np.ndarray, np.ndarray]:
    """A neighbour-prior front end's words and beats' ``line_start`` flags for ``frames``, with
    ``maps`` (one per output pixel, -1 = no match) standing in for the machine's results: the
    result of pixel k is given (``result_*``) after its last beat left, up to ``result_delay``
    random cycles later. Returns (words (P, rows, loaded_columns), flags (P, beats_per_pixel))."""
    p = front.params
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    n = output_pixels(frames, front.model)
    maps = np.asarray(maps).reshape(-1)
    if maps.shape != (n,):
        raise ValueError(f"maps must hold one MAP per output pixel ({n}), got {maps.shape}")
    expected = n * p.beats_per_pixel
    rnd = random.Random(seed)
    got: list[int] = []

    async def feeder(ctx: SimulatorContext) -> None:
        await feed_stream(ctx, front.pixels, beats, rnd, in_stall)

    async def results(ctx: SimulatorContext) -> None:
        for k in range(n):
            while len(got) < (k + 1) * p.beats_per_pixel:  # the pixel's words have left
                await ctx.tick()
            for _ in range(rnd.randint(0, result_delay)):
                await ctx.tick()
            value = int(maps[k])
            ctx.set(front.result_map, max(0, value))
            ctx.set(front.result_hit, int(value >= 0))
            ctx.set(front.result_take, 1)
            await ctx.tick()
            ctx.set(front.result_take, 0)

    async def collector(ctx: SimulatorContext) -> None:
        raw = front.beats.payload.as_value()
        cycles = 0
        while len(got) < expected:
            ready = not (out_stall and rnd.random() < out_stall)
            ctx.set(front.beats.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(front.beats.valid, raw)
            cycles += 1
            if valid and ready:
                got.append(payload)
            if cycles > max_cycles:
                raise RuntimeError(f"no complete output after {max_cycles} cycles ({len(got)}/{expected})")

    sim = Simulator(front)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(results, background=True)
    sim.add_testbench(collector)
    sim.run()
    return words_from_beats(p, got), line_starts_from_beats(p, got)
