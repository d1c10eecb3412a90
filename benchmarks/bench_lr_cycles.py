"""Benchmark: a fast estimate of census-lr's compute cycles per pixel (both passes), and its accuracy.

The machine's run at a pixel lasts about (n_max + 1) / p_win cycles, p_win the winning row's
probability of firing per cycle: the product over its operator columns of word / 2^W (the data
columns, the above prior, the consistency column, and the feedback column the machine forms from
its left neighbour). The estimate takes the MAPs of the 10-bit reference
(``reference_quantized_map`` and ``declared_maps(..., word_bits)["right"]``: the distribution the
machine samples) for the neighbours' prior words and the right MAPs, builds the words the machine
would load (``memory_words``, ``pass_words`` of the right pass), and caps each pixel at the watchdog
(``max_cycles``; the right pass's ``lr_right_max_cycles``). It is checked against the machine
(model engine, sobol, counter max 16, seed 1) on one band with ``--machine``.

Per variant it prints: the float64 reference's no-match rate, bad-2 on matched pixels, bad-2 with
no match counted as an error, the share of no-match calls on occluded pixels (the references have
no watchdog); the estimated cycles per output pixel over both passes (mean, median, p99: the left
pass's pixel plus the right pass's cycles per right pixel scaled by Wr / Wo), the left pass's and
the right pass's means, and the estimated share of pixels stopped by each watchdog; with
``--machine`` the same figures measured (timeouts as counts). Variants: census-lr's defaults, the
issue's model (no right no-match row, no neutral lanes), values inside the issue's stated flat
ranges, the right pass's watchdog; ``--max-cycles`` sets the left pass's watchdog (default: the
census-lr machine's, 64 runs of n_max + 1 cycles). Prints figures; asserts nothing.
Run: python benchmarks/bench_lr_cycles.py [--rows 150,190] [--machine] [--variants NAME,...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import MAX_COUNTER_MAX, int_in_range
from bayesmachine.columns import AbovePrior
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words, pass_grid, pass_words
from bayesmachine.host.metrics import bad_rates, gt_region, nomatch_occluded_share, occluded_mask
from bayesmachine.host.records import Prepared
from bayesmachine.host.reference import declared_maps, reference_map, reference_quantized_map
from bayesmachine.host.run import run_machine
from bayesmachine.models import ModelParams, disparity_machine, pass_machine
from bayesmachine.params import MachineParams
from bayesmachine.region import OutputRegion

# Short names of the census-lr fields a variant sets: NAME=VALUE (0/1 for a yes/no field).
KEYS = {"beta": ("lr_beta", float), "gamma": ("lr_gamma", float), "pnm": ("prior_nomatch", float),
        "tol": ("lr_tolerance", int), "rmax": ("lr_right_max_cycles", int), "rnm": ("lr_right_nomatch", bool),
        "neutral": ("lr_neutral", bool), "lnm": ("lr_nomatch", bool)}
# census-lr's defaults; the model (no right no-match row, no neutral lanes), alone and with the
# right pass's watchdog at 4096; the right no-match row without neutral lanes; values inside the issue's
# flat ranges (beta 0.03-0.3, gamma 0.001-0.03, no-match prior factor 0.05-0.25).
VARIANTS = ("default", "rnm=0,neutral=0", "rnm=0,neutral=0,rmax=4096", "neutral=0", "beta=0.03", "beta=0.3",
            "gamma=0.001", "gamma=0.03", "pnm=0.05", "pnm=0.25")


def variant(spec: str) -> dict[str, object]:
    """The ModelParams fields of a variant spec (``default``, or ``beta=0.3,rnm=0,...``)."""
    out: dict[str, object] = {}
    for item in spec.split(","):
        if item in ("", "default"):
            continue
        key, _, value = item.partition("=")
        field, kind = KEYS[key]
        out[field] = bool(int(value)) if kind is bool else kind(value)
    return out


def _rows(text: str) -> tuple[int, int] | None:
    """``--rows START,STOP`` (map rows of the bundled pair, 0 <= START < STOP <= 494), or None for 'all'."""
    if text == "all":
        return None
    try:
        y0, y1 = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START,STOP map rows or all, got {text!r}") from None
    if not 0 <= y0 < y1 <= 494:  # the bundled pair's 500 rows less the census-lr margins
        raise argparse.ArgumentTypeError(f"expected 0 <= START < STOP <= 494, got {text!r}")
    return y0, y1


def _variants(text: str) -> list[str]:
    """``--variants``: each one checked (its keys, its values: the model it makes) before any work."""
    names = [n for n in text.split(";") if n]
    if not names:
        raise argparse.ArgumentTypeError("give at least one variant")
    for name in names:
        try:
            ModelParams(name="census-lr").replace(**variant(name))
        except KeyError as exc:
            raise argparse.ArgumentTypeError(f"{name!r}: unknown key {exc} (keys: {', '.join(KEYS)})") \
                from None
        except (TypeError, ValueError) as exc:
            raise argparse.ArgumentTypeError(f"{name!r}: {exc}") from None
    return names


def _shifted_left(hat: np.ndarray) -> np.ndarray:
    """Each pixel's left neighbour's MAP in its row (-1 at the row's first pixel: line start)."""
    out = np.full_like(hat, -1)
    out[..., 1:] = hat[..., :-1]
    return out


def _run_cycles(words: np.ndarray, feedback: np.ndarray, word_bits: int, counter_max: int,
                max_cycles: int) -> np.ndarray:
    """(n_max + 1) / p_win per pixel, capped at the watchdog: p_win the largest row's product."""
    scale = float(1 << word_bits)
    p = np.prod(words.astype(np.float64) / scale, axis=2) * (feedback.astype(np.float64) / scale)
    pmax = p.max(axis=1)
    with np.errstate(divide="ignore"):
        est = (counter_max + 1) / pmax
    return np.minimum(est, float(max_cycles))


def estimate(fl, fr, model: ModelParams, machine: MachineParams) -> dict[str, np.ndarray]:
    """Estimated cycles (Ho, W) of both passes over every map row (from the 10-bit references' MAPs)."""
    w = machine.word_bits
    rmach = pass_machine(model, machine, "right")
    right_map = declared_maps(model, fl, fr, w)["right"]
    left_map = reference_quantized_map(fl, fr, model, w)
    above_l = model.column(AbovePrior)
    above_r = model.pass_named("right").model.column(AbovePrior)
    q, qr = above_l.table(w), above_r.table(w)
    region = OutputRegion.of_features(fl.shape, model.dmax)
    xr = pass_grid(model.pass_named("right"), region).columns
    left_c, right_c = [], []
    for y in range(left_map.shape[0]):
        row_r = right_map[y - 1] if y > 0 else np.full(xr.size, -1, np.int16)
        rw = pass_words(model.pass_named("right"), fl, fr, rmach, rows=slice(y, y + 1), above=row_r)
        rfb = above_r.loaded(qr, _shifted_left(right_map[y]))
        right_c.append(_run_cycles(rw, rfb, w, rmach.counter_max, rmach.max_cycles))
        above = left_map[y - 1] if y > 0 else np.full(left_map.shape[1], -1, np.int16)
        lw = memory_words(fl, fr, model, machine, rows=slice(y, y + 1), above=above,
                          results={"right": right_map[y][None]})
        lfb = above_l.loaded(q, _shifted_left(left_map[y]))
        left_c.append(_run_cycles(lw, lfb, w, machine.counter_max, machine.max_cycles))
    return {"left": np.stack(left_c), "right": np.stack(right_c), "right_max": rmach.max_cycles,
            "left_max": machine.max_cycles, "left_map": left_map}


def cycle_figures(left_c: np.ndarray, right_c: np.ndarray, left_max: int, right_max: int) -> dict[str, float]:
    """Cycles per output pixel over both passes: each left pixel's cycles plus its row's right-pass
    cycles spread over the row's output pixels (mean exact; median/p99 of that per-pixel sum)."""
    wo, wr = left_c.shape[1], right_c.shape[1]
    per_px = left_c + right_c.sum(axis=1, keepdims=True) / wo  # the right row's cost shared by its pixels
    return {
        "mean": float(left_c.mean() + right_c.mean() * wr / wo),
        "median": float(np.median(left_c)) + float(np.median(right_c)) * wr / wo,
        "p99": float(np.percentile(per_px, 99)),
        "left": float(left_c.mean()),
        "right": float(right_c.mean()),
        "right_median": float(np.median(right_c)),
        "right_p99": float(np.percentile(right_c, 99)),
        "left_to": float(np.mean(left_c >= left_max)),
        "right_to": float(np.mean(right_c >= right_max)),
    }


def accuracy(disp: np.ndarray, gt: np.ndarray, occ: np.ndarray) -> dict[str, float]:
    b2 = bad_rates(disp, gt, 2)
    return {"nomatch": float(np.mean(disp < 0)), "bad2": b2["matched"], "bad2_nm": b2["nomatch_bad"],
            "nm_occ": nomatch_occluded_share(disp, occ)}


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=_rows, default="150,190",
                    help="map rows START,STOP of the band (default 150,190); 'all' for the whole pair")
    ap.add_argument("--variants", type=_variants, default=";".join(VARIANTS),
                    help="variants separated by ';', each 'default' or comma-separated NAME=VALUE / flags of "
                    + ", ".join(KEYS) + f" (default: {';'.join(VARIANTS)})")
    ap.add_argument("--machine", action="store_true",
                    help="also run the machine (model engine, sobol, counter max 16, seed 1) on the band")
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16)
    ap.add_argument("--max-cycles", type=int_in_range(2, (1 << 32) - 1), default=None,
                    help="the left pass's watchdog (default: disparity_machine's for census-lr)")
    args = ap.parse_args(argv)
    names = args.variants
    left, right, gt_full = bundled_pair()
    base = ModelParams(name="census-lr")
    if args.rows is not None:
        # Map rows y0..y1-1 are image rows y0 + margin ..: crop the pair (and the truth) to them, so the
        # machine and the references both start the band afresh (no row above).
        y0, y1 = args.rows
        cut = slice(y0, y1 + 2 * base.margin)
        left, right, gt_full = left[cut], right[cut], gt_full[cut]
    gt = gt_region(gt_full, base.dmax, base.margin)
    occ = occluded_mask(gt)
    print(f"{'variant':<40} {'nm':>6} {'bad2':>6} {'b2nm':>6} {'nmocc':>6} | est cyc/px both: "
          f"{'mean':>8} {'median':>7} {'p99':>8} | {'left':>8} {'right':>8} {'r-med':>6} {'r-p99':>8} "
          f"{'to-L':>6} {'to-R':>6} | s")
    for name in names:
        t0 = time.perf_counter()
        model = base.replace(**variant(name))
        fl, fr = model_planes(left, model), model_planes(right, model)
        kw = {} if args.max_cycles is None else {"max_cycles": args.max_cycles}
        machine = disparity_machine(model, counter_max=args.counter_max, rng="sobol", seed=1, **kw)
        ref = reference_map(fl, fr, model)
        acc = accuracy(ref, gt, occ)
        est = estimate(fl, fr, model, machine)
        c = cycle_figures(est["left"], est["right"], est["left_max"], est["right_max"])
        print(f"{name:<40} {acc['nomatch']:6.3f} {acc['bad2']:6.3f} {acc['bad2_nm']:6.3f} "
              f"{acc['nm_occ']:6.3f} | "
              f"{'':>15}{c['mean']:8.1f} {c['median']:7.1f} {c['p99']:8.0f} | {c['left']:8.1f} "
              f"{c['right']:8.1f} {c['right_median']:6.1f} {c['right_p99']:8.0f} {c['left_to']:6.4f} "
              f"{c['right_to']:6.4f} | {time.perf_counter() - t0:.0f}", flush=True)
        # The left watchdog's effect, estimated: the 10-bit reference's MAP, no match where the estimate
        # reaches the watchdog (the right pass's timeouts and the neighbours' changed priors left out).
        stopped = np.where(est["left"] >= est["left_max"], np.int16(-1), est["left_map"])
        acc = accuracy(stopped, gt, occ)
        print(f"{'  10-bit ref, estimated left timeouts':<40} {acc['nomatch']:6.3f} {acc['bad2']:6.3f} "
              f"{acc['bad2_nm']:6.3f} {acc['nm_occ']:6.3f} |", flush=True)
        if args.machine:
            t0 = time.perf_counter()
            prep = Prepared(left, right, model, (fl, fr), None, 0.0, None, None)
            run = run_machine(prep, machine, "model", progress=False)
            rp = run.passes["right"]
            lm = run.cycles.astype(np.float64)
            rm = rp.cycles.astype(np.float64)
            m = cycle_figures(lm, rm, machine.max_cycles, rp.machine.max_cycles)
            acc = accuracy(run.map, gt, occ)
            print(f"{'  machine':<40} {acc['nomatch']:6.3f} {acc['bad2']:6.3f} {acc['bad2_nm']:6.3f} "
                  f"{acc['nm_occ']:6.3f} | {'measured':>15}{m['mean']:8.1f} {m['median']:7.1f} "
                  f"{m['p99']:8.0f} | "
                  f"{m['left']:8.1f} {m['right']:8.1f} {m['right_median']:6.1f} {m['right_p99']:8.0f} "
                  f"{int(run.timeout.sum()):6d} {int(rp.timeout.sum()):6d} | "
                  f"{time.perf_counter() - t0:.0f}", flush=True)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
