"""Benchmark: the random sources side by side on the full bundled pair (model engine).

Prints, per source and counter max: cycles per pixel, RMS error, no-match F1, MAP agreement,
and where a shared source could be worse than independent LFSRs: how often another row also
holds n_max at the stop (a tie or a photo finish), how often the no-match row ties with a
disparity row (exactly: the pixels whose MAP changes under the lowest-index tie rule), MAP
agreement on the pixels whose two best reference hypotheses are nearly equal, and on the pixels
whose two best rows have equal quantized rates (products of their words): rows a shared source
makes fire in the same cycles. Asserts nothing. Run:
    python benchmarks/bench_sources.py [--counter-max 16] [--rng lfsr,lfsr-shared,sobol]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import counter_max_list, float_in_range, rng_list
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.metrics import evaluate
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counter-max", type=counter_max_list, default="16")
    ap.add_argument("--rng", type=rng_list, default="lfsr,lfsr-shared,sobol")
    ap.add_argument("--near", type=float_in_range(0, 1), default=0.9,
                    help="near-equal pixels: second-best / best reference posterior above this (and < 1)")
    args = ap.parse_args(argv)
    left, right, gt = bundled_pair()
    model = ModelParams(name="paper")
    prep = prepare(left, right, model, gt)
    post = prep.reference.posterior.reshape(-1, model.hypotheses)
    top2 = np.sort(post, axis=1)[:, -2:]
    # Near-equal: the runner-up within the factor but not equal (exact ties make the reference's
    # own argmax arbitrary).
    near = (top2[:, 0] > args.near * top2[:, 1]) & (top2[:, 0] < top2[:, 1])
    ref_map = prep.reference.map.reshape(-1)
    print(f"bundled Motorcycle pair, Dmax {model.dmax}: {post.shape[0]} pixels; {near.sum()} "
          f"({100 * near.mean():.1f} %) have a runner-up hypothesis within {args.near:g}x of the best, "
          f"{(top2[:, 0] == top2[:, 1]).sum()} an exact tie")
    base = MachineParams.for_disparity(model.dmax)
    ho, wo = prep.shape
    equal_best = np.zeros(ho * wo, bool)
    for y in range(ho):  # a row of pixels at a time: the words of a frame are large
        q = memory_words(*prep.planes, model, base, rows=slice(y, y + 1)).astype(np.int64)
        rates = q.prod(axis=2)
        top = np.sort(rates, axis=1)[:, -2:]
        equal_best[y * wo : (y + 1) * wo] = top[:, 0] == top[:, 1]
    print(f"{equal_best.sum()} pixels ({100 * equal_best.mean():.1f} %) have two best rows of equal rate")
    for n in args.counter_max:
        for kind in args.rng:
            machine = MachineParams.for_disparity(model.dmax, counter_max=n, rng=kind)
            run = run_machine(prep, machine, "model", progress=False)
            r = evaluate(prep, run, sgbm=False).to_report()
            counts = run.counts.reshape(-1, machine.rows)
            ok = ~run.timeout.reshape(-1)
            photo = ok & ((counts == n).sum(axis=1) > 1)
            got = run.map.reshape(-1)
            lowest = MachineParams.for_disparity(model.dmax, counter_max=n, rng=kind,
                                                 tie_break="lowest-index")
            nm_ties = run_machine(prep, lowest, "model", progress=False).map.reshape(-1) != got
            print(
                f"{kind:12s} counter max {n:3d}: cycles/px {r['cycles_per_pixel_mean']:.2f}, "
                f"RMS {r['rms_error']:.4f}, no-match F1 {r['nomatch_f1']:.3f}, MAP agreement "
                f"{r['map_agreement']:.3f}; another row at n_max {100 * photo.mean():.1f} % of pixels, "
                f"no-match ties {100 * nm_ties.mean():.1f} %; near-equal pixels: MAP agreement "
                f"{(got[near] == ref_map[near]).mean():.3f}, no match {100 * (got[near] < 0).mean():.1f} % "
                f"(reference {100 * (ref_map[near] < 0).mean():.1f} %); MAP agreement on equal-rate best "
                f"rows {(got[equal_best] == ref_map[equal_best]).mean():.3f}, on the others "
                f"{(got[~equal_best] == ref_map[~equal_best]).mean():.3f}"
            )


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
