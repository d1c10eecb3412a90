"""The classifier's figures (docs/classifier.md): seeded k-fold accuracy of the machine against the exact
naive Bayes on the same bins, CategoricalNB and GaussianNB, on scikit-learn's bundled data sets.

Sections (``--what``):

- ``bins``: the exact naive Bayes and the log machine per count of quantile bins (the default's choice);
- ``integrators``: the stochastic machine (counter max ``--counter-max``) and the log machine, fused into
  one energy column, with their cycles per decision and confidence ECE;
- ``layouts``: fused into K = 1, 2, 4 energy columns against one column per feature (where it fits:
  at most 63 features; ``--layout-rng`` for more than 15 operator columns, as sobol has at most 16).

    python benchmarks/bench_classifier.py [--what all] [--datasets digits,iris,wine,breast_cancer]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from bayesmachine.argtypes import choice_of, int_in_range, value_list
from bayesmachine.classify import DEFAULT_BINS, MAX_BINS
from bayesmachine.cli import Parser, run_script
from bayesmachine.host.classification import BUNDLED_DATASETS, load_dataset, split_folds, study
from bayesmachine.params import RNG_KINDS

WHAT = ("bins", "integrators", "layouts", "all")


def _row(name: str, r: dict[str, Any], extra: str = "") -> str:
    a = r["accuracy"]
    return (f"  {name:<26} machine {a['machine']:.4f}  exact {a['exact_nb']:.4f}  "
            f"({r['machine_minus_exact_points']:+.2f} pts)  energy {a['energy_nb']:.4f}  "
            f"CategoricalNB {a['categorical_nb']:.4f}  GaussianNB {a['gaussian_nb']:.4f}  "
            f"cycles {r['cycles_per_decision']['mean']:.2f}  ECE {r['confidence']['machine']['ece']:.4f}"
            f"{extra}")


def _bins(data: Any, splits: list, args: argparse.Namespace) -> None:
    for b in args.bins:
        r = study(data, splits, {"integrator": "log", "bins": b})
        print(_row(f"bins {b} (log)", r, f"  bins/feature {r['bins_per_feature']['mean']:.1f}"))


def _integrators(data: Any, splits: list, args: argparse.Namespace) -> None:
    for name, options in (("stochastic", {"counter_max": args.counter_max}), ("log", {"integrator": "log"})):
        r = study(data, splits, {"bins": args.default_bins, **options})
        print(_row(name, r, f"  max cycles {r['cycles_per_decision']['max']}  timeouts "
                            f"{sum(f['timeouts'] for f in r['folds'])}"))


def _layouts(data: Any, splits: list, args: argparse.Namespace) -> None:
    features = data.x.shape[1]
    layouts: list[Any] = [k for k in (1, 2, 4) if k <= features] + ([None] if features <= 63 else [])
    for integrator in ("stochastic", "log"):
        for k in layouts:
            options = {"bins": args.default_bins, "fuse": k, "integrator": integrator}
            if integrator == "stochastic":
                options.update(counter_max=args.counter_max, rng=args.layout_rng)
            r = study(data, splits, options)
            label = f"{integrator} " + ("per feature" if k is None else f"fused K={k}")
            print(_row(label, r, f"  operator columns {r['operator_columns']}"))


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--what", type=choice_of(WHAT), default="all", help=f"{', '.join(WHAT)} (default all)")
    ap.add_argument("--datasets", type=value_list(choice_of(BUNDLED_DATASETS), "data set"),
                    default=list(BUNDLED_DATASETS))
    ap.add_argument("--bins", type=value_list(int_in_range(1, MAX_BINS), "count"), default=[4, 8, 16, 32],
                    help="the bin counts of --what bins (default 4,8,16,32)")
    ap.add_argument("--default-bins", type=int_in_range(1, MAX_BINS), default=DEFAULT_BINS,
                    help=f"the bins of the other sections (default {DEFAULT_BINS})")
    ap.add_argument("--counter-max", type=int_in_range(1, (1 << 24) - 1), default=16)
    ap.add_argument("--layout-rng", type=choice_of(RNG_KINDS), default="lfsr-shared",
                    help="the stochastic machine's source in --what layouts (default lfsr-shared: one per "
                    "operator column, as sobol, without sobol's limit of 16 columns)")
    ap.add_argument("--folds", type=int_in_range(2, 100), default=5)
    ap.add_argument("--split-seed", type=int_in_range(0, 2**32 - 1), default=0)
    args = ap.parse_args(argv)
    sections = {"bins": _bins, "integrators": _integrators, "layouts": _layouts}
    for name in args.datasets:
        data = load_dataset(name)
        splits = split_folds(data.y, args.folds, None, args.split_seed)
        print(f"{name}: {data.x.shape[0]} samples, {data.x.shape[1]} features, {args.folds}-fold, split seed "
              f"{args.split_seed}")
        for what, run in sections.items():
            if args.what in (what, "all"):
                t = time.perf_counter()
                print(f" {what}:")
                run(data, splits, args)
                print(f"  ({time.perf_counter() - t:.1f} s)")


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
