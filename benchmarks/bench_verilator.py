"""Benchmark: a whole VGA frame through the RTL with the Verilator engine, checked against the model.

The frame is a 640x480 crop of the bundled Motorcycle pair (the host's likelihood memories);
with Dmax = 80 that is 476 x 556 = 264,656 pixels. Without the host package, synthetic
disparity-like memories of the same size are used. Prints the build time, frame time (engine
only, and with the likelihood memories), simulated clock cycles per second, compute vs wall
cycles per pixel and whether every result equals the model's. Run:
    python benchmarks/bench_verilator.py [--counter-max 16] [--chunk-rows 8] [--no-model]
        [--result-stall P] [--load-stall P]   (random back-pressure: the slower back-pressure build)
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import MAX_COUNTER_MAX, float_in_range, input_path, int_in_range
from bayesmachine.hdl.machine import pixel_wall_cycles
from bayesmachine.params import MAX_DMAX, MachineParams
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.verilator import VerilatorEngine

Frame = tuple[str, int, Callable[[], Iterator[np.ndarray]]]  # description, pixels, chunk iterator


def host_frame(machine: MachineParams, chunk_rows: int) -> Frame:
    """Likelihood memories of the VGA Motorcycle crop, chunk_rows map rows at a time."""
    from bayesmachine.host.features import feature_sums
    from bayesmachine.host.images import Crop, bundled_pair, crop_image
    from bayesmachine.host.likelihoods import memory_words
    from bayesmachine.models import ModelParams

    crop = Crop(50, 10, 640, 480)
    left, right, _ = (crop_image(a, crop) for a in bundled_pair())
    model = ModelParams(name="paper", dmax=machine.rows - 2)
    lf, rf = feature_sums(left), feature_sums(right)
    ho = lf.shape[0]
    wo = lf.shape[1] - model.dmax

    def chunks() -> Iterator[np.ndarray]:
        for y in range(0, ho, chunk_rows):
            yield memory_words(lf, rf, model, machine, rows=slice(y, min(ho, y + chunk_rows)))

    return f"Motorcycle crop {crop} (host likelihoods)", ho * wo, chunks


def synthetic_frame(machine: MachineParams, chunk_rows: int) -> Frame:
    """Disparity-like memories: a few likely hypotheses per pixel, the rest unlikely."""
    ho, wo = 476, 556
    one = machine.word_one

    def chunks() -> Iterator[np.ndarray]:
        rng = np.random.default_rng(0)
        for y in range(0, ho, chunk_rows):
            n = min(chunk_rows, ho - y) * wo
            w = rng.integers(20, 120, size=(n, machine.rows, machine.operator_columns)).astype(np.uint16)
            for _ in range(3):
                good = rng.integers(0, machine.rows - 1, size=n)
                w[np.arange(n), good] = rng.integers(one // 2, one + 1, size=(n, machine.operator_columns))
            w[:, -1, 0] = rng.integers(10, 300, size=n)
            w[:, -1, 1:] = one
            yield w

    return "synthetic disparity-like memories", ho * wo, chunks


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16)
    ap.add_argument("--chunk-rows", type=int_in_range(1, 4096), default=8,
                    help="map rows per engine call (host-like chunks)")
    ap.add_argument("--build-dir", type=input_path, default=None,
                    help="build cache (default: the user cache)")
    ap.add_argument("--no-model", action="store_true", help="skip the bit-exact comparison with the model")
    ap.add_argument("--synthetic", action="store_true", help="synthetic memories even if the host is there")
    ap.add_argument("--result-stall", type=float_in_range(0, 0.999), default=0.0,
                    help="probability of a low result.ready per cycle (the back-pressure build; default 0)")
    ap.add_argument("--load-stall", type=float_in_range(0, 0.999), default=0.0,
                    help="probability of a low load.valid per cycle (default 0)")
    args = ap.parse_args(argv)

    machine = MachineParams.for_disparity(args.dmax, counter_max=args.counter_max)
    t0 = time.perf_counter()
    engine = VerilatorEngine(machine, build_dir=args.build_dir, result_stall=args.result_stall,
                             load_stall=args.load_stall, stall_seed=1)
    built = time.perf_counter() - t0
    how = f"compiled in {engine.build.seconds:.1f} s" if engine.compiled else (
        f"cached build (compiled once in {engine.build.seconds:.1f} s)")
    stalls = f", stalls: load {args.load_stall}, result {args.result_stall}" if (
        args.load_stall or args.result_stall) else ""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    children_cpu = children.ru_utime + children.ru_stime
    print(f"Verilator engine, Dmax {args.dmax}, counter max {args.counter_max}{stalls}: {how}; "
          f"engine ready in {built:.1f} s ({engine.build.directory})")

    source = synthetic_frame
    if not args.synthetic:
        try:
            import bayesmachine.host.likelihoods  # noqa: F401

            source = host_frame
        except ImportError:
            print("bayesmachine.host not available: synthetic memories")
    name, pixels, chunks = source(machine, args.chunk_rows)
    print(f"frame: {name}, {pixels} pixels, {args.chunk_rows} map rows per call")

    model = None if args.no_model else MachineModel(machine)
    engine_s = words_s = model_s = 0.0
    equal = True
    n = alone = 0
    t_words = time.perf_counter()
    for words in chunks():
        t1 = time.perf_counter()
        words_s += t1 - t_words
        res = engine.run(words)
        t2 = time.perf_counter()
        engine_s += t2 - t1
        if model is not None:
            equal &= res.equal(model.run(words))
            model_s += time.perf_counter() - t2
        n += len(words)
        alone += int(pixel_wall_cycles(machine, res.cycles, res.timeout).sum())
        t_words = time.perf_counter()
    engine.close()  # the harness process ends: its CPU time is counted among the children's
    harness_cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    harness_cpu = harness_cpu.ru_utime + harness_cpu.ru_stime - children_cpu
    st = engine.stats
    compute, wall = st["compute_cycles"], st["wall_cycles"]
    print(f"frame time: {engine_s:.2f} s in the engine, {engine_s + words_s:.2f} s with the likelihood "
          f"memories ({words_s:.2f} s)")
    print(f"simulated: {wall} clock cycles, {wall / engine_s / 1e6:.2f} M cycles/s; "
          f"{engine_s / n * 1e6:.1f} us per pixel; the harness's CPU time {harness_cpu:.2f} s, "
          f"{wall / harness_cpu / 1e6:.2f} M cycles per CPU second")
    print(f"cycles per pixel: compute {compute / n:.3f}, wall {wall / n:.3f} (loading included; "
          f"difference {(wall - compute) / n:.3f})")
    # A run costs its compute cycles plus the registered stop's bubble, and the load stream must
    # keep up: pixel_wall_cycles is that per pixel with loads and results never waiting.
    print(f"the machine at full rate (compute + bubble, pixel_wall_cycles): {alone / n:.3f} per pixel; "
          f"the engine's feeding adds {100 * (wall - alone) / alone:.2f} %")
    if model is not None:
        print(f"results equal to the model: {'yes' if equal else 'NO'} (model {model_s:.2f} s)")
    goal = engine_s + words_s <= 60 and (wall <= 1.01 * alone or bool(args.result_stall or args.load_stall))
    verdict = "met" if goal else "NOT met"
    print(f"goal (<= 60 s per VGA frame, wall within 1 % of the machine at full rate): {verdict}")
    return 0 if equal else 1


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
