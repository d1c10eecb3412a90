"""Benchmark: a dataset sweep on Dask against direct runs, on this machine.

The dataset: NPAIRS crops (H x W, disjoint rows x columns) of the bundled Middlebury Motorcycle pair
with their ground truth, written as a list dataset (PNG + PFM) in a temporary directory. The grid:
--counter-max x --rng on the paper model, model engine. Measured, in one run so that the ratios
compare like with like on a shared machine:

* direct: the tasks as plain ``prepare`` (once per pair) + ``run_pair`` calls in this process
  (no files, no scheduler): the cost of the work itself;
* ``--workers 0``: the sweep engine in this process (per-task result.json, the cache);
* ``bayesmachine run`` of one task's pair and point as a command (a new process each time: imports,
  numba's cache, the report and figures): what a shell loop over the tasks would pay per task;
* a LocalCluster of 1 and of 2 worker processes (and N with --workers-max N): its start-up (processes,
  imports, numba's cache load) apart, then the sweep on it: tasks/s, the speed-up over 1 worker, the
  overhead per task against direct, and each worker's peak resident memory (VmHWM).

All sweeps must give the same sweep.json (times aside): checked. Prints figures; asserts only that.
Run: python benchmarks/bench_sweep.py [--pairs 8] [--size 96x160] [--dmax 40]
     [--counter-max 4,16] [--rng sobol,lfsr] [--workers-max 2]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from bayesmachine.cli import Parser, build_parser, run_script
from bayesmachine.cliargs import counter_max_list, int_in_range, rng_list, size_pair
from bayesmachine.host.datasets import load_pair, resolve_dataset, write_pfm
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.reference import warm_up
from bayesmachine.host.run import prepare, run_pair
from bayesmachine.host.sweep import (
    SweepConfig,
    _local_cluster,
    clear_cache,
    run_sweep,
    strip_timings,
    sweep_points,
)
from bayesmachine.params import MAX_DMAX


def write_dataset(root: Path, pairs: int, h: int, w: int) -> Path:
    left, right, gt = bundled_pair()
    rows, cols = left.shape[0] // h, left.shape[1] // w
    if pairs > rows * cols:
        raise SystemExit(f"only {rows * cols} disjoint {w}x{h} crops in the "
                         f"{left.shape[1]}x{left.shape[0]} pair")
    lines = []
    for i in range(pairs):
        y, x = (i // cols) * h, (i % cols) * w
        for name, im in (("l", left), ("r", right)):
            cv2.imwrite(str(root / f"{name}{i}.png"), im[y : y + h, x : x + w])
        write_pfm(root / f"g{i}.pfm", gt[y : y + h, x : x + w])
        lines.append(f"l{i}.png r{i}.png g{i}.pfm")
    (root / "pairs.txt").write_text("\n".join(lines) + "\n")
    return root / "pairs.txt"


def peak_rss() -> int:
    """This process's peak resident memory: VmHWM (ru_maxrss would carry the parent's peak across the
    fork + exec that starts a worker process)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def cpu_seconds() -> float:
    """This process's CPU time (user + system): unlike wall time, not inflated by other sessions' load."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int_in_range(1, 1000), default=8)
    ap.add_argument("--size", type=size_pair("HxW", (16, 16), (500, 741)), default="96x160",
                    help="crop HxW (the bundled pair's 500 x 741 at most)")
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=40)
    ap.add_argument("--counter-max", type=counter_max_list, default="4,16")
    ap.add_argument("--rng", type=rng_list, default="sobol,lfsr")
    ap.add_argument("--workers-max", type=int_in_range(1, 2 * (os.cpu_count() or 1)), default=2)
    ap.add_argument("--rounds", type=int_in_range(1, 100), default=3,
                    help="measure every configuration this many times, interleaved (a shared machine's load "
                    "changes by the minute): the summary takes each one's best and median")
    a = ap.parse_args(argv)
    h, w = a.size
    tmp = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    data = write_dataset(tmp, a.pairs, h, w)
    args = build_parser().parse_args(["sweep", "--dmax", str(a.dmax), "--counter-max",
                                      ",".join(map(str, a.counter_max)), "--rng", ",".join(a.rng), "-o", "x"])
    points = sweep_points(args)
    pairs = resolve_dataset([str(data)]).pairs
    tasks = len(pairs) * len(points)
    print(f"{len(pairs)} pairs of {w}x{h} px (Dmax {a.dmax}) x {len(points)} points = {tasks} tasks; "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start (a shared machine)")

    loaded = [load_pair(p) for p in pairs]
    prepare(*loaded[0][:2], points[0].model, loaded[0][2])  # numba's cache load out of the timing

    def direct() -> float:
        """The same work as plain calls (a pair prepared once, as the sweep's cache does)."""
        t0, c0 = time.perf_counter(), cpu_seconds()
        for (left, right, gt) in loaded:
            prep = prepare(left, right, points[0].model, gt)
            for i, point in enumerate(points):
                run_pair(left, right, point.model, point.machine, prepared=prep, progress=False, sgbm=i == 0)
        return {"seconds": time.perf_counter() - t0, "cpu": cpu_seconds() - c0}

    results = {}

    def sweep(label: str, workers: int) -> dict[str, float]:
        out = tmp / f"out-{label}"
        config = SweepConfig(pairs=pairs, points=points, output=out, workers=workers)
        client = cluster = None
        start = 0.0
        if workers:
            t = time.perf_counter()
            client, cluster = _local_cluster(workers)
            # Warm each worker as its first task would (imports, numba's cache), so that start-up is apart.
            client.run(warm_up, points[0].model)
            start = time.perf_counter() - t
        else:
            clear_cache()
        try:
            worker_cpu = sum(client.run(cpu_seconds).values()) if client else 0.0
            t, c = time.perf_counter(), cpu_seconds()
            run_sweep(config, client=client)
            seconds = time.perf_counter() - t
            cpu = cpu_seconds() - c + (sum(client.run(cpu_seconds).values()) - worker_cpu if client else 0.0)
            rss = max(client.run(peak_rss).values()) if client else peak_rss()
        finally:
            if client is not None:
                client.close()
                cluster.close()
        results[label] = strip_timings(json.loads((out / "sweep.json").read_text()))
        # The sweep's fixed cost (read the results, pool, plot, commit): a --resume of the complete sweep.
        t, c = time.perf_counter(), cpu_seconds()
        run_sweep(SweepConfig(pairs=pairs, points=points, output=out, resume=True))
        fixed, fixed_cpu = time.perf_counter() - t, cpu_seconds() - c
        return {"start": start, "seconds": seconds, "fixed": fixed, "rss": rss, "cpu": cpu,
                "fixed_cpu": fixed_cpu}

    def command() -> dict[str, float]:
        spec, point = pairs[0], points[0]
        argv = [sys.executable, "-m", "bayesmachine", "run", spec.left, spec.right, "--gt", spec.gt,
                "--dmax", a.dmax, "--counter-max", str(point.machine.counter_max), "--rng", point.machine.rng,
                "--quiet", "-o", str(tmp / "run-out")]
        t0 = time.perf_counter()
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(argv, check=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        return {"seconds": time.perf_counter() - t0, "cpu": cpu}

    configs = [("direct", -1), ("in this process", 0)] + [
        (f"{n} worker process{'es' if n > 1 else ''}", n) for n in range(1, a.workers_max + 1)]
    runs: dict[str, list[dict[str, float]]] = {label: [] for label, _ in configs}
    for r in range(a.rounds):
        for label, workers in configs:
            m = direct() if workers < 0 else sweep(label, workers)
            if workers < 0:
                runs.setdefault("bayesmachine run", []).append(command())
            runs[label].append(m)
            print(f"round {r + 1}: {label:<20} {m['seconds']:6.2f} s, {m['cpu']:6.2f} CPU s"
                  + (f" (+ {m['start']:.2f} s cluster start-up)" if m.get("start") else ""), flush=True)

    def best(label: str, key: str = "seconds") -> float:  # the least disturbed run
        return min(m[key] for m in runs[label])

    def median(label: str) -> float:
        return float(np.median([m["seconds"] for m in runs[label]]))

    d = best("direct")
    print(f"\nbest (median) of {a.rounds} rounds, {tasks} tasks; "
          f"load average {os.getloadavg()[0]:.1f} at the end")
    dc = best("direct", "cpu")
    print(f"{'direct':<20} {d:6.2f} s ({median('direct'):6.2f}), {tasks / d:5.2f} tasks/s, "
          f"{d / tasks * 1000:.0f} ms per task; CPU {dc / tasks * 1000:.0f} ms per task")
    run_s, run_cpu = best("bayesmachine run"), best("bayesmachine run", "cpu")
    print(f"{'bayesmachine run':<20} {run_s:6.2f} s ({median('bayesmachine run'):6.2f}) for one task as a "
          f"command, CPU {run_cpu:.2f} s: {run_s - d / tasks:+.2f} s "
          f"({run_cpu - dc / tasks:+.2f} CPU s) over "
          f"the direct task")
    for label, workers in configs[1:]:
        s = best(label)
        fixed = float(np.median([m["fixed"] for m in runs[label]]))
        over = (s - fixed - d / max(workers, 1)) / tasks * 1000
        line = (f"{label:<20} {s:6.2f} s ({median(label):6.2f}), {tasks / s:5.2f} tasks/s, "
                f"of it {fixed:.2f} s pooling + plotting; overhead {over:+4.0f} ms per task vs "
                f"direct / workers; "
                f"peak memory per "
                f"{'worker' if workers else 'process'} {max(m['rss'] for m in runs[label]) / 2**20:.0f} MiB")
        cpu_over = (best(label, "cpu") - float(np.median([m["fixed_cpu"] for m in runs[label]])) - dc) / tasks
        line += f"; CPU overhead {cpu_over * 1000:+4.0f} ms per task"
        if workers:
            line += f"; cluster start-up {best(label, 'start'):.2f} s"
        if workers > 1:
            line += f"; speed-up over 1 worker {best('1 worker process') / s:.2f}x"
        print(line)
    first = next(iter(results.values()))
    assert all(r == first for r in results.values()), "the sweeps differ"
    print(f"all {len(results)} sweep configurations gave the same sweep.json (times aside)")


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
