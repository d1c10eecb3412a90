"""The gradient-magnitude column (``--gradient-magnitude``, an option of the paper model, off by
default): its table, its host words, the front end's words and the machine fed by the front end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.columns import GradMag, likelihood_formula, quantize
from bayesmachine.hdl.frontend.stereo import FrontEnd, stereo_machine_params
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words, memory_words_plain
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import ParameterError
from bayesmachine.sim.stereo_testbench import run_frontend

GRAD = {"name": "paper", "gradient_magnitude": True}


def test_the_column_is_a_paper_option_off_by_default() -> None:
    assert [c.name for c in ModelParams(name="paper").columns] == ["m", "gh", "gv"]
    model = ModelParams(**GRAD, dmax=6, sigma_g=7.0)
    assert [c.name for c in model.columns] == ["m", "gh", "gv", "g"]
    assert disparity_machine(model).columns == 4
    assert model.to_dict()["sigma_g"] == 7.0
    with pytest.raises(ParameterError, match="^gradient_magnitude is not a parameter of the census model"):
        ModelParams(name="census", gradient_magnitude=True)
    with pytest.raises(TypeError, match="gradient_magnitude must be True or False"):
        ModelParams(name="paper", gradient_magnitude=1)
    with pytest.raises(ParameterError, match="sigma_g"):
        ModelParams(**GRAD, sigma_g=0.0)


def test_table_is_the_formula_of_the_gradient_magnitudes() -> None:
    column = ModelParams(**GRAD, p0=0.1, sigma_g=4.0).column(GradMag)
    costs = np.array([0, 1, 20, 77, 5100])
    assert np.array_equal(column.table().values[costs], likelihood_formula(costs, 20, 0.1, 4.0))
    assert len(column.table().values) == 5101  # |g_l - g_r| <= 2 x (2550 + 2550) / 2
    image = np.random.default_rng(1).integers(0, 256, (9, 9), dtype=np.uint8)
    left = model_planes(image, ModelParams(**GRAD))
    assert set(left) == {"m25", "gh20", "gv20", "g20"}  # the planes its columns declare
    assert np.array_equal(left.g20, np.abs(left.gh20) + np.abs(left.gv20))


def test_host_words_equal_the_plain_formula() -> None:
    rng = np.random.default_rng(3)
    left, right = (rng.integers(0, 256, (9, 20), dtype=np.uint8) for _ in range(2))
    model = ModelParams(**GRAD, dmax=5, sigma_g=6.0)
    machine = disparity_machine(model)
    fl, fr = model_planes(left, model), model_planes(right, model)
    words = memory_words(fl, fr, model, machine)
    assert np.array_equal(words, memory_words_plain(fl, fr, model, machine))
    # Operator column 3 (the g column), row d of the first output pixel: the formula at |g_l - g_r(x-d)|.
    x = model.dmax
    for d in range(model.dmax + 1):
        p = likelihood_formula(np.abs(fl.g20[0, x] - fr.g20[0, x - d]), 20, 0.02, 6.0)
        assert words[0, d, 3] == quantize(p, machine.word_bits)
    assert words[0, model.dmax + 1, 3] == 1 << machine.word_bits  # its no-match entry is 1


@pytest.mark.parametrize("options", [{}, {"prior": "loaded", "word_bits": 8}])
def test_frontend_words_equal_the_host_words(options: dict) -> None:
    full_left, full_right, _ = bundled_pair()
    y, x, h, w = 200, 300, 7, 22
    left, right = full_left[y : y + h, x : x + w], full_right[y : y + h, x - 40 : x - 40 + w]
    model = ModelParams(**GRAD, dmax=6)
    params = stereo_machine_params(6, model=model, counter_max=4, **options)
    got = run_frontend(FrontEnd(params=params, model=model, width=w), [(left, right)], in_stall=0.2,
                       out_stall=0.3, seed=2)
    want = memory_words(model_planes(left, model), model_planes(right, model), model, params)
    assert got.shape == want.shape
    assert np.array_equal(got, want), np.argwhere(got != want)[:5]


@pytest.mark.eda
def test_cli_run_feed_pixels_gives_the_models_result(tmp_path: Path) -> None:
    """Verilator's stereo machine, fed pixels, against the model engine fed the host's words."""
    crop = ["--crop", "250,200,40,12", "--dmax", "8", "--quiet", "--no-sgbm", "--model", "paper",
            "--gradient-magnitude"]
    assert main(["run", "--engine", "verilator", "--feed", "pixels", *crop, "-o", str(tmp_path / "px")]) == 0
    assert main(["run", "--engine", "model", *crop, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "px" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    for key in ("map", "counts", "cycles", "timeout"):
        assert np.array_equal(got[key], want[key]), key
    assert len(set(want["map"].ravel().tolist())) > 2  # not a degenerate answer
