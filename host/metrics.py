"""Figures comparing the machine with the reference and the ground truth (paper Fig 6).

* cycles per pixel: mean, std, p99 (timeouts included, at their watchdog count); with passes run
  before the model's own (census-lr's right pass), the mean counts every pass (all compute cycles over
  the output pixels), the other figures are the own pass's (``left_pass_*``), and each declared pass's
  own figures are ``NAME_pass_*`` (``right_pass_*``);
* RMS error between counts / n_max and the reference posterior normalized to max 1,
  over the pixels the reference calls matched, all M rows;
* F1 of no-match detection, positive class = no match (a timeout counts as no match);
* MAP agreement with the reference (no match = -1 on both sides);
* bad-1 / bad-2 against ground truth over pixels with finite gt, both excluding the
  pixels a method calls no match and counting them as bad; OpenCV StereoSGBM and StereoBM
  alongside; the share of each method's no-match calls that fall on occluded pixels;
* the per-pixel confidence of the machine (from its counts) and of the reference (from its
  posterior), :mod:`.confidence`: with ground truth, its calibration (ECE, reliability table) and
  how it ranks errors (sparsification AUC beside the random and perfect orders); SGBM's
  left-right-check confidence (:func:`sgbm_lr_confidence`) as the classical baseline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from bayesmachine.extras import optional
from bayesmachine.models import OWN_PASS
from bayesmachine.region import MARGIN, OutputRegion

from .confidence import (
    BAD_THRESHOLD,
    ECE_BINS,
    FRACTIONS,
    ConfidenceMaps,
    ConfidenceParams,
    DistributionMeasures,
    measure_counts,
    method_figures,
    ranking_figures,
)
from .records import MachineRun, Prepared

if TYPE_CHECKING:
    from .fill import Fill

cv2 = optional("cv2", "OpenCV")

__all__ = [
    "RunMetrics",
    "cycle_stats",
    "rms_error",
    "RmsAccumulator",
    "f1_score",
    "map_agreement",
    "bad_rates",
    "gt_region",
    "SGBM_TUNED",
    "sgbm_disparity",
    "sgbm_lr_confidence",
    "bm_disparity",
    "occluded_mask",
    "nomatch_occluded_share",
    "evaluate",
    "confidence_report",
    "json_safe",
    "NO_KNOWN_GT",
]


def gt_region(gt: np.ndarray, dmax: int, margin: int = MARGIN) -> np.ndarray:
    """Ground truth (image coordinates) over the output region (a model's ``margin``), float,
    non-finite = unknown."""
    return np.asarray(OutputRegion.of_image(gt.shape, dmax, margin).cut(gt), dtype=np.float64)


def cycle_stats(cycles: np.ndarray) -> dict[str, float]:
    c = np.asarray(cycles, dtype=np.float64).ravel()
    if c.size == 0:
        return {k: math.nan for k in ("mean", "std", "p10", "median", "p90", "p99")}
    p10, median, p90, p99 = (float(v) for v in np.percentile(c, [10, 50, 90, 99]))
    mean, std = float(c.mean()), float(c.std())
    return {"mean": mean, "std": std, "p10": p10, "median": median, "p90": p90, "p99": p99}


class RmsAccumulator:
    """RMS of counts/n_max - posterior/max(posterior), accumulated over blocks of pixels.

    ``add`` takes ``counts`` and ``posterior`` of shape (..., M) and ``matched`` of the leading
    shape; only matched pixels enter, all M rows of each. ``value`` is NaN when none did.
    """

    def __init__(self, counter_max: int) -> None:
        self.counter_max = counter_max
        self.total = 0.0
        self.values = 0

    def add(self, counts: np.ndarray, posterior: np.ndarray, matched: np.ndarray) -> None:
        m = counts.shape[-1]
        c = np.asarray(counts).reshape(-1, m)
        p = np.asarray(posterior).reshape(-1, m)
        sel = np.asarray(matched, dtype=bool).reshape(-1)
        if c.shape != p.shape or sel.shape[0] != c.shape[0]:
            raise ValueError(
                f"shapes differ: counts {counts.shape}, posterior {posterior.shape}, matched {matched.shape}"
            )
        block = 1 << 15  # blocks of pixels keep the float temporaries small
        for i in range(0, c.shape[0], block):
            s = sel[i : i + block]
            if not s.any():
                continue
            pm = p[i : i + block][s]
            est = c[i : i + block][s].astype(np.float64) / self.counter_max
            diff = est - pm / pm.max(axis=-1, keepdims=True)
            self.total += float(np.square(diff).sum())
            self.values += diff.size

    @property
    def value(self) -> float:
        return math.sqrt(self.total / self.values) if self.values else math.nan


def rms_error(counts: np.ndarray, counter_max: int, posterior: np.ndarray, matched: np.ndarray) -> float:
    """RMS of counts/n_max - posterior/max(posterior) over ``matched`` pixels and all rows.

    ``counts`` and ``posterior`` are (..., M); ``matched`` is the leading shape (bool).
    NaN when no pixel is matched.
    """
    acc = RmsAccumulator(counter_max)
    acc.add(counts, posterior, matched)
    return acc.value


def f1_score(predicted: np.ndarray, actual: np.ndarray) -> float:
    """F1 of a boolean detection (positive = True). NaN when neither side has a positive."""
    pred = np.asarray(predicted, dtype=bool)
    act = np.asarray(actual, dtype=bool)
    tp = int(np.sum(pred & act))
    fp = int(np.sum(pred & ~act))
    fn = int(np.sum(~pred & act))
    if tp + fp + fn == 0:
        return math.nan
    return 2 * tp / (2 * tp + fp + fn)


def map_agreement(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels where two disparity maps (-1 = no match) agree exactly."""
    a = np.asarray(a)
    return float(np.mean(a == np.asarray(b))) if a.size else math.nan


def bad_rates(disp: np.ndarray, gt: np.ndarray, n: float) -> dict[str, float]:
    """bad-n = |d - gt| > n over pixels with finite gt; ``disp`` < 0 is no match.

    Returns ``matched`` (no-match pixels excluded), ``nomatch_bad`` (no-match counted as
    bad) and ``coverage`` (the fraction of finite-gt pixels the method matched).
    """
    d = np.asarray(disp, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    known = np.isfinite(g)
    matched = known & (d >= 0)
    bad = matched & (np.abs(d - np.where(known, g, 0.0)) > n)
    n_known = int(known.sum())
    n_matched = int(matched.sum())
    return {
        "matched": float(bad.sum() / n_matched) if n_matched else math.nan,
        "nomatch_bad": float((bad.sum() + (known & ~matched).sum()) / n_known) if n_known else math.nan,
        "coverage": float(n_matched / n_known) if n_known else math.nan,
    }


def sgbm_numdisparities(dmax: int) -> int:
    """numDisparities = Dmax + 1 rounded up to a multiple of 16 (OpenCV's requirement)."""
    return -(-(dmax + 1) // 16) * 16


# A tuned StereoSGBM, as the FPGA stereo literature runs it: 3-way, block 5, P1 = 8·3·25, P2 = 32·3·25,
# uniqueness 10, speckle window 100 / range 2, disp12MaxDiff 1, preFilterCap 63.
SGBM_TUNED = {"blockSize": 5, "P1": 8 * 3 * 25, "P2": 32 * 3 * 25, "uniquenessRatio": 10,
              "speckleWindowSize": 100, "speckleRange": 2, "disp12MaxDiff": 1, "preFilterCap": 63}


def _sgbm_image(left: np.ndarray, right: np.ndarray, dmax: int, tuned: bool = False) -> np.ndarray | None:
    """OpenCV StereoSGBM (blockSize 5; ``tuned``: :data:`SGBM_TUNED`, mode SGBM_3WAY) over the whole image,
    float, -1 = invalid; None when OpenCV cannot run it (an image barely wider than numDisparities)."""
    n = sgbm_numdisparities(dmax)
    if tuned:
        sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=n, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
                                     **SGBM_TUNED)
    else:
        sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=n, blockSize=5)
    try:
        raw = sgbm.compute(np.ascontiguousarray(left), np.ascontiguousarray(right))
    except cv2.error:
        return None
    disp = raw.astype(np.float64) / 16.0  # int16, 4 fractional bits, negative = invalid
    disp[raw < 0] = -1.0
    return disp


def sgbm_disparity(left: np.ndarray, right: np.ndarray, dmax: int, margin: int = MARGIN,
                   tuned: bool = False) -> np.ndarray | None:
    """OpenCV StereoSGBM (blockSize 5, its defaults; ``tuned``: :data:`SGBM_TUNED`) on the full pair, cut to
    the output region; -1 = invalid.

    None when OpenCV cannot run it: an image barely wider than numDisparities (a narrow crop).
    """
    disp = _sgbm_image(left, right, dmax, tuned)
    return None if disp is None else OutputRegion.of_image(disp.shape, dmax, margin).cut(disp)


def sgbm_lr_confidence(left: np.ndarray, right: np.ndarray, dmax: int,
                       margin: int = MARGIN) -> np.ndarray | None:
    """SGBM's left-right-check confidence over the output region: 1 / (1 + |d_L(x) - d_R(x')|), where
    d_L is SGBM's left disparity, d_R its right one (SGBM on the mirrored pair, right image as the
    reference) and x' = round(x - d_L(x)); 0 where either is invalid or x' leaves the image. None when
    OpenCV cannot run SGBM."""
    dl = _sgbm_image(left, right, dmax)
    mirrored = _sgbm_image(right[:, ::-1], left[:, ::-1], dmax)
    if dl is None or mirrored is None:
        return None
    dr = mirrored[:, ::-1]
    h, w = dl.shape
    xr = np.rint(np.arange(w)[None, :] - dl).astype(np.int64)
    ok = (dl >= 0) & (xr >= 0) & (xr < w)
    drx = dr[np.arange(h)[:, None], np.clip(xr, 0, w - 1)]
    ok &= drx >= 0
    conf = np.where(ok, 1.0 / (1.0 + np.abs(dl - drx)), 0.0)
    return OutputRegion.of_image(conf.shape, dmax, margin).cut(conf)


def bm_disparity(left: np.ndarray, right: np.ndarray, dmax: int, block: int = 15,
                 margin: int = MARGIN) -> np.ndarray | None:
    """OpenCV StereoBM (``block`` x ``block``), like :func:`sgbm_disparity`: output region, -1 = invalid."""
    bm = cv2.StereoBM_create(numDisparities=sgbm_numdisparities(dmax), blockSize=block)
    try:
        raw = bm.compute(left, right)
    except cv2.error:
        return None
    disp = raw.astype(np.float64) / 16.0
    disp[raw < 0] = -1.0
    return OutputRegion.of_image(disp.shape, dmax, margin).cut(disp)


def occluded_mask(gt: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Left pixels the right camera cannot see, from the left ground truth (image coordinates).

    Pixel x of a row (disparity g, finite) lands on x - g in the right image; a pixel x' > x of
    the same row landing there or further left (x' - g(x') <= x - g(x) - ``tolerance``) is a
    nearer surface hiding it (a jump of k in disparity hides k pixels). Unknown gt (non-finite)
    hides nothing and is not occluded.
    """
    g = np.asarray(gt, dtype=np.float64)
    known = np.isfinite(g)
    x = np.arange(g.shape[1], dtype=np.float64)[None, :]
    land = np.where(known, x - np.where(known, g, 0.0), np.inf)
    # Running minimum of x' - g(x') over x' > x, from the right.
    right_min = np.minimum.accumulate(land[:, ::-1], axis=1)[:, ::-1]
    after = np.concatenate([right_min[:, 1:], np.full((g.shape[0], 1), np.inf)], axis=1)
    return known & (after <= land - tolerance)


def nomatch_occluded_share(disp: np.ndarray, occluded: np.ndarray) -> float:
    """The share of a method's no-match calls (``disp`` < 0) that fall on occluded pixels; NaN if none."""
    nm = np.asarray(disp) < 0
    n = int(nm.sum())
    return float((nm & np.asarray(occluded, dtype=bool)).sum() / n) if n else math.nan


def json_safe(v: object) -> object:
    """JSON-safe: NaN -> None, numpy scalars -> Python (in dicts and lists too)."""
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return None if math.isnan(v) else v
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, dict):
        return {k: json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x) for x in v]
    return v


@dataclass
class RunMetrics:
    pixels: int
    cycles: dict[str, float]
    rms_error: float
    nomatch_f1: float
    map_agreement: float
    timeouts: int
    machine_nomatch: int
    reference_nomatch: int
    bad: dict[str, dict[str, float]] | None = None  # {"machine": {...}, "reference": ..., "sgbm": ...}
    sgbm_map: np.ndarray | None = field(default=None, repr=False)  # SGBM's disparity, when computed
    # The passes run before the own one (census-lr's "right"), by name: pixels, cycles, timeouts.
    passes: dict[str, dict[str, float]] = field(default_factory=dict)
    confidence: dict[str, object] | None = None  # the confidence figures (confidence_report)
    fill: Fill | None = field(default=None, repr=False)  # the filled map (None: not filled)
    fill_maps: ConfidenceMaps | None = field(default=None, repr=False)  # its confidence (None: no counts)
    maps: ConfidenceMaps | None = field(default=None, repr=False)  # the machine's (None: no counts)
    reference_maps: ConfidenceMaps | None = field(default=None, repr=False)
    ground_truth_pixels: int | None = None  # output pixels with a known (finite) ground truth

    def to_report(self) -> dict[str, object]:
        out: dict[str, object] = {
            "pixels": self.pixels,
            "cycles_per_pixel_mean": self.cycles["mean"],
            "cycles_per_pixel_std": self.cycles["std"],
            "cycles_per_pixel_p99": self.cycles["p99"],
            # The per-pixel distribution is heavy-tailed (a few pixels run 100x longer): quantiles say more.
            "cycles_per_pixel_p10": self.cycles["p10"],
            "cycles_per_pixel_median": self.cycles["median"],
            "cycles_per_pixel_p90": self.cycles["p90"],
            "rms_error": self.rms_error,
            "nomatch_f1": self.nomatch_f1,
            "map_agreement": self.map_agreement,
            "timeouts": self.timeouts,
            "machine_nomatch_pixels": self.machine_nomatch,
            "reference_nomatch_pixels": self.reference_nomatch,
        }
        if self.passes:
            # Cycles per pixel count every pass: every compute cycle over the output pixels.
            out[f"{OWN_PASS}_pass_cycles_per_pixel_mean"] = self.cycles["mean"]
            out["cycles_per_pixel_mean"] = self.cycles["mean"] + sum(
                figures["cycles_sum"] for figures in self.passes.values()) / self.pixels
            for name, figures in self.passes.items():
                out.update({f"{name}_pass_{k}": v for k, v in figures.items() if k != "cycles_sum"})
        if self.bad is not None:
            for method, figs in self.bad.items():
                for k, v in figs.items():
                    out[f"{method}_{k}"] = v
        if self.ground_truth_pixels is not None:
            out["ground_truth_pixels"] = self.ground_truth_pixels
        if self.fill is not None:
            out["fill"] = self.fill.rule
            out["fill_holes"] = int(self.fill.holes.sum())
            out["filled_pixels"] = int(self.fill.filled.sum())
        if self.confidence is not None:
            out.update(_confidence_keys(self.confidence))
            out["confidence"] = self.confidence
        return json_safe(out)  # type: ignore[return-value]


# The confidence figures a sweep pools over pairs (top-level numbers of each task's report).
_POOLED = ("ece", "auc", "auc_random", "auc_perfect")


def _confidence_keys(conf: dict[str, object]) -> dict[str, object]:
    """The confidence figures as flat report keys: ``machine_confidence_ece``, ``sgbm_lr_auc``, ..."""
    out: dict[str, object] = {"mean_confidence": conf.get("mean_confidence")}
    for method in ("machine", "reference", "filled"):
        figs = conf.get(method)
        if isinstance(figs, dict):
            out.update({f"{method}_confidence_{k}": figs.get(k) for k in _POOLED})
            out[f"{method}_pixel_mass_auc"] = figs["pixel_mass"]["auc"]  # type: ignore[index]
    sgbm = conf.get("sgbm_lr")
    if isinstance(sgbm, dict):
        out.update({f"sgbm_lr_{k}": sgbm.get(k) for k in _POOLED if k != "ece"})
    return out


def evaluate(prepared: Prepared, run: MachineRun, sgbm: bool | None = None,
             confidence: ConfidenceParams | None = None, fill: Fill | None = None) -> RunMetrics:
    """All figures of one machine run against the prepared reference (and gt).

    The RMS error and the reference's confidence need the float64 posterior: it is recomputed
    band by band and accumulated, so memory stays at one band whatever the frame size.
    ``confidence``: how confidence is read from a distribution (default ``ConfidenceParams()``).
    ``fill``: the run's filled map (:mod:`.fill`; its figures are the method ``filled``'s, a filled
    pixel's confidence that of the pixel whose disparity it took).
    """
    ref_map = prepared.reference_map
    if ref_map is None:
        raise ValueError("the pair was prepared without its reference (prepare(..., reference=False)): "
                         "nothing to evaluate the run against")
    params = confidence if confidence is not None else ConfidenceParams()
    machine_nm = run.map < 0  # no-match row won, or watchdog timeout
    ref_nm = ref_map < 0
    rms = RmsAccumulator(run.machine.readout_max)
    ref_conf = DistributionMeasures(ref_map, params)
    for rows, band in prepared.reference_bands():
        ref_conf.add(rows, band.posterior)
        if run.counts is not None:  # a board asked for MAPs only has no counts: no RMS error (null)
            rms.add(run.counts[rows], band.posterior, band.map >= 0)
    maps = None if run.counts is None else measure_counts(run.counts, run.map, params)
    filled = fill is not None and fill.rule != "none"
    fill_maps = None if maps is None or not filled else _carried(maps, fill)
    ref_maps = ref_conf.result()
    bad = None
    sgbm_map = None
    lr_conf = None
    if prepared.gt is not None:
        methods = {"machine": run.map, "reference": ref_map}
        if filled:
            methods["filled"] = fill.map
        if sgbm is None or sgbm:  # OpenCV's block matchers: SGBM (block 5) and StereoBM (block 15)
            dmax, margin = prepared.model.dmax, prepared.model.margin
            sgbm_map = sgbm_disparity(prepared.left, prepared.right, dmax, margin)
            if sgbm_map is not None:  # too narrow for SGBM: the report simply has no SGBM figures
                methods["sgbm"] = sgbm_map
                lr_conf = sgbm_lr_confidence(prepared.left, prepared.right, dmax, margin)
                tuned = sgbm_disparity(prepared.left, prepared.right, dmax, margin, tuned=True)
                if tuned is not None:
                    methods["sgbm_tuned"] = tuned
            bm_map = bm_disparity(prepared.left, prepared.right, dmax, margin=margin)
            if bm_map is not None:
                methods["bm"] = bm_map
        bad = _bad_figures(prepared, methods)
    return RunMetrics(
        pixels=int(run.map.size),
        cycles=cycle_stats(run.cycles if run.cycles is not None else np.empty(0)),
        rms_error=rms.value,
        nomatch_f1=f1_score(machine_nm, ref_nm),
        map_agreement=map_agreement(run.map, ref_map),
        timeouts=int(run.timeout.sum()),
        machine_nomatch=int(machine_nm.sum()),
        reference_nomatch=int(ref_nm.sum()),
        bad=bad,
        sgbm_map=sgbm_map,
        passes={name: _pass_figures(r.cycles, r.timeout) for name, r in run.passes.items()},
        confidence=confidence_report(params, maps, ref_maps, run.map, ref_map, prepared.gt, sgbm_map,
                                     lr_conf, (fill_maps, fill.map) if fill_maps is not None else None),
        maps=maps,
        reference_maps=ref_maps,
        ground_truth_pixels=None if prepared.gt is None else int(np.isfinite(prepared.gt).sum()),
        fill=fill if filled else None,
        fill_maps=fill_maps,
    )


def _carried(maps: ConfidenceMaps, fill: Fill) -> ConfidenceMaps:
    """The filled map's measures: a filled pixel's are those of the pixel whose disparity it took."""
    return ConfidenceMaps(*(fill.carried(getattr(maps, k))
                            for k in ("mass", "confidence", "entropy", "nomatch_mass")))


def _bad_figures(prepared: Prepared, methods: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """bad-1 / bad-2 (matched, no match counted bad), coverage and no match on occluded pixels."""
    assert prepared.gt is not None
    occluded = None
    if prepared.gt_image is not None and np.isfinite(prepared.gt).any():  # else no pixel's occlusion is known
        occluded = gt_region(occluded_mask(prepared.gt_image), prepared.model.dmax,
                             prepared.model.margin).astype(bool)
    bad: dict[str, dict[str, float]] = {}
    for name, disp in methods.items():
        b1 = bad_rates(disp, prepared.gt, 1)
        b2 = bad_rates(disp, prepared.gt, 2)
        bad[name] = {
            "bad1": b1["matched"],
            "bad2": b2["matched"],
            "bad1_nomatch_bad": b1["nomatch_bad"],
            "bad2_nomatch_bad": b2["nomatch_bad"],
            "coverage": b1["coverage"],
        }
        if occluded is not None:
            bad[name]["nomatch_occluded"] = nomatch_occluded_share(disp, occluded)
    return bad


# What a report says when the ground truth knows no output pixel (every value NaN, inf or 0 in an image).
NO_KNOWN_GT = ("the ground truth has no known pixel in the output region (every value unknown): no accuracy, "
               "occlusion or calibration figures")


def confidence_report(
    params: ConfidenceParams, maps: ConfidenceMaps | None, ref_maps: ConfidenceMaps, disp: np.ndarray,
    ref_map: np.ndarray, gt: np.ndarray | None, sgbm_map: np.ndarray | None = None,
    lr_conf: np.ndarray | None = None, filled: tuple[ConfidenceMaps, np.ndarray] | None = None,
) -> dict[str, object]:
    """The report's ``confidence`` entry: the parameters, the machine's mean confidence over its
    matched pixels and, with ground truth, each method's calibration and sparsification figures (the
    filled map's, ``filled``: its confidence maps and its map, over every pixel it gives a disparity).
    Without counts (a board asked for MAPs only) the machine has no confidence: None, never made up."""
    matched = np.asarray(disp) >= 0
    out: dict[str, object] = {
        **params.to_dict(), "bins": ECE_BINS, "fractions": [float(f) for f in FRACTIONS],
        "sparsification_bad": BAD_THRESHOLD,
        "mean_confidence": (float(maps.confidence[matched].mean()) if maps is not None and matched.any()
                            else None),
    }
    if maps is None:
        out["machine"] = None
        out["note"] = "the run has no counts (--board-fields without counts): no machine confidence"
    if gt is None:
        return out
    if not np.isfinite(gt).any():  # figures of no pixel would be empty: none, and the reason
        out["note"] = NO_KNOWN_GT
        return out
    if maps is not None:
        out["machine"] = method_figures(maps, disp, gt, params.t)
    out["reference"] = method_figures(ref_maps, ref_map, gt, params.t)
    if filled is not None:
        out["filled"] = method_figures(filled[0], filled[1], gt, params.t)
    if sgbm_map is not None and lr_conf is not None:
        sel = np.isfinite(gt) & (sgbm_map >= 0)
        out["sgbm_lr"] = ranking_figures(lr_conf[sel], np.abs(sgbm_map[sel] - gt[sel]) > BAD_THRESHOLD)
    return out


def _pass_figures(cycles: np.ndarray, timeout: np.ndarray) -> dict[str, float]:
    """A declared pass's own figures (per pixel of its grid)."""
    stats = cycle_stats(cycles)
    return {
        "pixels": int(cycles.size),
        "cycles_sum": float(cycles.sum()),
        "cycles_per_pixel_mean": stats["mean"],
        "cycles_per_pixel_median": stats["median"],
        "cycles_per_pixel_p99": stats["p99"],
        "timeouts": int(timeout.sum()),
    }
