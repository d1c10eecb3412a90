"""Benchmark: how fast the ``pysim`` engine (the RTL in Amaranth's Python simulator) runs.

Runs the first pixels of the bundled Motorcycle pair's paper-model words (the host's likelihood
memories, map rows from the middle of the image) through ``pysim`` for a machine of Dmax = DMAX,
checks them against the model and prints the simulated clock cycles per second of wall time and of
the process's CPU time (the figure of an idle core on a shared machine; loading included:
the engine's ``wall_cycles``), after a first call of a few pixels that builds the simulation. Run:
    python benchmarks/bench_pysim.py [--dmax 80] [--pixels 40]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from bayesmachine.cli import Parser
from bayesmachine.cliargs import MAX_COUNTER_MAX, int_in_range
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import ModelParams, memory_words
from bayesmachine.params import MAX_DMAX, MachineParams
from bayesmachine.sim.engines import get_engine


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16)
    ap.add_argument("--pixels", type=int_in_range(1, 100_000), default=40,
                    help="pixels to run, 1 .. 100000 (default 40)")
    args = ap.parse_args(argv)

    machine = MachineParams.for_disparity(args.dmax, counter_max=args.counter_max)
    model = ModelParams(name="paper", dmax=args.dmax)
    left, right, _ = bundled_pair()
    y = left.shape[0] // 2
    words = memory_words(feature_sums(left), feature_sums(right), model, machine, rows=slice(y, y + 1))
    words = words[: args.pixels]
    warm = 4  # pixels of the first call, which builds the simulation
    with get_engine("model", machine) as reference:  # the same two calls: the state carries over
        want = (reference.run(words[:warm]), reference.run(words[warm:]))
    with get_engine("pysim", machine) as engine:
        t0 = time.perf_counter()
        first = engine.run(words[:warm])
        t1, cpu = time.perf_counter(), time.process_time()
        start = engine.wall_cycles
        rest = engine.run(words[warm:])
        seconds, cpu = time.perf_counter() - t1, time.process_time() - cpu
        cycles = engine.wall_cycles - start
    equal = first.equal(want[0]) and rest.equal(want[1])
    print(f"pysim, Dmax {args.dmax} ({machine.operators} operators), counter max {args.counter_max}: "
          f"first call ({warm} pixels, building the simulation) {t1 - t0:.1f} s; then {len(words) - warm} "
          f"pixels, {cycles} clock cycles in {seconds:.1f} s: {cycles / seconds:,.0f} cycles/s, "
          f"{cycles / cpu:,.0f} per CPU second (compute cycles per pixel {rest.cycles.mean():.1f}); "
          f"equal to the model: {equal}")
    return 0 if equal else 1


if __name__ == "__main__":
    raise SystemExit(main())
