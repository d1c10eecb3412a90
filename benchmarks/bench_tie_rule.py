"""How often do several counters overflow in the same cycle, and what does the tie rule change?

Runs the machine model (Dmax = 80, N = 3, n_max = 16 by default) with ideal random numbers on
the likelihood memories of real image rows (the stereo pair bundled with scikit-image, through
the host pipeline) and on synthetic paper-like pixels, and prints:

- ties: pixels where two or more rows overflowed in the stopping cycle;
- no-match ties: ties that include the no-match row (the only ones where ``nomatch-first`` and
  ``lowest-index`` report different rows);
- no-match decisions under each rule.

    python benchmarks/bench_tie_rule.py [--rows 12] [--pixels 20000] [--counter-max 16]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import MAX_COUNTER_MAX, int_in_range
from bayesmachine.params import MAX_DMAX, MachineParams
from bayesmachine.sim.synthetic import synthetic_disparity_words
from bayesmachine.sim.ties import measure_ties


def real_words(params: MachineParams, rows: int) -> np.ndarray | None:
    try:
        from bayesmachine.host.features import feature_sums
        from bayesmachine.host.images import bundled_pair
        from bayesmachine.host.likelihoods import memory_words
        from bayesmachine.models import ModelParams
    except ImportError as exc:  # the host pipeline is optional here
        print(f"(no real images: {exc})")
        return None
    left, right, _ = bundled_pair()
    # `rows` output rows need rows + 4 image rows (the 5x5 filters), taken from the middle.
    top = left.shape[0] // 2 - rows // 2 - 2
    left, right = left[top : top + rows + 4], right[top : top + rows + 4]
    model = ModelParams(name="paper", dmax=params.rows - 2)
    return memory_words(feature_sums(left), feature_sums(right), model, params)


def report(name: str, m: dict[str, float], seconds: float) -> None:
    n = m["pixels"]
    print(f"{name}: {n} pixels ({seconds:.1f} s)")
    print(f"  ties (>= 2 rows overflow together): {m['ties']:6d}  ({100 * m['tie_fraction']:.2f} %)")
    print(f"  ties including the no-match row:    {m['nomatch_ties']:6d}  "
          f"({100 * m['nomatch_tie_fraction']:.2f} %)")
    print(f"  no-match decisions, lowest-index:   {m['nomatch_lowest_index']:6d}  "
          f"({100 * m['nomatch_lowest_index'] / n:.2f} %)")
    print(f"  no-match decisions, nomatch-first:  {m['nomatch_nomatch_first']:6d}  "
          f"({100 * m['nomatch_nomatch_first'] / n:.2f} %)")
    if m["timeouts"]:
        print(f"  timeouts: {m['timeouts']}")


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int_in_range(1, 490), default=12,
                    help="image rows of the bundled pair, 1 .. 490 (default 12)")
    ap.add_argument("--pixels", type=int_in_range(1, 10_000_000), default=20_000,
                    help="synthetic pixels (default 20000)")
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16)
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--seed", type=int_in_range(0, 2**64 - 1), default=1)
    args = ap.parse_args(argv)
    params = MachineParams.for_disparity(args.dmax, counter_max=args.counter_max)
    rng = np.random.default_rng(args.seed)
    words = real_words(params, args.rows)
    if words is not None:
        t = time.perf_counter()
        m = measure_ties(params, words, rng)
        report(f"bundled stereo pair, {args.rows} rows", m, time.perf_counter() - t)
    words = synthetic_disparity_words(params, args.pixels, rng)
    t = time.perf_counter()
    m = measure_ties(params, words, rng)
    report("synthetic paper-like pixels", m, time.perf_counter() - t)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
