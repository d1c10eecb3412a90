"""Benchmark: the machine model on a VGA frame (a 640x480 crop of the bundled Motorcycle pair).

Prints, per counter max: model (engine) seconds per frame, likelihood-memory build time,
cycles per pixel and the comparison figures. Asserts nothing. Run:
    python benchmarks/bench_model.py [--counter-max 1,16] [--engine model] [--rng lfsr,sobol]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import counter_max_list, rng_list
from bayesmachine.host.images import Crop, bundled_pair, crop_image
from bayesmachine.host.metrics import evaluate
from bayesmachine.host.run import ENGINES, prepare, run_machine
from bayesmachine.models import ModelParams
from bayesmachine.params import DEFAULT_RNG, MachineParams


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counter-max", type=counter_max_list, default="1,16")
    ap.add_argument("--engine", choices=ENGINES, default="model")
    ap.add_argument("--rng", type=rng_list, default=DEFAULT_RNG, help="comma-separated random sources")
    args = ap.parse_args(argv)
    crop = Crop(50, 10, 640, 480)
    left, right, gt = (crop_image(a, crop) for a in bundled_pair())
    model = ModelParams(name="paper")
    prep = prepare(left, right, model, gt)
    ho, wo = prep.shape
    print(
        f"Motorcycle crop {crop} (640x480), Dmax {model.dmax}: {ho}x{wo} = {ho * wo} output pixels; "
        f"reference {prep.reference_seconds:.3f} s"
    )
    for kind, n in ((k, v) for k in args.rng for v in args.counter_max):
        machine = MachineParams.for_disparity(model.dmax, counter_max=n, rng=kind)
        t0 = time.perf_counter()
        run = run_machine(prep, machine, args.engine, progress=False)
        wall = time.perf_counter() - t0
        r = evaluate(prep, run, sgbm=False).to_report()
        cycles = int(run.cycles.sum())
        print(
            f"{kind} counter max {n:3d}: engine {run.seconds:6.2f} s/frame, "
            f"words {run.words_seconds:5.2f} s, wall {wall:6.2f} s"
        )
        print(
            f"    cycles/px {r['cycles_per_pixel_mean']:.2f} +- {r['cycles_per_pixel_std']:.2f} "
            f"(p99 {r['cycles_per_pixel_p99']:.0f}), {cycles} cycles/frame "
            f"= {500e6 / max(1, cycles):.1f} frames/s at 500 MHz"
        )
        print(
            f"    RMS {r['rms_error']:.4f}, no-match F1 {r['nomatch_f1']:.4f}, "
            f"MAP agreement {r['map_agreement']:.4f}, timeouts {r['timeouts']}"
        )


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
