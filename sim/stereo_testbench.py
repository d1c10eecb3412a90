"""Driving the front end and ``StereoMachine`` in Amaranth's simulator (tests, debugging).

Frames go in as pixel beats packed from ``pixel_in_layout()``; the front end's load beats and
the machine's results come out decoded from their layouts. Random ``valid`` / ``ready`` stalls on
both streams exercise the handshakes (results must not depend on them).
"""

from __future__ import annotations

import random
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from amaranth.sim import Simulator, SimulatorContext

from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine
from bayesmachine.hdl.signatures import beat_words, load_layout, pixel_in_layout
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sim.results import MachineResult, decode_results

__all__ = ["frame_beats", "line_starts_from_beats", "output_pixels", "pass_pixels", "run_frontend",
           "run_frontend_beats", "run_frontend_passes", "run_stereo", "run_stereo_passes", "words_from_beats"]


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
    """The ``line_start`` flag of each beat of a machine's load beats, (P, beats_per_pixel) (0 without a
    neighbour prior: its beats have none)."""
    layout = load_layout(params)
    flags = [int(layout.from_bits(raw).line_start) if params.feedback_columns else 0 for raw in beats]
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
    return pass_pixels(frames, model, model.passes[-1].name)


def pass_pixels(frames: Sequence[tuple[np.ndarray, np.ndarray]], model: ModelParams, name: str) -> int:
    """The pixels (results) of ``model``'s pass ``name`` in ``frames``: per output row its reference's
    (the own pass's output pixels; a right-reference pass's every right map column)."""
    from bayesmachine.hdl.frontend.passes import pass_row_pixels

    k = model.margin
    return sum((lf.shape[0] - 2 * k) * pass_row_pixels(model, name, lf.shape[1]) for lf, _ in frames)


def run_frontend(front: FrontEnd, frames: Sequence[tuple[np.ndarray, np.ndarray]], *,
                 in_stall: float = 0.0, out_stall: float = 0.0, seed: int = 0,
                 max_cycles: int = 1_000_000) -> np.ndarray:
    """The words the front end writes for ``frames`` (pairs of (H, width) uint8 images), all frames'
    output pixels in order: (P, rows, loaded_columns). A front end that reads MAPs (``maps`` ports)
    needs stand-ins for them: :func:`run_frontend_passes`."""
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    return run_frontend_beats(front, beats, output_pixels(frames, front.model), in_stall=in_stall,
                              out_stall=out_stall, seed=seed, max_cycles=max_cycles)


def run_frontend_beats(front: FrontEnd, beats: list[int], pixels: int, *, in_stall: float = 0.0,
                       out_stall: float = 0.0, seed: int = 0, max_cycles: int = 1_000_000) -> np.ndarray:
    """The words of the first ``pixels`` output pixels the front end writes for raw pixel ``beats``."""
    if any(name.endswith("maps") for name in front.signature.members):
        raise ValueError("this front end reads MAPs (its maps ports): run it with run_frontend_passes")
    expected = pixels * front.params.beats_per_pixel
    got, _ = _simulate(front, front.pixels, front.beats, beats, expected, in_stall, out_stall, seed,
                       max_cycles)
    return words_from_beats(front.params, got)


def run_stereo(top: StereoMachine, frames: Sequence[tuple[np.ndarray, np.ndarray]], *,
               in_stall: float = 0.0, out_stall: float = 0.0, seed: int = 0,
               max_cycles: int = 1_000_000) -> tuple[MachineResult, int]:
    """The machine's results for ``frames`` through ``StereoMachine`` and the clock cycles it took (the
    declared passes' results are taken too: :func:`run_stereo_passes`)."""
    results, cycles = run_stereo_passes(top, frames, in_stall=in_stall, out_stall=out_stall, seed=seed,
                                        max_cycles=max_cycles)
    return results[top.model.passes[-1].name], cycles


def run_stereo_passes(top: StereoMachine, frames: Sequence[tuple[np.ndarray, np.ndarray]], *,
                      in_stall: float = 0.0, out_stall: float | Mapping[str, float] = 0.0, seed: int = 0,
                      max_cycles: int = 1_000_000) -> tuple[dict[str, MachineResult], int]:
    """Every pass's results for ``frames`` through ``StereoMachine``, by pass name (the own pass's on
    ``result``, a declared pass's on ``<pass>_result``: every pixel of the pass of every output row,
    raster order), each result stream stalled at random (``out_stall``: one probability, or one per pass
    name, 0 for a pass not named), and the clock cycles it took."""
    from bayesmachine.hdl.frontend.passes import pass_port
    from bayesmachine.hdl.frontend.words import pass_params

    model = top.model
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    ports = {p.name: getattr(top, pass_port(model, p, "result")) for p in model.passes}
    expected = {name: pass_pixels(frames, model, name) for name in ports}
    got: dict[str, list[int]] = {name: [] for name in ports}
    stalls = out_stall if isinstance(out_stall, Mapping) else dict.fromkeys(ports, out_stall)
    rnd = random.Random(seed)
    cycles = 0

    async def feeder(ctx: SimulatorContext) -> None:
        await feed_stream(ctx, top.pixels, beats, rnd, in_stall)

    async def collector(ctx: SimulatorContext) -> None:
        nonlocal cycles
        names = list(ports)
        samples = [v for n in names for v in (ports[n].valid, ports[n].payload.as_value())]
        while any(len(got[n]) < expected[n] for n in names):
            ready = {n: not (stalls.get(n) and rnd.random() < stalls[n]) for n in names}
            for n in names:
                ctx.set(ports[n].ready, ready[n])
            _, _, *values = await ctx.tick().sample(*samples)
            cycles += 1
            for i, n in enumerate(names):
                if values[2 * i] and ready[n]:
                    got[n].append(values[2 * i + 1])
            if cycles > max_cycles:
                raise RuntimeError(f"no complete output after {max_cycles} cycles ("
                                   + ", ".join(f"{n} {len(got[n])}/{expected[n]}" for n in names) + ")")

    sim = Simulator(top)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    out = {}
    for p in model.passes:
        pp = pass_params(model, top.params, p.name)
        out[p.name] = decode_results(pp, got[p.name]) if got[p.name] else MachineResult.empty(pp.rows)
    return out, cycles


def run_frontend_passes(front: FrontEnd, frames: Sequence[tuple[np.ndarray, np.ndarray]],
                        maps: Mapping[str, np.ndarray] | None = None, *, in_stall: float = 0.0,
                        out_stall: float = 0.0, result_delay: int = 0, seed: int = 0,
                        max_cycles: int = 1_000_000) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every pass's words and beats' ``line_start`` flags for ``frames``, by pass name: (words (P,
    rows, loaded_columns), flags (P, beats_per_pixel)), P the pass's pixels (:func:`pass_pixels`).
    ``maps[name]`` stands in for the results of each pass whose MAPs the front end reads (its ``maps``
    ports), one per pixel of the pass, -1 = no match: the MAP of pixel i goes in after its last beat
    left, up to ``result_delay`` random cycles later, when the front end is ready for it."""
    from bayesmachine.hdl.frontend.passes import pass_port
    from bayesmachine.hdl.frontend.words import pass_params

    model, maps = front.model, dict(maps or {})
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    rnd = random.Random(seed)
    got: dict[str, list[int]] = {p.name: [] for p in model.passes}
    params = {p.name: pass_params(model, front.params, p.name) for p in model.passes}
    sim = Simulator(front)
    sim.add_clock(1e-8)

    async def feeder(ctx: SimulatorContext) -> None:
        await feed_stream(ctx, front.pixels, beats, rnd, in_stall)

    sim.add_testbench(feeder, background=True)
    benches = []
    for p in model.passes:
        n, bpp = pass_pixels(frames, model, p.name), params[p.name].beats_per_pixel
        port = pass_port(model, p, "maps")
        if port in front.signature.members:
            values = np.asarray(maps.get(p.name, ())).reshape(-1)
            if values.shape != (n,):
                raise ValueError(f"maps[{p.name!r}] must hold one MAP per pixel of the {p.name} pass ({n}), "
                                 f"got {values.shape}")
            benches.append(_stand_in(getattr(front, port), values, got[p.name], bpp, rnd, result_delay))
        benches.append(_collector(getattr(front, pass_port(model, p, "beats")), got[p.name], n * bpp, rnd,
                                  out_stall, max_cycles))
    done: list[bool] = []

    def finishing(bench: Any) -> Any:
        async def run(ctx: SimulatorContext) -> None:
            await bench(ctx)
            done.append(True)
        return run

    async def until_all_done(ctx: SimulatorContext) -> None:  # every stand-in given, every beat taken
        while len(done) < len(benches):
            await ctx.tick()

    for bench in benches:
        sim.add_testbench(finishing(bench), background=True)
    sim.add_testbench(until_all_done)
    sim.run()
    return {name: (words_from_beats(params[name], got[name]), line_starts_from_beats(params[name], got[name]))
            for name in got}


def _stand_in(port: object, values: np.ndarray, sink: list[int], bpp: int, rnd: random.Random,
              delay: int) -> object:
    """A testbench giving ``values`` as a machine's MAPs on ``port`` (a ``map_stream``), value i once
    pixel i's ``bpp`` beats are in ``sink``."""
    async def bench(ctx: SimulatorContext) -> None:
        for i, value in enumerate(values.tolist()):
            while len(sink) < (i + 1) * bpp:  # the pixel's words have left
                await ctx.tick()
            for _ in range(rnd.randint(0, delay)):
                await ctx.tick()
            ctx.set(port.payload, {"map": max(0, value), "hit": int(value >= 0)})  # type: ignore[attr-defined]
            ctx.set(port.valid, 1)  # type: ignore[attr-defined]
            await ctx.tick().until(port.ready)  # type: ignore[attr-defined]
            ctx.set(port.valid, 0)  # type: ignore[attr-defined]
    return bench


def _collector(stream_: object, sink: list[int], expected: int, rnd: random.Random, out_stall: float,
               max_cycles: int) -> object:
    async def bench(ctx: SimulatorContext) -> None:
        await collect_stream(ctx, stream_, sink, expected, rnd, out_stall, max_cycles)
    return bench
