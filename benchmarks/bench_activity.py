"""Switching activity per output pixel: every register bit's toggles in the StereoMachine under
Verilator on a crop of the bundled pair, summed and by block, per model.

A technology-free proxy for dynamic energy: the harness is built with Verilator's toggle coverage
(``bayesmachine.sim.activity``), runs the crop with ``--feed pixels`` (the on-chip front end, every
pass), and the registers' toggles of the frame (front end, sources, likelihood memory, operators,
counters, encoder, the feedback prior, control) are divided by its output pixels. Each run is checked
against the model engine on the host's words (every result equal) before its figures are printed;
the crop's cycles per pixel are printed beside them. docs/integrators.md holds the figures measured
with the command it names.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bayesmachine.argtypes import int_in_range
from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import model_list
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import ModelParams
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import disparity_machine
from bayesmachine.params import stereo_words_per_beat
from bayesmachine.sim.activity import BLOCKS, OTHER, activity
from bayesmachine.sim.stereo_engine import build_stereo_harness

ORDER = tuple(dict.fromkeys([b for b, _, _ in BLOCKS] + [OTHER]))


def crop_arg(text: str) -> tuple[int, int, int, int]:
    """``X,Y,W,H`` inside the bundled pair (741 x 500)."""
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,W,H, got {text!r}") from None
    if not (0 <= x and 0 <= y and w > 0 and h > 0 and x + w <= 741 and y + h <= 500):
        raise argparse.ArgumentTypeError(f"the crop {text!r} is not inside the bundled pair (741 x 500)")
    return x, y, w, h


def measure(name: str, crop: tuple[int, int, int, int], dmax: int, workdir: Path) -> dict:
    """One model's crop under the activity build: its activity, checked against the model engine."""
    x, y, w, h = crop
    left, right, gt = bundled_pair()
    model = ModelParams(name=name, dmax=dmax)
    machine = disparity_machine(model)
    machine = dataclasses.replace(machine, words_per_beat=stereo_words_per_beat(machine))
    prep = prepare(left[y:y + h, x:x + w], right[y:y + h, x:x + w], model, None, reference=False)
    coverage = workdir / f"{name}.dat"
    t0 = time.perf_counter()
    run = run_machine(prep, machine, engine="verilator", feed="pixels",
                      engine_options={"activity": coverage, "verbose": False})
    seconds = time.perf_counter() - t0
    want = run_machine(prep, machine, engine="model")
    if not (np.array_equal(run.map, want.map) and np.array_equal(run.counts, want.counts)
            and np.array_equal(run.cycles, want.cycles)):
        raise SystemExit(f"bench_activity: {name}: the activity build's results differ from the model's")
    build = build_stereo_harness(machine, model, w, activity=True, verbose=False)
    act = activity(coverage, build.directory / "bayesmachine.v", run.map.size, ORDER)
    return {"activity": act, "cycles": float(run.cycles.mean()), "seconds": seconds}


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=model_list, default="paper,census,census-lr",
                    help="comma-separated models (default paper,census,census-lr)")
    ap.add_argument("--crop", type=crop_arg, default="50,200,640,24",
                    help="X,Y,W,H of the bundled pair: the design's width is W (default 50,200,640,24: a "
                    "VGA-wide strip)")
    ap.add_argument("--dmax", type=int_in_range(1, 255), default=80, help="Dmax (default 80)")
    args = ap.parse_args(argv)
    print(f"register toggles per output pixel, StereoMachine under Verilator (--coverage-toggle), crop "
          f"{','.join(map(str, args.crop))} of the bundled pair, Dmax {args.dmax}")
    print(f"{'model':<10} {'cycles/px':>9} {'total':>9}  " + "  ".join(f"{b:>{len(b)}}" for b in ORDER))
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.models:
            m = measure(name, args.crop, args.dmax, Path(tmp))
            per = m["activity"].per_pixel()
            print(f"{name:<10} {m['cycles']:9.2f} {per['total']:9.0f}  "
                  + "  ".join(f"{per.get(b, 0.0):{len(b)}.1f}" for b in ORDER)
                  + f"  [{m['seconds']:.0f} s]", flush=True)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
