"""Per-pixel confidence from the disparity distribution, and how well it ranks and predicts errors.

Every quantity is a function of a pixel's distribution over the M = Dmax + 2 hypotheses (rows
0..Dmax, then the no-match row): the machine's overflow counts ``c`` normalized, ``p = c / sum(c)``,
or the float64 reference's posterior normalized the same way. The exact definitions are in
``docs/confidence.md``; in short, for a pixel whose MAP is a disparity ``d``:

* ``mass``: the pixel's own mass within +-t of ``d``, ``sum p_j`` over rows ``j <= Dmax`` with
  ``|j - d| <= t`` (the no-match row is within no distance of any disparity);
* ``confidence``: the same mass of the *pooled* distribution, the mean of ``p`` over the
  ``window`` x ``window`` pixels around the pixel (those of the output region that have a
  distribution); ``window`` 1 makes it ``mass``;
* ``entropy``: ``-sum p_j log2 p_j`` over all M rows, in bits;
* ``nomatch_mass``: ``p`` of the no-match row.

A pixel with no MAP disparity (no match, timeout) has ``mass`` and ``confidence`` 0. The figures
against ground truth: the expected calibration error (ECE) of a confidence against "|d - gt| <= t"
in :data:`ECE_BINS` equal-width bins with its reliability table, and the sparsification curve of
bad-2 as the least confident pixels are removed at :data:`FRACTIONS`, with its area (AUC) beside
the random and the perfect (oracle) orders. Pixels of equal confidence are removed together in
expectation (a random order among them), so the random order's curve is flat at the bad-2 rate.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError

__all__ = [
    "DEFAULT_T",
    "DEFAULT_WINDOW",
    "MAX_T",
    "MAX_WINDOW",
    "ECE_BINS",
    "FRACTIONS",
    "BAD_THRESHOLD",
    "DECIMALS",
    "ConfidenceParams",
    "ConfidenceMaps",
    "DistributionMeasures",
    "measure_counts",
    "expected_calibration_error",
    "reliability_table",
    "sparsification_curve",
    "sparsification_auc",
    "method_figures",
    "ranking_figures",
]

DEFAULT_T = 2
DEFAULT_WINDOW = 3
# The bounds of t and window: t beyond the largest Dmax (4094) adds no disparity; a window is at most
# MAX_WINDOW pixels wide (bounded, so that no size wraps in the int64 sums).
MAX_T = 4094
MAX_WINDOW = 4095
ECE_BINS = 10
# Fractions of the pixels removed, least confident first: 0, 0.05, ..., 0.95.
FRACTIONS = np.arange(20) / 20
BAD_THRESHOLD = 2  # the sparsification curve is of bad-2, the project's headline error rate
# Confidences are binned and ranked after rounding to this many decimals: the same rational value
# computed in two orders of floating-point additions then lands in one bin and ties with itself.
DECIMALS = 9


@dataclass(frozen=True, kw_only=True)
class ConfidenceParams:
    """How a pixel's confidence is read from its distribution.

    Parameters
    ----------
    t : int
        Half-width, in disparities, of the interval around the MAP whose mass is the confidence
        (the confidence predicts "|d - gt| <= t"); 0 .. :data:`MAX_T`, default 2.
    window : int
        Side of the square of pixels whose distributions are pooled (averaged) before the mass is
        read; odd, 1 .. :data:`MAX_WINDOW` (1: the pixel's own distribution), default 3.

    Attributes
    ----------
    t, window : int
        As given (read-only).
    """

    t: int = DEFAULT_T
    window: int = DEFAULT_WINDOW

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", as_int("t", self.t, 0, MAX_T))
        object.__setattr__(self, "window", as_int("window", self.window, 1, MAX_WINDOW))
        if self.window % 2 == 0:
            raise ParameterError(f"window must be odd (a square around its pixel), got {self.window}",
                                 "window")

    def to_dict(self) -> dict[str, int]:
        return {"t": self.t, "window": self.window}


@dataclass
class ConfidenceMaps:
    """The per-pixel measures of one method over the output region, each (Ho, Wo) float64."""

    mass: np.ndarray
    confidence: np.ndarray
    entropy: np.ndarray
    nomatch_mass: np.ndarray

    def arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """The four maps by name (``result.npz``'s keys, after ``prefix``), as float32."""
        return {f"{prefix}{k}": getattr(self, k).astype(np.float32)
                for k in ("mass", "confidence", "entropy", "nomatch_mass")}


def _normalized(dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p, has): each pixel's distribution over the last axis normalized to sum 1; pixels with none
    (all zero) get p = 0 and has = False."""
    d = np.asarray(dist, dtype=np.float64)
    n = d.sum(axis=-1)
    has = n > 0
    return d / np.where(has, n, 1.0)[..., None], has


def _box_rows(a: np.ndarray, half: int) -> np.ndarray:
    """Sum of ``a`` (W, ...) over the columns x - half .. x + half that exist, for every x."""
    c = np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0)])
    x = np.arange(a.shape[0])
    return c[np.minimum(x + half + 1, a.shape[0])] - c[np.maximum(x - half, 0)]


def _mass_near(p: np.ndarray, dmap: np.ndarray, t: int) -> np.ndarray:
    """sum of p[x, j] over disparity rows j (not the last, no-match row) with |j - d[x]| <= t; 0 where
    d < 0. ``p`` is (W, M), ``dmap`` (W,)."""
    rows = p.shape[1] - 1  # disparity rows 0..Dmax
    c = np.concatenate([np.zeros((p.shape[0], 1)), np.cumsum(p[:, :rows], axis=1)], axis=1)
    d = np.asarray(dmap, dtype=np.int64)
    x = np.arange(p.shape[0])
    hi = np.clip(d + t + 1, 0, rows)
    lo = np.clip(d - t, 0, rows)
    return np.where(d >= 0, c[x, hi] - c[x, lo], 0.0)


class DistributionMeasures:
    """The :class:`ConfidenceMaps` of a method, fed its distributions band by band, top to bottom.

    ``add(rows, dist)`` takes output rows ``rows`` and their distributions (n, Wo, M), counts or
    posterior (copied as needed: the caller may reuse its buffer); only ``window`` rows of
    column-pooled sums are held. :meth:`result` returns the maps once every row came.
    """

    def __init__(self, dmap: np.ndarray, params: ConfidenceParams) -> None:
        self.dmap = np.asarray(dmap)
        self.params = params
        shape = self.dmap.shape
        self.maps = ConfidenceMaps(*(np.zeros(shape) for _ in range(4)))
        self._half = params.window // 2
        self._rows: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self._next = 0  # the next output row expected
        self._emitted = 0  # rows whose confidence is final

    def add(self, rows: slice, dist: np.ndarray) -> None:
        if rows.start != self._next:
            raise ValueError(f"rows must come in order: expected row {self._next}, got {rows.start}")
        t, half = self.params.t, self._half
        for i, y in enumerate(range(rows.start, rows.stop)):
            p, has = _normalized(dist[i])
            d = self.dmap[y]
            self.maps.mass[y] = _mass_near(p, d, t)
            with np.errstate(divide="ignore", invalid="ignore"):
                self.maps.entropy[y] = -np.where(p > 0, p * np.log2(np.where(p > 0, p, 1.0)), 0.0).sum(-1)
            self.maps.nomatch_mass[y] = p[:, -1]
            self._rows.append((y, _box_rows(p, half), _box_rows(has.astype(np.float64), half)))
            while len(self._rows) > 2 * half + 1:
                self._rows.popleft()
            if y - half >= 0:
                self._emit(y - half)
        self._next = rows.stop

    def _emit(self, y: int) -> None:
        lo, hi = y - self._half, y + self._half
        parts = [(s, n) for r, s, n in self._rows if lo <= r <= hi]
        total = sum(s for s, _ in parts)
        count = sum(n for _, n in parts)
        pooled = total / np.where(count > 0, count, 1.0)[:, None]
        self.maps.confidence[y] = _mass_near(pooled, self.dmap[y], self.params.t)
        self._emitted = y + 1

    def result(self) -> ConfidenceMaps:
        height = self.dmap.shape[0]
        if self._next != height:
            raise ValueError(f"rows 0..{height - 1} expected, got 0..{self._next - 1}")
        for y in range(self._emitted, height):
            self._emit(y)
        return self.maps


def measure_counts(counts: np.ndarray, dmap: np.ndarray, params: ConfidenceParams,
                   band_rows: int = 64) -> ConfidenceMaps:
    """The :class:`ConfidenceMaps` of a machine's counts (Ho, Wo, M) and its MAP (Ho, Wo; < 0: none)."""
    acc = DistributionMeasures(dmap, params)
    for y0 in range(0, counts.shape[0], band_rows):
        rows = slice(y0, min(counts.shape[0], y0 + band_rows))
        acc.add(rows, counts[rows])
    return acc.result()


# --- figures against ground truth ---------------------------------------------------------------


def _rounded(conf: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(conf, np.float64), DECIMALS)


def _bins(conf: np.ndarray, bins: int) -> np.ndarray:
    """Bin i holds i/bins <= conf < (i+1)/bins (conf rounded to DECIMALS); conf = 1 falls in the last."""
    return np.minimum(np.floor(_rounded(conf) * bins).astype(np.int64), bins - 1)


def reliability_table(conf: np.ndarray, good: np.ndarray, bins: int = ECE_BINS) -> list[dict[str, object]]:
    """Per bin: its bounds, the mean confidence (``predicted``), the rate of ``good``
    (``observed``; both None for an empty bin) and the pixel count."""
    c = np.asarray(conf, np.float64)
    g = np.asarray(good, bool)
    idx = _bins(c, bins)
    table = []
    for i in range(bins):
        sel = idx == i
        n = int(sel.sum())
        table.append({"lower": i / bins, "upper": (i + 1) / bins, "count": n,
                      "predicted": float(c[sel].mean()) if n else None,
                      "observed": float(g[sel].mean()) if n else None})
    return table


def expected_calibration_error(conf: np.ndarray, good: np.ndarray, bins: int = ECE_BINS) -> float:
    """sum over bins of (count / N) |mean confidence - rate of good|; NaN for no pixel."""
    n = int(np.asarray(conf).size)
    if n == 0:
        return math.nan
    return float(sum(r["count"] / n * abs(r["predicted"] - r["observed"])  # type: ignore[operator]
                     for r in reliability_table(conf, good, bins) if r["count"]))


def sparsification_curve(conf: np.ndarray, bad: np.ndarray, fractions: np.ndarray = FRACTIONS) -> np.ndarray:
    """The rate of ``bad`` among the pixels kept when a fraction f of them, the least confident, is
    removed, for each f of ``fractions``. Equal confidences are removed together in expectation:
    the kept (1 - f) N pixels' expected bad count interpolates linearly within a group of ties."""
    c = _rounded(conf).ravel()
    b = np.asarray(bad, bool).ravel()
    n = c.size
    if n == 0:
        return np.full(len(fractions), np.nan)
    order = np.argsort(-c, kind="stable")
    c, b = c[order], b[order]
    ends = np.flatnonzero(np.r_[c[1:] != c[:-1], True]) + 1  # one past each group of equal values
    taken = np.r_[0, ends].astype(np.float64)
    bad_taken = np.r_[0, np.cumsum(b)[ends - 1]].astype(np.float64)
    kept = (1.0 - np.asarray(fractions, np.float64)) * n
    return np.interp(kept, taken, bad_taken) / kept


def sparsification_auc(curve: np.ndarray) -> float:
    """The area under a sparsification curve sampled at :data:`FRACTIONS`: the mean of its points."""
    return float(np.mean(curve))


def ranking_figures(conf: np.ndarray, bad: np.ndarray) -> dict[str, object]:
    """The sparsification curves and AUCs of ``conf`` and of the random and perfect orders."""
    b = np.asarray(bad, bool)
    curve = sparsification_curve(conf, b)
    random = sparsification_curve(np.zeros(b.shape), b)
    perfect = sparsification_curve((~b).astype(np.float64), b)
    return {
        "pixels": int(b.size),
        "auc": sparsification_auc(curve),
        "auc_random": sparsification_auc(random),
        "auc_perfect": sparsification_auc(perfect),
        "curve": [float(v) for v in curve],
        "curve_perfect": [float(v) for v in perfect],
    }


def method_figures(maps: ConfidenceMaps, disp: np.ndarray, gt: np.ndarray, t: int) -> dict[str, object]:
    """ECE, reliability table and sparsification of a method's confidence over the pixels with
    finite ground truth that it matched (``disp`` >= 0), and the same of its pixel ``mass``."""
    d = np.asarray(disp, np.float64)
    g = np.asarray(gt, np.float64)
    sel = np.isfinite(g) & (d >= 0)
    err = np.abs(d[sel] - g[sel])
    good = err <= t
    bad = err > BAD_THRESHOLD
    conf = maps.confidence[sel]
    out: dict[str, object] = {
        "ece": expected_calibration_error(conf, good),
        **ranking_figures(conf, bad),
        "reliability": reliability_table(conf, good),
        "mean_confidence": float(conf.mean()) if conf.size else math.nan,
        "observed": float(good.mean()) if good.size else math.nan,
    }
    mass = maps.mass[sel]
    out["pixel_mass"] = {"ece": expected_calibration_error(mass, good),
                         "auc": sparsification_auc(sparsification_curve(mass, bad))}
    return out
