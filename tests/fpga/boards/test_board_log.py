"""The logarithmic machine on the board (fpga/boards), without Verilator: its result records carry the
rows' weights (up to 2^W: two bytes each), the link gives the log model's results from the board's twin,
and the commands a user runs, ``board build|simulate --integrator log`` (their tools and harness stood in
for) and ``run --engine board --integrator log``, against ``run --engine model --integrator log``.
(tests/fpga/boards/test_simulate.py runs the board's RTL with the log machine.)"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import passes_model

from bayesmachine.cli import main
from bayesmachine.fpga.boards import protocol as pr
from bayesmachine.fpga.boards.twin import BoardTwin
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.models import ModelParams

from .test_board import DMAX, HEIGHT, WIDTH, StandInHarness, TwinPort, _crop, _link

MODEL = ModelParams(name="census-lr", dmax=DMAX)  # two passes and the neighbour prior's feedback
PARAMS = stereo_machine_params(DMAX, model=MODEL, integrator="log")


def _twin() -> BoardTwin:
    return BoardTwin(PARAMS, MODEL, WIDTH, results=lambda lf, rf: passes_model([(lf, rf)], MODEL, PARAMS))


def test_a_log_machines_records_carry_its_weights() -> None:
    """A weight is up to 2^W = 1024 (11 bits, where the stochastic machine's counter max 16 takes 5):
    two bytes per row. The record's size is the one the simulated board sent (1120 bytes for a 16 x 12
    frame of the paper model at Dmax 4: 64 records and the start and end records)."""
    paper = ModelParams(name="paper", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=paper, integrator="log")
    fmt = pr.ResultFormat.of(params, pr.FIELDS_ALL)
    assert (fmt.count_width, fmt.count_bytes, fmt.record_bytes) == (11, 2, 17)
    assert 64 * fmt.record_bytes + 2 * pr.RECORD_BYTES == 1120
    weights = np.array([[1024, 0, 37, 1023, 1, 512], [0, 0, 0, 0, 0, 1024]])
    raw = fmt.encode(np.array([0, 5]), np.array([False, True]), np.array([False, False]), weights,
                     np.array([1, 5]))
    back = fmt.decode(raw)
    np.testing.assert_array_equal(back["counts"], weights)
    np.testing.assert_array_equal(back["map"], [0, 5])
    np.testing.assert_array_equal(back["cycles"], [1, 5])


@pytest.mark.parametrize("fields", [pr.FIELDS_ALL, pr.FIELD_COUNTS])
def test_link_gives_the_log_models_results(fields: int) -> None:
    """Every pass of census-lr on the log machine through the link: the log model's maps, flags, weights
    (the MAP's row weighs 2^W) and cycles."""
    left, right = _crop()
    got = _link(TwinPort(_twin())).run_frame(left, right, PARAMS, MODEL, fields)
    want = passes_model([(left, right)], MODEL, PARAMS)
    assert set(got) == {"left", "right"}
    for name, res in want.items():
        assert sorted(got[name]) == sorted(["map", "nomatch", "timeout", "counts",
                                            *(["cycles"] if fields & pr.FIELD_CYCLES else [])])
        for field in got[name]:
            np.testing.assert_array_equal(got[name][field], np.asarray(getattr(res, field)), err_msg=field)
        assert got[name]["counts"].max() == PARAMS.readout_max == 1024


def test_the_log_board_commands(tmp_path, monkeypatch, capsys) -> None:
    """``board simulate --integrator log -o OUT`` reports the log machine's design; ``run --engine board
    --integrator log`` on it writes the result.npz of ``run --engine model --integrator log``, array for
    array; a stochastic run is told the integrator differs, a stochastic option is refused, each in one
    line. The harness is stood in for by the twin at the other end of the port."""
    from bayesmachine.fpga.boards import link as link_mod
    from bayesmachine.fpga.boards import simulate as simulate_mod

    def open_twin(port: str, baud: int, timeout: float = 2.0) -> TwinPort:
        twin_port = TwinPort(_twin())
        twin_port.close = lambda: None
        return twin_port

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(simulate_mod, "BoardSimulation", StandInHarness)
    monkeypatch.setattr(link_mod, "open_port", open_twin)
    design = ["--dmax", str(DMAX), "--model", "census-lr"]
    assert main(["board", "simulate", *design, "--integrator", "log", "--width", str(WIDTH), "--quiet", "-o",
                 str(tmp_path / "sim")]) == 2  # the stand-in harness ended
    capsys.readouterr()
    report = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert report["machine"] == PARAMS.to_dict() and report["machine"]["integrator"] == "log"
    run = ["run", "--crop", f"400,250,{WIDTH},{HEIGHT}", *design, "--no-sgbm", "--quiet"]
    assert main([*run, "--integrator", "log", "--engine", "board", "--port", "twin", "-o",
                 str(tmp_path / "b")]) == 0
    assert main([*run, "--integrator", "log", "-o", str(tmp_path / "m")]) == 0
    got, want = np.load(tmp_path / "b" / "result.npz"), np.load(tmp_path / "m" / "result.npz")
    assert sorted(got.files) == sorted(want.files) and "right_map" in want.files
    for name in want.files:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert want["counts"].max() == 1024
    for extra, message in ((["--engine", "board", "--port", "twin"],
                            "--integrator stochastic here, log on the board; run with the board's options"),
                           (["--integrator", "log", "--engine", "board", "--port", "twin", "--seed", "3"],
                            "--seed: without effect on the logarithmic machine")):
        assert main([*run, *extra, "-o", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x").exists()


def test_board_build_elaborates_the_log_machine(tmp_path, monkeypatch) -> None:
    """``board build --integrator log`` builds the board's StereoMachine on the log machine (its argmin
    tree in the RTLIL Yosys gets) and goes on to place and route; the tools are stood in for, the run
    stops at nextpnr's command line."""
    from bayesmachine.fpga import flow

    class Stop(Exception):
        pass

    def fake_run(cmd: list[str], cwd, log: str, what: str, progress) -> None:
        if log == "nextpnr":
            raise Stop

    monkeypatch.setattr(flow, "_run", fake_run)
    monkeypatch.setattr(flow, "_tool", lambda name: name)
    out = tmp_path / "b"
    with pytest.raises(Stop):
        main(["board", "build", "--integrator", "log", "--dmax", "4", "--width", "16", "-o", str(out)])
    rtlil = (out / "work" / "top.il").read_text()
    assert "argmin" in rtlil and "encoder" not in rtlil  # not the stochastic machine's MAP encoder
    assert not (out / "report.json").exists()
