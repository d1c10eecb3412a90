"""Benchmark: the paper model against the census model (issue 17) on the bundled Motorcycle pair.

Float64 reference of: the paper model; + a 7x7 census column with the no-match row left
uncalibrated (h_nm = 0: its census entry is L_c(0) = 1); + the no-match row calibrated
(h_nm = bits / 8); + the raster-order neighbour prior; the 5x5 census option (calibrated, with
the prior). Each model also on 10-bit words (``reference_quantized``): the share of pixels whose
MAP changes. OpenCV StereoSGBM (block 5) and StereoBM (block 15) on the same pixels. Then the
machine (model engine, sobol, counter max 16) on the paper model and on the census model
without the prior, each beside its float and quantized references. All bad-n figures come
from ``host.metrics.bad_rates`` (report.json's). Prints figures; asserts nothing; tunes
nothing (the issue's defaults).
Run: python benchmarks/bench_models.py [--dmax 80] [--no-machine]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bayesmachine.host.features import model_features
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import ModelParams
from bayesmachine.host.metrics import (
    bad_rates,
    bm_disparity,
    gt_region,
    nomatch_occluded_share,
    occluded_mask,
    sgbm_disparity,
)
from bayesmachine.host.records import Prepared
from bayesmachine.host.reference import reference_map, reference_quantized_map, warm_up
from bayesmachine.host.run import run_machine
from bayesmachine.params import MachineParams


def figures(disp: np.ndarray, gt: np.ndarray, occluded: np.ndarray) -> dict[str, float]:
    b2 = bad_rates(disp, gt, 2)
    return {
        "nomatch": float(np.mean(disp < 0)),  # over all output pixels
        "bad2": b2["matched"],
        "bad2_nm": b2["nomatch_bad"],
        "nm_occluded": nomatch_occluded_share(disp, occluded),
    }


def line(name: str, f: dict[str, float], extra: str = "") -> None:
    cells = " ".join(f"{f[k]:8.3f}" for k in ("nomatch", "bad2", "bad2_nm", "nm_occluded"))
    print(f"{name:<44} {cells}  {extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dmax", type=int, default=80)
    ap.add_argument("--word-bits", type=int, default=10)
    ap.add_argument("--no-machine", action="store_true", help="skip the machine run")
    ap.add_argument("--counter-max", default="16",
                    help="the machine's counter max, or a comma-separated list (Fig 6 for each model)")
    args = ap.parse_args()
    left, right, gt_full = bundled_pair()
    dmax = args.dmax
    gt = gt_region(gt_full, dmax)
    occluded = gt_region(occluded_mask(gt_full), dmax).astype(bool)
    warm_up(ModelParams(name="census"))
    models = {
        "paper": ModelParams(dmax=dmax),
        "+ census 7x7, no-match uncalibrated": ModelParams(dmax=dmax, name="census", census_nomatch_h=0,
                                                           neighbour_prior=False),
        "+ census 7x7, no-match calibrated": ModelParams(dmax=dmax, name="census", neighbour_prior=False),
        "+ neighbour prior (census model default)": ModelParams(dmax=dmax, name="census"),
        "census 5x5 + calibrated + prior": ModelParams(dmax=dmax, name="census", census_window=5),
        "census 5x5 + calibrated, no prior": ModelParams(dmax=dmax, name="census", census_window=5,
                                                         neighbour_prior=False),
    }
    print(f"Motorcycle {left.shape[1]}x{left.shape[0]}, Dmax {dmax}, output {gt.shape[1]}x{gt.shape[0]} = "
          f"{gt.size} pixels, {np.isfinite(gt).mean():.3f} with finite gt, "
          f"{occluded.mean():.3f} occluded (gt)")
    print(f"{'float64 reference':<44} {'no-match':>8} {'bad2':>8} {'bad2,nm':>8} {'nm occl':>8}  "
          f"(W={args.word_bits} words: MAP changed, bad2 / bad2,nm)")
    feats_cache: dict[int | None, tuple] = {}
    refs = {}
    for name, model in models.items():
        key = model.census_window if model.census else None
        if key not in feats_cache:
            feats_cache[key] = (model_features(left, model), model_features(right, model))
        fl, fr = feats_cache[key]
        t0 = time.perf_counter()
        ref = reference_map(fl, fr, model)
        t1 = time.perf_counter()
        q = reference_quantized_map(fl, fr, model, args.word_bits)
        refs[name] = (ref, q)
        fq = figures(q, gt, occluded)
        line(name, figures(ref, gt, occluded),
             f"{np.mean(q != ref):.4f}, {fq['bad2']:.3f} / {fq['bad2_nm']:.3f}   ({t1 - t0:.2f} s)")
    for name, disp in (("OpenCV StereoSGBM (block 5)", sgbm_disparity(left, right, dmax)),
                       ("OpenCV StereoBM (block 15)", bm_disparity(left, right, dmax))):
        if disp is not None:
            line(name, figures(disp, gt, occluded))
    if args.no_machine:
        return
    runs = [(name, columns, key, int(cm)) for cm in args.counter_max.split(",")
            for name, columns, key in (("paper", 3, None), ("+ census 7x7, no-match calibrated", 4, 7))]
    for name, columns, key, counter_max in runs:
        model = models[name]
        machine = MachineParams.for_disparity(dmax, columns=columns, rng="sobol", counter_max=counter_max,
                                              seed=1)
        fl, fr = feats_cache[key]
        ref, q = refs[name]
        prepared = Prepared(left, right, model, (fl, fr), ref, 0.0, gt, gt_full)
        t0 = time.perf_counter()
        run = run_machine(prepared, machine, "model", progress=False)
        t1 = time.perf_counter()
        print(f"\nmachine ({machine.rng}, counter max {machine.counter_max}, {machine.columns} columns, "
              f"word bits {machine.word_bits}) on the model '{name}' ({t1 - t0:.1f} s):")
        line("machine", figures(run.map, gt, occluded),
             f"cycles/pixel {run.cycles.mean():.2f} (median {np.median(run.cycles):.0f}), "
             f"timeouts {int(run.timeout.sum())}")
        line("its float64 reference", figures(ref, gt, occluded))
        line(f"its {machine.word_bits}-bit quantized reference", figures(q, gt, occluded))
        print(f"MAP agreement machine/float reference {np.mean(run.map == ref):.3f}, "
              f"machine/quantized {np.mean(run.map == q):.3f}")


if __name__ == "__main__":
    main()
