"""census-sgm through Verilator fed pixels (the front end's semi-global lanes in both passes, either
integrator): every result array of ``run --feed pixels`` equal to the model engine's on a crop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayesmachine.cli import main


@pytest.mark.eda
@pytest.mark.slow
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("integrator", ["log", "stochastic"])
def test_semiglobal_stereo_verilator_equals_the_model(integrator: str, tmp_path: Path) -> None:
    crop = ["--crop", "250,200,60,12", "--dmax", "16", "--model", "census-sgm", "--integrator", integrator,
            "--no-sgbm", "--quiet"]
    outs = {}
    for engine, feed in (("model", []), ("verilator", ["--feed", "pixels"])):
        assert main(["run", "--engine", engine, *feed, *crop, "-o", str(tmp_path / engine)]) == 0
        outs[engine] = np.load(tmp_path / engine / "result.npz")
    keys = set(outs["model"].files)
    assert keys == set(outs["verilator"].files) and {"map", "counts", "cycles", "timeout"} <= keys
    for key in sorted(keys):
        assert np.array_equal(outs["model"][key], outs["verilator"][key]), key
    assert len(np.unique(outs["model"]["map"])) > 3
