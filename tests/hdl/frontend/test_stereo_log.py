# amaranth: UnusedElaboratable=no
"""The logarithmic machine fed pixels: the on-chip front end writes each column's energy codes
(``Column.codes``, the host's words path for a log machine) and ``StereoMachine`` runs ``LogMachine``s
(one per pass, K of them), equal to the log model engine bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_passes_equal_the_model, assert_same_results

from bayesmachine.columns.energy import INFINITE_CODE, log_codes
from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine, stereo_machine_params
from bayesmachine.hdl.frontend.tables import LoadForm, clamp_table, frontend_tables
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.run import machines_model
from bayesmachine.models import ModelParams
from bayesmachine.sim.stereo_testbench import run_frontend, run_stereo


def _crop(y: int, x: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    left, right, _ = bundled_pair()
    return (np.ascontiguousarray(left[y:y + height, x:x + width]),
            np.ascontiguousarray(right[y:y + height, x:x + width]))


def test_load_form_and_tables() -> None:
    """A log machine's tables are the columns' codes (``log_codes`` of the float64 table), clamped; the
    fused column's way back is the sum itself up to INFINITE_CODE - 1; 1.0 and 0 are the codes 0 and
    511 (the words 2^W and 0 of a stochastic machine)."""
    assert (LoadForm("log", 10).one, LoadForm("log", 10).zero) == (0, 511)
    assert (LoadForm("stochastic", 10).one, LoadForm("stochastic", 10).zero) == (1024, 0)
    paper = ModelParams(name="paper", dmax=24)
    codes = frontend_tables(paper, 10, "log")
    m = next(c for c in paper.columns if c.name == "m")
    np.testing.assert_array_equal(codes["m"], clamp_table(log_codes(m.table().values)))
    # Measured: 1.0 at cost 0, the floor p0 from cost 1,064 on (the words change up to 1,164).
    assert (codes["m"][0], codes["m"][-1], len(codes["m"])) == (0, 63, 1065)
    words = frontend_tables(paper, 10)
    np.testing.assert_array_equal(words["m"], clamp_table(m.table(10).values))
    fused = frontend_tables(ModelParams(name="census-lr", dmax=24), 10, "log")["fused_exp"]
    np.testing.assert_array_equal(fused, np.arange(INFINITE_CODE))


def test_frontend_writes_the_hosts_codes() -> None:
    """The paper model's front end writes ``memory_words`` of a log machine (its codes), word for word."""
    model = ModelParams(name="paper", dmax=12)
    params = stereo_machine_params(12, model=model, integrator="log")
    width = 12 + 2 * model.margin + 10
    frames = [_crop(250, 200, 2 * model.margin + 3, width)]
    got = run_frontend(FrontEnd(params=params, model=model, width=width), frames, in_stall=0.2,
                       out_stall=0.3, seed=3)
    left, right = frames[0]
    want = memory_words(model_planes(left, model), model_planes(right, model), model, params)
    np.testing.assert_array_equal(got, want)
    assert want.max() < INFINITE_CODE and len(np.unique(want)) > 20  # codes, not words


@pytest.mark.parametrize(("name", "machines"), [("paper", 1),
                                                pytest.param("census", 2, marks=pytest.mark.slow)])
def test_stereo_log_machine_equals_the_model(name: str, machines: int) -> None:
    """StereoMachine with LogMachines (the census model: the above neighbour's codes from another
    machine's MAPs, the left neighbour's formed by the machine) against the log model engine on the host's
    codes, two frames back to back, random stalls on both streams."""
    dmax = 12
    model = ModelParams(name=name, dmax=dmax)
    params = stereo_machine_params(dmax, model=model, integrator="log")
    width = dmax + 2 * model.margin + 8
    frames = [_crop(250, 200, 2 * model.margin + 3, width), _crop(150, 400, 2 * model.margin + 2, width)]
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2, machines=machines)
    got, _ = run_stereo(top, frames, in_stall=0.2, out_stall=0.3, seed=machines)
    want = machines_model(frames, model, params, machines)
    assert_same_results(got, want)
    assert len(np.unique(want.map)) > 3  # disparities, not only no match


@pytest.mark.parametrize("fuse", [True, pytest.param(False, marks=pytest.mark.slow)])
def test_stereo_log_census_lr_equals_the_model(fuse: bool) -> None:
    """census-lr (fused or per column): the right pass's LogMachine, its flush lanes (infinite codes),
    the consistency column's codes; every pass's results equal the log model's run as the host runs it."""
    dmax = 12
    model = ModelParams(name="census-lr", dmax=dmax, fuse_columns=fuse)
    params = stereo_machine_params(dmax, model=model, integrator="log")
    width = dmax + 2 * model.margin + 8
    frames = [_crop(250, 200, 2 * model.margin + 3, width), _crop(150, 400, 2 * model.margin + 2, width)]
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2)
    want = assert_passes_equal_the_model(top, frames, model, params, seed=1)
    assert set(want) == {"right", "left"} and len(np.unique(want["left"].map)) > 3


def test_emit_summary_of_a_log_top() -> None:
    """``emit --top stereo``'s summary: a log machine's declared pass has no seed or watchdog to name."""
    from bayesmachine.hdl.frontend.cli import summary

    model = ModelParams(name="census-lr", dmax=6)
    for integrator, named in (("log", False), ("stochastic", True)):
        params = stereo_machine_params(6, model=model, integrator=integrator)
        text = summary(StereoMachine(params=params, model=model, width=23))
        line = next(row for row in text.splitlines() if row.startswith("right pass:"))
        assert ("seed" in line and "watchdog" in line) == named, line
