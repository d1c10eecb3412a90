"""Benchmark: cycles per pixel against B, the random samples per operator and clock.

On the bundled pair with the model engine, for each model (default: census and census-lr, their
default machines: sobol, counter max 16, W = 10) and each B of ``--samples`` (default 1, 2, 4, 8,
16), one whole run (``run_machine``, both passes for census-lr) and per line: the compute cycles per
output pixel in clocks (mean over both passes for census-lr, then the left and right passes' means,
the median and p99), their ratio to B = 1's, the wall cycles per pixel of the machine fed words at
full rate (``pixel_wall_cycles``: the load stream's ``beats_per_pixel + 2`` bound, then the same
with a pixel's words in one beat), the timeouts, and whether the maps, no-match flags, timeouts and
counts (both passes) equal B = 1's bit for bit, as they must. Prints figures; asserts nothing.
Run: python benchmarks/bench_samples.py [--models census,census-lr] [--samples 1,2,4,8,16]
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import int_of, model_list, value_list
from bayesmachine.hdl.machine import pixel_wall_cycles
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import ModelParams
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import disparity_machine
from bayesmachine.params import SAMPLES_PER_CLOCK


def wall(machine, cycles: np.ndarray, timeout: np.ndarray, one_beat: bool = False) -> float:  # noqa: ANN001
    """Mean wall cycles per pixel at full rate; ``one_beat``: a pixel's words in one load beat."""
    if one_beat:
        machine = dataclasses.replace(machine, words_per_beat=machine.words_per_pixel)
    return float(pixel_wall_cycles(machine, cycles, timeout).mean())


def same(a, b) -> bool:  # noqa: ANN001
    """Maps, no-match flags, timeouts and counts equal (and the right pass's map)."""
    names = ("map", "nomatch", "timeout", "counts")
    equal = all(np.array_equal(getattr(a, f), getattr(b, f)) for f in names)
    for name, r in a.passes.items():
        other = b.passes[name]
        equal &= np.array_equal(r.map, other.map) and np.array_equal(r.timeout, other.timeout)
    return equal


def measure(prep, model: ModelParams, b: int) -> dict:  # noqa: ANN001
    """One whole run of ``model``'s default machine at B = ``b`` on the prepared pair: its figures and
    the run (``run``) and machine (``machine``) themselves."""
    machine = disparity_machine(model, samples_per_clock=b)
    t0 = time.perf_counter()
    run = run_machine(prep, machine, "model", progress=False)
    seconds = time.perf_counter() - t0
    c, r = run.cycles, run.passes.get("right")
    both = (c.sum() + (r.cycles.sum() if r is not None else 0)) / c.size
    walls = wall(machine, c, run.timeout), wall(machine, c, run.timeout, one_beat=True)
    if r is not None:  # the right pass's wall cycles per output pixel
        scale = r.cycles.size / c.size
        walls = (walls[0] + scale * wall(r.machine, r.cycles, r.timeout),
                 walls[1] + scale * wall(r.machine, r.cycles, r.timeout, one_beat=True))
    return {"machine": machine, "run": run, "seconds": seconds, "cycles_per_pixel": float(both),
            "wall_cycles_per_pixel": walls[0], "wall_cycles_per_pixel_one_beat": walls[1],
            "timeouts": int(run.timeout.sum())}


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", type=model_list, default="census,census-lr",
                    help="comma-separated models (default census,census-lr)")
    ap.add_argument("--samples", type=value_list(int_of(SAMPLES_PER_CLOCK), "B"), default="1,2,4,8,16",
                    help="the B to compare with B = 1, comma-separated; B = 1 always runs, first: the "
                    "ratios and the bit-for-bit check are against it (default 1,2,4,8,16)")
    args = ap.parse_args(argv)
    samples = sorted({1, *args.samples})
    left, right, gt = bundled_pair()
    print("model      B  cycles/px (left, right; median, p99)             x B=1   wall/px (1 beat)  "
          "timeouts  = B=1")
    for name in args.models:
        model = ModelParams(name=name)
        prep = prepare(left, right, model, gt, reference=False)
        base = None
        for b in samples:  # ascending: B = 1 first, the base of every ratio and comparison
            m = measure(prep, model, b)
            run, both = m["run"], m["cycles_per_pixel"]
            base = base or m
            assert base["machine"].samples_per_clock == 1
            c, r = run.cycles, run.passes.get("right")
            ratio = both / base["cycles_per_pixel"]
            passes = f"{c.mean():.2f}, {r.cycles.mean():.2f}" if r is not None else f"{c.mean():.2f}"
            spread = f"{np.median(c):.0f}, {np.percentile(c, 99):.0f}"
            print(f"{name:<10} {b:2d}  {both:7.2f} ({passes}; {spread})"
                  f"{'':<{max(0, 24 - len(passes))}} {ratio:6.3f}  {m['wall_cycles_per_pixel']:7.2f} "
                  f"({m['wall_cycles_per_pixel_one_beat']:6.2f})  {m['timeouts']:8d}  "
                  f"{same(run, base['run'])!s:<5} [{m['seconds']:.0f} s]", flush=True)

if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
