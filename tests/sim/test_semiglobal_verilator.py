"""census-sgm through Verilator fed pixels (the front end's semi-global lanes in both passes, either
integrator): every result array of ``run --feed pixels`` equal to the model engine's on a crop."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import assert_feed_pixels_equals_model


@pytest.mark.eda
@pytest.mark.slow
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("integrator", ["log", "stochastic"])
def test_semiglobal_stereo_verilator_equals_the_model(integrator: str, tmp_path: Path) -> None:
    assert_feed_pixels_equals_model(["--crop", "250,200,60,12", "--dmax", "16", "--model", "census-sgm",
                                     "--integrator", integrator, "--no-sgbm", "--quiet"], tmp_path)
