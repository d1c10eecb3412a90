"""The throughput measurement behind ``synth``: the frame's place in the bundled pair and the check
that the StereoMachine's run equals the model's (a difference must show)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bayesmachine.host.throughput import FRAME_HEIGHT, _same_run, frame_crop, measure_frame
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams


def test_frame_is_centred_and_needs_a_pair_as_large() -> None:
    assert frame_crop(640, (500, 741)) == (50, 10)
    assert frame_crop(741, (500, 741)) == (0, 10)
    assert frame_crop(742, (500, 741)) is None
    assert frame_crop(16, (FRAME_HEIGHT - 1, 741)) is None


def test_no_frame_wider_than_the_bundled_pair() -> None:
    model = ModelParams(name="paper", dmax=3)
    params = MachineParams.for_disparity(3, counter_max=3)
    assert measure_frame(params, model, width=742, fifo_pixels=2) is None


@pytest.mark.parametrize("name", ["census", "census-lr"])
def test_same_run_sees_every_difference(name: str) -> None:
    from bayesmachine.host.images import Crop, bundled_pair, crop_image
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.models import disparity_machine

    left, right, _ = (crop_image(a, Crop(300, 200, 40, 10)) for a in bundled_pair())
    model = ModelParams(name=name, dmax=6)
    params = disparity_machine(model, counter_max=4)
    run = run_machine(prepare(left, right, model, reference=False), params, "model", progress=False)
    assert _same_run(run, dataclasses.replace(run))
    for field in ("map", "counts", "cycles", "timeout", "nomatch"):
        changed = np.array(getattr(run, field), copy=True)
        changed.flat[0] = not changed.flat[0] if changed.dtype == bool else changed.flat[0] + 1
        assert not _same_run(run, dataclasses.replace(run, **{field: changed})), field
    if name == "census-lr":
        assert list(run.passes) == ["right"]
        cycles = run.passes["right"].cycles.copy()
        cycles.flat[-1] += 1
        other = dataclasses.replace(run.passes["right"], cycles=cycles)
        assert not _same_run(run, dataclasses.replace(run, passes={"right": other}))
        assert not _same_run(run, dataclasses.replace(run, passes={}))
