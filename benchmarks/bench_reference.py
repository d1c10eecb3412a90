"""Benchmark: the float64 reference on a 640x480 pair with Dmax 80 (goal: <= 0.1 s on 2 cores).

Prints figures; asserts nothing. Checks the fast kernel's MAP against the plain vectorized
float64 computation on the same frame. Run: python benchmarks/bench_reference.py

With ``--models paper,census,census-lr``: each model's float64 and ``--word-bits``-bit references
(``reference_map``, ``reference_quantized_map``: every pass, band by band) on the bundled Motorcycle pair
(Dmax 80), median and minimum of ``--repeats`` runs after a warm one, and a checksum of the MAP.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import int_in_range, model_list
from bayesmachine.host.features import feature_sums, model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.reference import (
    reference_fast,
    reference_map,
    reference_plain,
    reference_quantized_map,
    warm_up,
)
from bayesmachine.models import ModelParams


def vga_pair(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 640x480 pair: smoothed random texture, right = left shifted by a ramp of disparities."""
    rng = np.random.default_rng(seed)
    right = cv2.GaussianBlur(rng.integers(0, 256, (480, 720), dtype=np.uint8), (0, 0), 1.0)
    left = np.empty((480, 640), np.uint8)
    for y in range(480):
        d = 5 + (70 * y) // 479  # disparity grows down the frame: 5 .. 75
        left[y] = right[y, 80 - d : 720 - d]
    return left, np.ascontiguousarray(right[:, 80:])


def models_on_the_bundled_pair(names: list[str], word_bits: int, repeats: int) -> None:
    """Each model's float64 and word references on the bundled pair (module text)."""
    left, right, _ = bundled_pair()
    print(f"bundled pair {left.shape[1]}x{left.shape[0]}, {numba.get_num_threads()} threads")
    for name in names:
        model = ModelParams(name=name)
        warm_up(model)
        planes = model_planes(left, model), model_planes(right, model)
        for label, bits in (("float64", None), (f"{word_bits}-bit", word_bits)):
            times = []
            for _ in range(repeats + 1):  # the first one warm
                t0 = time.perf_counter()
                got = (reference_map(*planes, model) if bits is None
                       else reference_quantized_map(*planes, model, bits))
                times.append(time.perf_counter() - t0)
            times = times[1:]
            print(f"{name:10s} {label:8s} median {statistics.median(times) * 1e3:8.1f} ms, min "
                  f"{min(times) * 1e3:8.1f} ms (MAP sum {int(got.astype(np.int64).sum())})", flush=True)


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__)
    ap.add_argument("--repeats", type=int_in_range(1, 1000), default=10)
    ap.add_argument("--no-plain", action="store_true", help="skip the plain-oracle check (needs ~3 GB)")
    ap.add_argument("--models", type=model_list, default=None,
                    help="comma-separated models: their references on the bundled pair instead")
    ap.add_argument("--word-bits", type=int_in_range(1, 15), default=10,
                    help="with --models: the word references' W (default %(default)s)")
    args = ap.parse_args(argv)
    if args.models:
        models_on_the_bundled_pair(args.models, args.word_bits, args.repeats)
        return
    left, right = vga_pair()
    model = ModelParams(name="paper")
    t0 = time.perf_counter()
    warm_up(model)
    print(
        f"numba warm-up (cache load or compile): {time.perf_counter() - t0:.2f} s, "
        f"{numba.get_num_threads()} threads"
    )

    def once(out: np.ndarray | None) -> tuple[float, float, object]:
        t0 = time.perf_counter()
        fl, fr = feature_sums(left), feature_sums(right)
        t1 = time.perf_counter()
        ref = reference_fast(fl, fr, model, out=out)
        return t1 - t0, time.perf_counter() - t1, ref

    feat_first, ref_first, ref = once(None)
    ms = 1e3
    print(f"first call (new pages): features {feat_first * ms:.1f} ms + reference {ref_first * ms:.1f} ms")
    fresh = [sum(once(None)[:2]) for _ in range(args.repeats)]
    out = np.empty_like(ref.posterior)
    runs = [once(out) for _ in range(args.repeats)]
    feat = [r[0] for r in runs]
    kern = [r[1] for r in runs]
    total = [a + b for a, b in zip(feat, kern, strict=True)]
    ho, wo, m = ref.posterior.shape
    mb = ref.posterior.nbytes / 1e6
    print(f"frame 640x480, Dmax {model.dmax}: posterior {ho}x{wo}x{m} float64 ({mb:.0f} MB)")
    print(f"features  median {statistics.median(feat) * 1e3:6.1f} ms")
    print(f"reference median {statistics.median(kern) * 1e3:6.1f} ms (output buffer reused)")
    print(f"total     median {statistics.median(total) * ms:6.1f} ms, min {min(total) * ms:.1f} (goal 100)")
    print(f"total with a new output array each frame: median {statistics.median(fresh) * ms:.1f} ms")
    banded = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        band_map = reference_map(feature_sums(left), feature_sums(right), model)
        banded.append(time.perf_counter() - t0)
    print(
        f"MAP only, band by band (what run/sweep hold): median {statistics.median(banded) * ms:.1f} ms; "
        f"same MAP: {np.array_equal(band_map, ref.map)}"
    )
    if not args.no_plain:
        fl, fr = feature_sums(left), feature_sums(right)
        t0 = time.perf_counter()
        plain = reference_plain(fl, fr, model)
        t_plain = time.perf_counter() - t0
        fast = reference_fast(fl, fr, model)
        same = np.array_equal(plain.map, fast.map)
        err = float(np.abs(plain.posterior - fast.posterior).max())
        print(f"plain vectorized float64: {t_plain:.2f} s; same MAP as fast: {same}; max |diff| {err:.1e}")
        # The ramp's true disparity of each map row (map row y is image row y + 2).
        truth = 5 + (70 * (np.arange(ho) + 2)) // 479
        print(f"MAP == true disparity on {np.mean(fast.map == truth[:, None]) * 100:.1f} % of pixels")


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
