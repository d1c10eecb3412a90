"""Switching activity per output pixel: every register bit's toggles under Verilator on a crop of the
bundled pair, summed and by block, per model and integrator.

A technology-free proxy for dynamic energy: the harness is built with Verilator's toggle coverage
(``bayesmachine.sim.activity``) and runs the crop, with ``--feed pixels`` the StereoMachine (the
on-chip front end, every pass), with ``--feed words`` the machines alone on the host's words (each
pass's); the registers' toggles (front end, sources, likelihood memory, operators, counters, encoder,
the feedback prior, the logarithmic integrator's adders, argmin and weights, control) are divided by
the crop's output pixels. Each run is checked against the model engine (every result equal) before
its figures are printed; beside them the crop's cycles per pixel (the own pass's) and wall cycles per
output pixel (the StereoMachine's since reset; fed words, the own pass's machine's).
docs/integrators.md holds the figures measured with the command it names.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bayesmachine.argtypes import choice_of, int_in_range, value_list
from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import model_list
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import ModelParams
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import disparity_machine
from bayesmachine.params import INTEGRATORS, stereo_words_per_beat
from bayesmachine.sim.activity import BLOCKS, OTHER, directory_activity

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


def measure(name: str, integrator: str, feed: str, crop: tuple[int, int, int, int], dmax: int,
            workdir: Path) -> dict:
    """One model's crop on one integrator under activity builds, checked against the model engine."""
    x, y, w, h = crop
    left, right, _ = bundled_pair()
    model = ModelParams(name=name, dmax=dmax)
    machine = disparity_machine(model, integrator=integrator)
    if feed == "pixels":
        machine = dataclasses.replace(machine, words_per_beat=stereo_words_per_beat(machine))
    prep = prepare(left[y:y + h, x:x + w], right[y:y + h, x:x + w], model, None, reference=False)
    counts = workdir / f"{name}-{integrator}-{feed}"
    t0 = time.perf_counter()
    run = run_machine(prep, machine, engine="verilator", feed=feed,
                      engine_options={"activity": counts, "verbose": False})
    seconds = time.perf_counter() - t0
    want = run_machine(prep, machine, engine="model")
    if not (np.array_equal(run.map, want.map) and np.array_equal(run.counts, want.counts)
            and np.array_equal(run.cycles, want.cycles)):
        raise ValueError(f"{name}, {integrator}: the activity build's results differ from the model's")
    act = directory_activity(counts, run.map.size, ORDER)
    return {"activity": act, "cycles": float(run.cycles.mean()), "wall": run.wall_cycles / run.map.size,
            "seconds": seconds}


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", type=model_list, default="paper,census,census-lr",
                    help="comma-separated models (default paper,census,census-lr)")
    ap.add_argument("--crop", type=crop_arg, default="50,200,640,24",
                    help="X,Y,W,H of the bundled pair: the design's width is W (default 50,200,640,24: a "
                    "VGA-wide strip)")
    ap.add_argument("--dmax", type=int_in_range(1, 255), default=80, help="Dmax (default 80)")
    ap.add_argument("--integrators", type=value_list(choice_of(INTEGRATORS), "integrator"),
                    default="stochastic", help=f"comma-separated, of {', '.join(INTEGRATORS)} (default "
                    "stochastic)")
    ap.add_argument("--feed", type=choice_of(("pixels", "words")), default="pixels",
                    help="pixels: the StereoMachine, front end included; words: the machines alone "
                    "(default pixels)")
    args = ap.parse_args(argv)
    what = "the StereoMachine" if args.feed == "pixels" else "the machines fed words"
    print(f"register toggles per output pixel, {what} under Verilator (--coverage-toggle), crop "
          f"{','.join(map(str, args.crop))} of the bundled pair, Dmax {args.dmax}")
    print(f"{'model':<10} {'integrator':<10} {'cycles/px':>9} {'wall/px':>8} {'total':>9}  "
          + "  ".join(f"{b:>{len(b)}}" for b in ORDER))
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.models:
            for integrator in args.integrators:
                m = measure(name, integrator, args.feed, args.crop, args.dmax, Path(tmp))
                per = m["activity"].per_pixel()
                print(f"{name:<10} {integrator:<10} {m['cycles']:9.2f} {m['wall']:8.2f} {per['total']:9.0f}  "
                      + "  ".join(f"{per.get(b, 0.0):{len(b)}.1f}" for b in ORDER)
                      + f"  [{m['seconds']:.0f} s]", flush=True)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
