"""Benchmark: peak memory (RSS) of ``bayesmachine run`` and ``reference`` on large pairs.

Each case runs the real command in its own child process; the peak RSS is that child's
``ru_maxrss`` (read with ``resource.getrusage(RUSAGE_CHILDREN)`` by a small wrapper process
that runs nothing else). Pairs are synthetic random-dot stereograms written as PNG first.
Goal: <= 3 GiB for a 3000x2000 pair at Dmax 80, counter max 16 (model engine). Prints
figures, asserts nothing. Run:
    python benchmarks/bench_memory.py [--sizes 640x480,3000x2000] [--keep DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import MAX_COUNTER_MAX, input_path, int_in_range, size_pair, value_list
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.outputs import format_bytes
from bayesmachine.params import MAX_DMAX
from bayesmachine.region import OutputRegion

# Runs one command and prints its peak RSS in bytes (ru_maxrss is in KiB on Linux).
WRAPPER = (
    "import resource, subprocess, sys; "
    "rc = subprocess.run(sys.argv[1:]).returncode; "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024, rc)"
)


def peak_rss(cmd: list[str]) -> tuple[int, int, float]:
    """(peak RSS bytes, exit code, seconds) of ``cmd`` run in a fresh child."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", WRAPPER, *cmd], capture_output=True, text=True, check=True)
    seconds = time.perf_counter() - t0
    rss, rc = out.stdout.split()[-2:]
    return int(rss), int(rc), seconds


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=value_list(size_pair("WxH", (64, 64), (16384, 16384)), "size"),
                    default="640x480,3000x2000", help="WxH pairs, comma-separated, 64 .. 16384 each way")
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16)
    ap.add_argument("--keep", type=input_path, default=None, help="keep inputs and outputs in this directory")
    args = ap.parse_args(argv)
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_memory_"))
    work.mkdir(parents=True, exist_ok=True)
    cli = [sys.executable, "-m", "bayesmachine"]
    baseline, _, _ = peak_rss([sys.executable, "-c", "import bayesmachine.host.run"])
    print(f"python + imports alone: peak RSS {format_bytes(baseline)}")
    for w, h in args.sizes:
        left, right, _ = random_dot_stereogram(height=h, width=w, background=20, square=50, dot=2, seed=1)
        lp, rp = work / f"l{w}x{h}.png", work / f"r{w}x{h}.png"
        cv2.imwrite(str(lp), left)
        cv2.imwrite(str(rp), right)
        region = OutputRegion.of_image((h, w), args.dmax)
        volume = region.pixels * (args.dmax + 2) * 8
        print(
            f"{w}x{h}, Dmax {args.dmax}: {region.shape[0]}x{region.shape[1]} = {region.pixels} output "
            f"pixels; the whole float64 posterior would be {format_bytes(volume)}"
        )
        run_cmd = [*cli, "run", str(lp), str(rp), "--dmax", str(args.dmax), "--counter-max",
                   str(args.counter_max), "--engine", "model", "--no-sgbm", "--quiet",
                   "-o", str(work / f"run{w}")]
        rss, rc, seconds = peak_rss(run_cmd)
        print(f"  run (model, counter max {args.counter_max}): peak RSS {format_bytes(rss)}, "
              f"{seconds:.1f} s, exit {rc}")
        if volume < 1 << 30:  # reference -o writes the whole volume to disk: keep the disk use small
            ref_cmd = [*cli, "reference", str(lp), str(rp), "--dmax", str(args.dmax), "--quiet",
                       "-o", str(work / f"ref{w}.npz")]
            rss, rc, seconds = peak_rss(ref_cmd)
            print(f"  reference -o (posterior written band by band): peak RSS {format_bytes(rss)}, "
                  f"{seconds:.1f} s, exit {rc}")
    if args.keep is None:
        import shutil

        shutil.rmtree(work)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
