"""Switching activity per decision of the classifier top (``emit --top classifier``): every register
bit's toggles under Verilator on a held-out fold, by block, per data set and integrator.

The StereoMachine's mechanism (``bayesmachine.sim.activity``, ``benchmarks/bench_activity.py``): the
top's harness (``sim/classifier_verilator.py``) is built with Verilator's toggle coverage; its tables
are loaded in one batch, then fold 0's held-out observations of a seeded 5-fold split (split seed 0)
in another, whose registers' toggles (the top's table reads and sums, the machine's likelihood
memory, operators, counters, encoder, sources, the log machine's adders, argmin and weights, control)
are divided by its decisions. Each run is checked against the model (MAP, counters or weights, cycles)
before its figures are printed; beside them the mean cycles and the wall cycles per decision (the
batch's, first observation presented to last result). docs/classifier.md holds the figures.

    python benchmarks/bench_classifier_activity.py --datasets digits,iris --integrators stochastic,log
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from bayesmachine.argtypes import choice_of, int_in_range, value_list
from bayesmachine.classify import DEFAULT_BINS, MAX_BINS
from bayesmachine.cli import Parser, run_script
from bayesmachine.host.classification import BUNDLED_DATASETS, check_top_run, held_out
from bayesmachine.params import INTEGRATORS
from bayesmachine.sim.activity import BLOCKS, OTHER, Activity, directory_activity

ORDER = tuple(dict.fromkeys([b for b, _, _ in BLOCKS if b != "front end"] + [OTHER]))


def measure(dataset: str, integrator: str, bins: int, decisions: int | None, workdir: Path) -> dict:
    """One data set's held-out fold through the top of one integrator under an activity build."""
    from bayesmachine.sim.classifier_verilator import run_classifier_verilator

    held = held_out(dataset, bins=bins, machine={"integrator": integrator}, decisions=decisions)
    counts = workdir / f"{dataset}-{integrator}"
    t0 = time.perf_counter()
    run = run_classifier_verilator(held.machine, held.observed, held.bins, activity=counts, verbose=True)
    seconds = time.perf_counter() - t0
    check_top_run(held, run.result, "Verilator")
    n = len(held.observed)
    act: Activity = directory_activity(counts, n, ORDER)
    return {"activity": act, "decisions": n, "cycles": float(run.result.cycles.mean()),
            "wall": run.wall_cycles / n, "seconds": seconds}


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--datasets", type=value_list(choice_of(BUNDLED_DATASETS), "data set"),
                    default="digits,iris",
                    help=f"comma-separated, of {', '.join(BUNDLED_DATASETS)} (default digits,iris)")
    ap.add_argument("--integrators", type=value_list(choice_of(INTEGRATORS), "integrator"),
                    default=",".join(INTEGRATORS), help=f"comma-separated (default {','.join(INTEGRATORS)})")
    ap.add_argument("--bins", type=int_in_range(1, MAX_BINS), default=DEFAULT_BINS,
                    help=f"bins per feature (default {DEFAULT_BINS})")
    ap.add_argument("--decisions", type=int_in_range(1, 100_000), default=None,
                    help="the first N held-out observations (default: the whole fold)")
    args = ap.parse_args(argv)
    print("register toggles per decision, the classifier top under Verilator (--coverage-toggle), fold 0 "
          f"of a stratified 5-fold split (split seed 0), {args.bins} bins")
    print(f"{'data set':<13} {'integrator':<10} {'decisions':>9} {'cycles':>7} {'wall':>6} {'total':>8}  "
          + "  ".join(ORDER))
    with tempfile.TemporaryDirectory() as tmp:
        for dataset in args.datasets:
            for integrator in args.integrators:
                m = measure(dataset, integrator, args.bins, args.decisions, Path(tmp))
                per = m["activity"].per_pixel()
                print(f"{dataset:<13} {integrator:<10} {m['decisions']:9d} {m['cycles']:7.2f} "
                      f"{m['wall']:6.2f} {per['total']:8.1f}  "
                      + "  ".join(f"{per.get(b, 0.0):{len(b)}.1f}" for b in ORDER)
                      + f"  [{m['seconds']:.0f} s]", flush=True)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
