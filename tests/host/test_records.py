"""A run's records (bayesmachine.host.records): the figures a run reports beside its results, pinned
on a crop of the bundled pair, in the library and in ``report.json``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bayesmachine.host.images import bundled_pair
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine

# The bundled pair's rows 200..223, columns 300..419 (run's --crop 300,200,120,24), at Dmax 64.
CROP = (300, 200, 120, 24)
DMAX = 64


def _crop() -> tuple[np.ndarray, ...]:
    x, y, w, h = CROP
    return tuple(np.ascontiguousarray(a[y : y + h, x : x + w]) for a in bundled_pair())


@pytest.mark.parametrize(("keywords", "machine", "want"), [
    ({}, {}, 18995.6067),
    ({"fuse_columns": False}, {}, 44612.1133),
    # B = 4 counts every sample of a run's last clock (4 x its clocks, not its cycles).
    ({}, {"samples_per_clock": 4}, 20612.5333),
    # The log machine samples nothing.
    ({}, {"integrator": "log"}, None),
])
def test_operator_samples_per_pixel(keywords: dict, machine: dict, want: float | None) -> None:
    """Every pass's operators x its cycles summed over its pixels, per output pixel (measured): census-lr
    (35483 x 66 x 4 + 39033 x 66 x 3) / 900 fused, (46225 x 66 x 7 + 47462 x 66 x 6) / 900 per column."""
    model = ModelParams(name="census-lr", dmax=DMAX, **keywords)
    left, right, gt = _crop()
    run = run_machine(prepare(left, right, model, gt), disparity_machine(model, **machine), progress=False)
    got = run.operator_samples_per_pixel
    assert got is None if want is None else got == pytest.approx(want, abs=1e-4)


def test_report_gives_operator_samples_per_pixel(tmp_path) -> None:
    from bayesmachine.cli import main

    crop = ",".join(map(str, CROP))
    argv = ["run", "--model", "census-lr", "--crop", crop, "--dmax", str(DMAX), "--no-sgbm", "--quiet", "-o",
            str(tmp_path)]
    assert main(argv) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["operator_samples_per_pixel"] == pytest.approx(18995.6067, abs=1e-4)
