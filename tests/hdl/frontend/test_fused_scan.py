"""The fused column's scan on chip (hdl/frontend/lanes/fused.py, ``WordNets._hold``): the word generator
scans the next output pixel's beats while the current pixel's words issue, so a fused pass's output
pixels follow each other every ``beats_per_pixel`` + 6 cycles (the scan and its latency), not the scan
plus the issues; the words stay the host's."""

from __future__ import annotations

import random
from collections import Counter

import numpy as np
from amaranth.sim import Simulator

from bayesmachine.hdl.frontend.stereo import FrontEnd, stereo_machine_params
from bayesmachine.host.features import model_planes
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams
from bayesmachine.sim.stereo_testbench import feed_stream, frame_beats, output_pixels, words_from_beats


def _noisy_pair(height: int, width: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    left = rng.integers(0, 256, (height, width), dtype=np.uint8)
    return left, np.roll(left, -2, axis=1)


def _beats_and_cycles(front: FrontEnd, frames: list) -> tuple[list[int], list[int]]:
    """Every beat the front end writes (the sink always ready, the pixels never stalled) and its cycle."""
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    expected = output_pixels(frames, front.model) * front.params.beats_per_pixel
    got: list[int] = []
    at: list[int] = []

    async def feeder(ctx) -> None:
        await feed_stream(ctx, front.pixels, beats, random.Random(0), 0.0)

    async def collector(ctx) -> None:
        raw = front.beats.payload.as_value()
        ctx.set(front.beats.ready, 1)
        cycle = 0
        while len(got) < expected and cycle < 100_000:
            _, _, valid, payload = await ctx.tick().sample(front.beats.valid, raw)
            cycle += 1
            if valid:
                got.append(payload)
                at.append(cycle)

    sim = Simulator(front)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    return got, at


def test_the_next_pixels_scan_runs_beside_the_issues() -> None:
    model = ModelParams(name="census", dmax=14, fuse_columns=True, neighbour_prior=False)
    params = stereo_machine_params(14, model=model, counter_max=2, words_per_beat=4)
    assert params.beats_per_pixel == 4
    frames = [_noisy_pair(8, 30, seed=3)]
    got, at = _beats_and_cycles(FrontEnd(params=params, model=model, width=30), frames)
    want = np.concatenate([memory_words(model_planes(lf, model), model_planes(rf, model), model, params)
                           for lf, rf in frames])
    assert np.array_equal(words_from_beats(params, got), want)
    firsts = at[:: params.beats_per_pixel]
    gaps = Counter(np.diff(firsts).tolist())
    # Two output rows of 10 pixels: within a row one pixel every beats_per_pixel + 6 cycles (scanning
    # then issuing took 2 x 4 + 5: 13).
    assert gaps == Counter({10: 18, 33: 1})
