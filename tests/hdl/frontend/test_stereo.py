# amaranth: UnusedElaboratable=no
"""``StereoMachine(machines=K)``: one feature pipeline, map rows dealt to K machines, results in
raster order, bit for bit the model's (``host.run.machines_model``: each machine's random source and
left neighbour run over its own rows)."""

from __future__ import annotations

import gc

import numpy as np
import pytest
from conftest import assert_passes_equal_the_model, assert_same_results, noisy_pair, own_options, passes_model

from bayesmachine.columns.energy import INFINITE_CODE, log_codes
from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine, stereo_machine_params
from bayesmachine.hdl.frontend.tables import LoadForm, clamp_table, frontend_tables
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.run import machines_model
from bayesmachine.models import ModelParams
from bayesmachine.params import ParameterError
from bayesmachine.sim.stereo_testbench import run_frontend, run_stereo

# Whole StereoMachines under Amaranth's simulator: the pysim tier (tests/conftest.py).
pytestmark = pytest.mark.pysim


def _crop(y: int, x: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    left, right, _ = bundled_pair()
    return (np.ascontiguousarray(left[y:y + height, x:x + width]),
            np.ascontiguousarray(right[y:y + height, x:x + width]))


@pytest.mark.parametrize(("machines", "fused"), [(2, False), pytest.param(3, False, marks=pytest.mark.slow),
                                                  (2, True)])
def test_census_machines_equal_the_model(machines: int, fused: bool) -> None:
    """The census model (neighbour prior on: the above neighbour from another machine) per column, and
    with its image columns fused, the default (each machine's word generator scans its pixels' beats)."""
    width = 14
    model = ModelParams(dmax=2, name="census", fuse_columns=fused)
    params = stereo_machine_params(2, model=model, counter_max=8, max_cycles=3000)
    frames = [_crop(150, 400, 13, width), noisy_pair(10, width, seed=1)]  # 7 and 4 map rows
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2, machines=machines)
    got, _ = run_stereo(top, frames, in_stall=0.2, out_stall=0.3, seed=machines)
    assert_same_results(got, machines_model(frames, model, params, machines))


@pytest.mark.parametrize(("machines", "rng"), [(2, "sobol"), (3, "lfsr"), (2, "lfsr-shared")])
def test_paper_machines_equal_the_model(machines: int, rng: str) -> None:
    """The paper model (no neighbour prior), frames back to back without waiting."""
    width = 16
    model = ModelParams(dmax=4, name="paper")
    params = stereo_machine_params(4, model=model, counter_max=8, max_cycles=3000, rng=rng)
    frames = [noisy_pair(9, width, seed=2), _crop(200, 300, 7, width)]
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2, machines=machines)
    got, _ = run_stereo(top, frames, in_stall=0.2, out_stall=0.3, seed=machines)
    assert_same_results(got, machines_model(frames, model, params, machines))


@pytest.mark.parametrize(("machines", "integrator"), [(2, "stochastic"),
                                                       pytest.param(3, "stochastic", marks=pytest.mark.slow),
                                                       (2, "log")])
def test_census_lr_machines_equal_the_model(machines: int, integrator: str) -> None:
    """census-lr on K machines per pass (both passes' rows dealt: map row r's right and left pass on lane
    r mod K, each pass's above neighbour from lane r - 1, the consistency column from its own lane),
    two frames back to back, random stalls on both streams: every pass's results equal the model's with
    K machines per pass; the dealing shows in the cycles (each machine its own random stream)."""
    dmax = 8
    model = ModelParams(name="census-lr", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, integrator=integrator,
                                   **own_options(integrator, counter_max=6))
    width = dmax + 2 * model.margin + 6
    left, right = _crop(100, 100, 2 * model.margin + 4, width)  # where Dmax 8 finds matches
    frames = [(left, right), noisy_pair(2 * model.margin + 3, width, seed=machines)]
    top = StereoMachine(params=params, model=model, width=width, fifo_pixels=2, machines=machines)
    want = assert_passes_equal_the_model(top, frames, model, params, seed=machines)
    assert set(want) == {"right", "left"} and len(np.unique(want["left"].map)) > 3
    if integrator == "stochastic":
        one = passes_model(frames, model, params)
        assert not np.array_equal(one["left"].cycles, want["left"].cycles)
        assert not np.array_equal(one["right"].cycles, want["right"].cycles)


# A constructor that refuses its arguments leaves an object Amaranth reports as never elaborated.
@pytest.mark.filterwarnings("ignore::amaranth.hdl.UnusedElaboratable")
def test_machines_is_validated() -> None:
    model = ModelParams(dmax=2, name="census")
    params = stereo_machine_params(2, model=model)
    with pytest.raises(TypeError, match="machines must be an integer"):
        StereoMachine(params=params, model=model, width=14, machines=2.0)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="machines must be an integer"):
        StereoMachine(params=params, model=model, width=14, machines=True)  # type: ignore[arg-type]
    for bad in (0, 17):
        with pytest.raises(ParameterError, match=r"machines must be in \[1, 16\]"):
            StereoMachine(params=params, model=model, width=14, machines=bad)
    smtj = stereo_machine_params(2, model=model, rng="smtj")
    with pytest.raises(ParameterError, match="rng 'smtj' is off chip"):
        StereoMachine(params=smtj, model=model, width=14, machines=2)
    StereoMachine(params=smtj, model=model, width=14, machines=1)
    top = StereoMachine(params=params, model=model, width=14, machines=16)
    assert top.machines == 16
    del top
    gc.collect()  # the never-elaborated warnings are given here, where they are expected


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("machines", [2, 4])
def test_verilator_machines_on_a_crop_equal_the_model(machines: int) -> None:
    """The census model at Dmax 8 (counter max 16) on crops of the bundled pair, frames back to back
    (the second waits at its first pixel for every machine to go idle); more wall cycles than compute
    cycles per machine would take alone are not asserted here (see the slow VGA test)."""
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    dmax, width = 8, 40
    model = ModelParams(dmax=dmax, name="census")
    params = stereo_machine_params(dmax, model=model, counter_max=16)
    # crops where Dmax 8 finds matches (most of the pair's disparities are larger)
    frames = [_crop(100, 100, 14, width), _crop(150, 350, 11, width)]  # 8 and 5 map rows
    want = machines_model(frames, model, params, machines)
    assert len(set(want.map.tolist())) > 2  # not a degenerate answer
    with StereoVerilatorEngine(params, model, width, verbose=False, machines=machines) as engine:
        rows = [engine.run(left, right) for left, right in frames]
    from bayesmachine.sim.results import MachineResult

    assert_same_results(MachineResult.concatenate(rows, params.rows), want)
    one = machines_model(frames, model, params, 1)
    assert not np.array_equal(one.cycles, want.cycles)  # the dealing shows: each machine its own stream


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_verilator_census_lr_machines_on_a_crop_equal_the_model() -> None:
    """census-lr on 2 machines per pass at Dmax 8 under Verilator, a crop of the bundled pair: both passes'
    results equal the model's with 2 machines per pass."""
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    dmax, width = 8, 40
    model = ModelParams(dmax=dmax, name="census-lr")
    params = stereo_machine_params(dmax, model=model, counter_max=16)
    frame = _crop(100, 100, 14, width)
    want = passes_model([frame], model, params, machines=2)
    assert len(set(want["left"].map.tolist())) > 2  # not a degenerate answer
    with StereoVerilatorEngine(params, model, width, verbose=False, machines=2) as engine:
        got = engine.run(*frame)
        right = engine.last_passes["right"]
    assert_same_results(got, want["left"])
    assert_same_results(right, want["right"])


@pytest.mark.parametrize(("argv", "message"), [
    (["emit", "--top", "stereo", "--machines", "0"], "--machines: expected an integer in [1, 16], got '0'"),
    (["emit", "--machines", "2"], "--machines: only with --top stereo"),
    (["emit", "--top", "stereo", "--model", "census-lr", "--machines", "2", "--rng", "smtj"],
     "rng 'smtj' is off chip"),
    (["synth", "--top", "stereo", "--machines", "17", "--target", "ecp5-85k"], "machines must be in [1, 16]"),
    (["run", "--engine", "board", "--port", "/dev/null", "--machines", "2"], "the board carries one machine"),
])
def test_cli_refuses_a_bad_machines_in_one_line(argv: list[str], message: str, tmp_path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    from bayesmachine.cli import main

    assert main([*argv, "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out").exists()


def test_cli_emit_stereo_machines(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from bayesmachine.cli import main

    out = tmp_path / "top.il"
    assert main(["emit", "--top", "stereo", "--model", "paper", "--dmax", "4", "--width", "16",
                 "--machines", "3", "-o", str(out)]) == 0
    assert "3 machines (map row r on machine r mod 3" in capsys.readouterr().out
    text = out.read_text()
    assert all(f"machine{j}" in text for j in range(3)) and "machine3" not in text


def test_model_run_with_machines_deals_rows(tmp_path) -> None:
    """``run --engine model --machines K`` is :func:`machines_model` on the pair (the twin the
    StereoMachine's results are held to)."""
    from bayesmachine.cli import main

    crop = ["--crop", "250,200,40,12", "--dmax", "8", "--model", "census", "--quiet", "--no-sgbm"]
    assert main(["run", "--engine", "model", "--machines", "3", *crop, "-o", str(tmp_path / "k3")]) == 0
    got = np.load(tmp_path / "k3" / "result.npz")
    left, right = _crop(200, 250, 12, 40)
    model = ModelParams(dmax=8, name="census")
    want = machines_model([(left, right)], model, stereo_machine_params(8, model=model), 3)
    assert np.array_equal(got["cycles"].ravel(), want.cycles)
    assert np.array_equal(got["counts"].reshape(len(want), -1), want.counts)


@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.slow
def test_verilator_four_machines_on_a_vga_frame_equal_the_model() -> None:
    """A 640 x 480 crop of the bundled pair through StereoMachine(machines=4) (the default census
    model, Dmax 80, counter max 16, ``sobol``): every result the model's, and the machines overlap (the
    frame's wall cycles well below one machine's compute cycles)."""
    from bayesmachine.host.images import Crop, crop_image
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    left, right, _ = (crop_image(a, Crop(50, 10, 640, 480)) for a in bundled_pair())
    model = ModelParams(dmax=80, name="census")
    params = stereo_machine_params(80, model=model, counter_max=16)
    want = machines_model([(left, right)], model, params, 4)
    with StereoVerilatorEngine(params, model, 640, verbose=False, machines=4) as engine:
        got = engine.run(left, right)
        wall = engine.last_wall_cycles
    assert_same_results(got, want)
    assert wall < 0.5 * int(want.cycles.sum())


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
