"""The fused column's scan on chip (hdl/frontend/lanes/fused.py, ``ScanRing``): the word generator
scans the next output pixels' beats while the current pixel's words issue, far enough ahead that a fused
pass's output pixels follow each other every ``beats_per_pixel`` cycles (not that plus the scan's
latency, nor the scan plus the issues), for any beats per pixel; the words stay the host's, the streams
stalled or not."""

from __future__ import annotations

import random
from collections import Counter

import numpy as np
import pytest
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


def _beats_and_cycles(front: FrontEnd, frames: list, stall: float = 0.0) -> tuple[list[int], list[int]]:
    """Every beat the front end writes and its cycle (the pixels and the sink stalled with probability
    ``stall`` per cycle)."""
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    expected = output_pixels(frames, front.model) * front.params.beats_per_pixel
    got: list[int] = []
    at: list[int] = []

    async def feeder(ctx) -> None:
        await feed_stream(ctx, front.pixels, beats, random.Random(0), stall)

    async def collector(ctx) -> None:
        raw = front.beats.payload.as_value()
        rnd = random.Random(1)
        cycle = 0
        while len(got) < expected and cycle < 100_000:
            ready = not (stall and rnd.random() < stall)
            ctx.set(front.beats.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(front.beats.valid, raw)
            cycle += 1
            if valid and ready:
                got.append(payload)
                at.append(cycle)

    sim = Simulator(front)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    return got, at


def _census(dmax: int, words_per_beat: int) -> tuple[ModelParams, object]:
    model = ModelParams(name="census", dmax=dmax, fuse_columns=True, neighbour_prior=False)
    return model, stereo_machine_params(dmax, model=model, counter_max=2, words_per_beat=words_per_beat)


# words per beat -> beats per pixel, and the gaps between output pixels' first beats (measured): within
# an output row one pixel every beats_per_pixel cycles (before: beats_per_pixel + 6, 10 at 4 beats;
# scanning then issuing took 2 x 4 + 5: 13); a row's first pixel comes after the 20 pixels outside the
# output region between the rows, and at 2 beats or more a cycle after the last of them (its delay-line
# write pending: WordPipeline.accept; 26, 32, 36 before).
GAPS = {16: (1, Counter({1: 18, 21: 1})), 8: (2, Counter({2: 18, 27: 1})),
        4: (4, Counter({4: 18, 33: 1})), 3: (6, Counter({6: 18, 37: 1}))}


@pytest.mark.parametrize("words_per_beat", list(GAPS))
def test_a_fused_pass_takes_a_pixel_every_beats_per_pixel_cycles(words_per_beat: int) -> None:
    model, params = _census(14, words_per_beat)
    beats, gaps = GAPS[words_per_beat]
    assert params.beats_per_pixel == beats
    frames = [_noisy_pair(8, 30, seed=3)]
    got, at = _beats_and_cycles(FrontEnd(params=params, model=model, width=30), frames)
    want = np.concatenate([memory_words(model_planes(lf, model), model_planes(rf, model), model, params)
                           for lf, rf in frames])
    assert np.array_equal(words_from_beats(params, got), want)
    assert Counter(np.diff(at[:: params.beats_per_pixel]).tolist()) == gaps


@pytest.mark.parametrize("words_per_beat", [16, 4])
def test_the_words_hold_under_random_stalls(words_per_beat: int) -> None:
    """The scans run ahead whatever the streams do; the issues stall: the words stay the host's."""
    model, params = _census(14, words_per_beat)
    frames = [_noisy_pair(8, 30, seed=4), _noisy_pair(7, 30, seed=5)]
    got, _ = _beats_and_cycles(FrontEnd(params=params, model=model, width=30), frames, stall=0.4)
    want = np.concatenate([memory_words(model_planes(lf, model), model_planes(rf, model), model, params)
                           for lf, rf in frames])
    assert np.array_equal(words_from_beats(params, got), want)
