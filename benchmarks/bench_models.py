"""Benchmark: the paper model, the census model and census-lr on the bundled pair.

Float64 reference of: the paper model; + a 7x7 census column with the no-match row left
uncalibrated (h_nm = 0: its census entry is L_c(0) = 1); + the no-match row calibrated
(h_nm = bits / 8); + the raster-order neighbour prior; the 5x5 census option (calibrated, with
and without the prior). Each model also on 10-bit words (``reference_quantized``: the machine's
exact products): the share of pixels whose MAP changes. Each model on its own output region (the
7x7 census's is one pixel further inside: ``bayesmachine.region``). OpenCV StereoSGBM (block 5) and
StereoBM (block 15) on the same pixels, on both regions. Then the machine (model engine, sobol,
seed 1) each model needs
(``disparity_machine``: the census model's with its neighbour prior, fed back from its own
results through ``run_machine``) on the paper model and the census model, against counter max,
beside its float and quantized references, with cycles and wall cycles per pixel; then the
random sources on the census model at counter max 16. The census-lr model (left-right
consistency column from a right pass): its float64 reference with its defaults (the right pass's
no-match row, neutral lanes), the issue's model (no right no-match row, no neutral lanes) with and
without the left pass's no-match row, the right no-match row without neutral lanes, and 2 values
each of beta, gamma, the no-match prior factor and the tolerance around the defaults (the issue's
flatness claim; nothing is picked from these); its machine (both passes, model engine, its default
watchdog) at ``--lr-counter-max`` (default 16), with the right pass's cycles. The references have no
watchdog; ``benchmarks/bench_lr_cycles.py`` estimates and measures census-lr's cycles per variant. All bad-n
figures come from ``host.metrics.bad_rates`` (report.json's). Prints
figures; asserts nothing; tunes nothing (the issues' defaults).
Run: python benchmarks/bench_models.py [--dmax 80] [--counter-max 1,2,4,8,16] [--lr-counter-max 16]
     [--no-machine] [--no-lr] [--figure docs/figures/motorcycle-models.png]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import counter_max_list, int_in_range, output_path
from bayesmachine.hdl.machine import pixel_wall_cycles
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
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
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.outputs import atomic_file
from bayesmachine.params import MAX_DMAX


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


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--word-bits", type=int_in_range(1, 15), default=10)
    ap.add_argument("--no-machine", action="store_true", help="skip the machine run")
    ap.add_argument("--counter-max", type=counter_max_list, default="1,2,4,8,16",
                    help="the machine's counter max values, comma-separated (Fig 6 for each model)")
    ap.add_argument("--lr-counter-max", type=lambda t: counter_max_list(t) if t.strip() else [], default="16",
                    help="counter max values of the census-lr machine, comma-separated ('' for none)")
    ap.add_argument("--no-lr", action="store_true", help="skip the census-lr model")
    ap.add_argument("--figure", type=output_path, default=None, metavar="PNG",
                    help="write the paper and census machines, SGBM, StereoBM and the ground truth")
    args = ap.parse_args(argv)
    left, right, gt_full = bundled_pair()
    dmax = args.dmax
    # Each model on its own output region (bayesmachine.region: margin 2, or 3 with a 7x7 census).
    truth = {k: (gt_region(gt_full, dmax, k), gt_region(occluded_mask(gt_full), dmax, k).astype(bool))
             for k in (2, 3)}
    gt, occluded = truth[2]
    warm_up(ModelParams(name="census"))
    models = {
        "paper": ModelParams(name="paper", dmax=dmax),
        "+ census 7x7, no-match uncalibrated": ModelParams(dmax=dmax, name="census", census_nomatch_h=0,
                                                           neighbour_prior=False),
        "+ census 7x7, no-match calibrated": ModelParams(dmax=dmax, name="census", neighbour_prior=False),
        "+ neighbour prior (census model default)": ModelParams(dmax=dmax, name="census"),
        "census 5x5 + calibrated + prior": ModelParams(dmax=dmax, name="census", census_window=5),
        "census 5x5 + calibrated, no prior": ModelParams(dmax=dmax, name="census", census_window=5,
                                                         neighbour_prior=False),
    }
    if not args.no_lr:
        lr = ModelParams(dmax=dmax, name="census-lr")
        issue = lr.replace(lr_right_nomatch=False, lr_neutral=False)
        models["+ left-right column (census-lr default)"] = lr
        models["census-lr, the issue's (no right no-match row)"] = issue
        models["the issue's, no no-match row (left pass)"] = issue.replace(lr_nomatch=False)
        models["the issue's + right no-match row, not neutral"] = lr.replace(lr_neutral=False)
        for field, values in (("lr_beta", (0.03, 0.3)), ("lr_gamma", (0.001, 0.03)),
                              ("prior_nomatch", (0.05, 0.25)), ("lr_tolerance", (0, 2))):
            for v in values:
                models[f"census-lr, {field} {v}"] = lr.replace(**{field: v})
    print(f"Motorcycle {left.shape[1]}x{left.shape[0]}, Dmax {dmax}, output {gt.shape[1]}x{gt.shape[0]} = "
          f"{gt.size} pixels, {np.isfinite(gt).mean():.3f} with finite gt, "
          f"{occluded.mean():.3f} occluded (gt)")
    print(f"{'float64 reference':<44} {'no-match':>8} {'bad2':>8} {'bad2,nm':>8} {'nm occl':>8}  "
          f"(W={args.word_bits} words: MAP changed, bad2 / bad2,nm)")
    feats_cache: dict[int, tuple] = {}
    refs = {}
    for name, model in models.items():
        key = model.margin  # the feature grid: the census window decides it
        if key not in feats_cache:
            feats_cache[key] = (model_planes(left, model), model_planes(right, model))
        fl, fr = feats_cache[key]
        t0 = time.perf_counter()
        ref = reference_map(fl, fr, model)
        t1 = time.perf_counter()
        q = reference_quantized_map(fl, fr, model, args.word_bits)
        refs[name] = (ref, q)
        gt, occluded = truth[model.margin]
        fq = figures(q, gt, occluded)
        line(name, figures(ref, gt, occluded),
             f"{np.mean(q != ref):.4f}, {fq['bad2']:.3f} / {fq['bad2_nm']:.3f}   ({t1 - t0:.2f} s)")
    for k, (gt, occluded) in truth.items():
        for name, disp in (("OpenCV StereoSGBM (block 5)", sgbm_disparity(left, right, dmax, k)),
                           ("OpenCV StereoBM (block 15)", bm_disparity(left, right, dmax, margin=k))):
            if disp is not None:
                line(f"{name}, margin {k}", figures(disp, gt, occluded))
    if args.no_machine:
        return
    figure_maps: dict[str, np.ndarray] = {}
    machine_models = {"paper": "paper", "census + prior": "+ neighbour prior (census model default)"}
    counters = args.counter_max
    print(f"\nThe machine (model engine, sobol, seed 1, W {args.word_bits}): against counter max; agreement "
          "with its float64 / quantized reference; cycles per pixel mean (median); wall cycles per pixel "
          "(hdl.machine timing rule, loading included)")
    print(f"{'machine':<44} {'no-match':>8} {'bad2':>8} {'bad2,nm':>8} {'nm occl':>8}  "
          "MAP=float MAP=words  cycles/px (median)  wall/px  beats")
    for counter_max in counters:
        for label, name in machine_models.items():
            gt, occluded = truth[models[name].margin]
            run = machine_run(left, right, gt, gt_full, models[name], feats_cache, refs[name], counter_max,
                              "sobol", args.word_bits)
            if counter_max == 16:
                figure_maps[label] = run.map
            machine_line(f"{label}, counter max {counter_max}", run, refs[name], gt, occluded)
    lr_name = "+ left-right column (census-lr default)"
    lr_counters = args.lr_counter_max
    if lr_name in models and lr_counters:
        print("\ncensus-lr machine (both passes, model engine): cycles/px over both passes = all compute "
              "cycles / output pixels; the right pass's own cycles per right pixel and timeouts")
        for counter_max in lr_counters:
            run = lr_machine_line(left, right, gt, gt_full, models[lr_name], feats_cache, refs[lr_name],
                                  counter_max, args.word_bits, occluded)
            if counter_max == 16:
                figure_maps["census-lr"] = run.map
    print("\nRandom sources on the census model with its prior, counter max 16:")
    name = machine_models["census + prior"]
    gt, occluded = truth[models[name].margin]
    for rng in ("sobol", "lfsr", "lfsr-shared"):
        run = machine_run(left, right, gt, gt_full, models[name], feats_cache, refs[name], 16, rng,
                          args.word_bits)
        machine_line(f"census + prior, {rng}", run, refs[name], gt, occluded)
    if args.figure and {"paper", "census + prior"} <= set(figure_maps):
        from bayesmachine.host.plots import save_disparity_figure
        from bayesmachine.region import OutputRegion

        # The census model's output region (margin 3), the paper machine's map cut to it.
        region = OutputRegion.of_image(left.shape, dmax, 3)
        panels = [("Paper model: machine (counter max 16)", figure_maps["paper"][1:-1, 1:-1]),
                  ("Census + neighbour prior: machine (counter max 16)", figure_maps["census + prior"]),
                  ("OpenCV StereoSGBM (block 5)", sgbm_disparity(left, right, dmax, 3)),
                  ("OpenCV StereoBM (block 15)", bm_disparity(left, right, dmax, margin=3)),
                  ("Ground truth", truth[3][0])]
        with atomic_file(args.figure) as tmp:  # complete or absent
            save_disparity_figure(tmp, region.cut(left), panels, dmax)
        print(f"wrote {args.figure}")


def machine_run(left, right, gt, gt_full, model, feats_cache, ref, counter_max, rng, word_bits):
    machine = disparity_machine(model, rng=rng, counter_max=counter_max, seed=1, word_bits=word_bits)
    fl, fr = feats_cache[model.margin]
    prepared = Prepared(left, right, model, (fl, fr), ref[0], 0.0, gt, gt_full)
    return run_machine(prepared, machine, "model", progress=False)


def lr_machine_line(left, right, gt, gt_full, model, feats_cache, ref, counter_max, word_bits, occluded):
    """One census-lr machine run: its figures, then both passes' cycles (compute and wall)."""
    t0 = time.perf_counter()
    run = machine_run(left, right, gt, gt_full, model, feats_cache, ref, counter_max, "sobol", word_bits)
    machine_line(f"census-lr, counter max {counter_max}", run, ref, gt, occluded)
    r = run.passes["right"]
    both = (run.cycles.sum() + r.cycles.sum()) / run.cycles.size
    rwall = pixel_wall_cycles(r.machine, r.cycles, r.timeout)
    lwall = pixel_wall_cycles(run.machine, run.cycles, run.timeout)
    wall = (lwall.sum() + rwall.sum()) / run.cycles.size
    print(f"{'':<44} both passes {both:.2f} cycles/px, wall {wall:.2f}"
          f"; left pass {run.cycles.mean():.2f} (median {np.median(run.cycles):.0f}, p99 "
          f"{np.percentile(run.cycles, 99):.0f}); right pass {r.cycles.size} px, "
          f"{r.cycles.mean():.2f} (median {np.median(r.cycles):.0f}, "
          f"p99 {np.percentile(r.cycles, 99):.0f}), timeouts "
          f"{int(r.timeout.sum())}; {time.perf_counter() - t0:.0f} s")
    return run


def machine_line(name: str, run, ref: tuple, gt: np.ndarray, occluded: np.ndarray) -> None:
    m = run.machine
    wall = pixel_wall_cycles(m, run.cycles, run.timeout)
    line(name, figures(run.map, gt, occluded),
         f"{np.mean(run.map == ref[0]):8.3f} {np.mean(run.map == ref[1]):9.3f}  "
         f"{run.cycles.mean():8.2f} ({np.median(run.cycles):4.0f})  {wall.mean():8.2f}  "
         f"{m.beats_per_pixel:5d}"
         + (f"  timeouts {int(run.timeout.sum())}" if run.timeout.any() else ""))


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
