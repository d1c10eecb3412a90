"""Exact (float64) inference: the reference the machine is measured against.

Posterior over Dmax+2 hypotheses per output pixel: disparity d gets the product of the
three likelihoods, the no-match hypothesis its probability alone (uniform prior over all
Dmax+2), normalized to sum 1. MAP = argmax of the unnormalized products (the same order
as the posterior's, without a division that could round two close values into a tie);
exact ties go to the lowest index, so no match wins only when strictly more probable.

``reference_fast`` is a numba loop with one lookup table per feature instead of exp;
``reference_plain`` is the vectorized float64 formula, kept as its test oracle.
Large frames go band by band (:func:`reference_bands`, :func:`reference_map`), so the
float64 posterior volume (H x W x (Dmax+2) x 8 bytes) is never held whole.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numba
import numpy as np

from .features import FeatureSums, feature_sums
from .images import validate_pair
from .likelihoods import LikelihoodTables, ModelParams, likelihood_tables, likelihoods_plain
from .region import OutputRegion

__all__ = [
    "Reference",
    "reference",
    "reference_fast",
    "reference_bands",
    "reference_map",
    "reference_plain",
    "map_from_index",
    "warm_up",
]


@dataclass
class Reference:
    """posterior (Ho, Wo, Dmax+2) float64, last index = no match; map (Ho, Wo) int16, -1 = no match."""

    posterior: np.ndarray
    map: np.ndarray

    @property
    def nomatch(self) -> np.ndarray:
        return self.map < 0


def map_from_index(index: np.ndarray, dmax: int) -> np.ndarray:
    """Hypothesis index (0..Dmax+1) -> disparity map int16 with -1 for no match."""
    out = np.asarray(index).astype(np.int16)
    out[out == dmax + 1] = -1
    return out


@numba.njit(parallel=True, cache=True, fastmath=False, boundscheck=False)
def _reference_kernel(ml, mr, ghl, ghr, gvl, gvr, tm, tgh, tgv, tnm, dmax, post, idx):  # pragma: no cover
    h, w4 = ml.shape
    wo = w4 - dmax
    nm_index = dmax + 1
    for y in numba.prange(h):
        for i in range(wo):
            x = i + dmax
            a = ml[y, x]
            b = ghl[y, x]
            c = gvl[y, x]
            out = post[y, i]
            best = -1.0
            arg = 0
            total = 0.0
            for d in range(dmax + 1):
                v = tm[abs(a - mr[y, x - d])] * tgh[abs(b - ghr[y, x - d])] * tgv[abs(c - gvr[y, x - d])]
                out[d] = v
                total += v
                if v > best:  # strict: the lowest index wins exact ties
                    best = v
                    arg = d
            v = tnm[abs(c)]
            out[nm_index] = v
            total += v
            if v > best:
                arg = nm_index
            for d in range(dmax + 2):
                out[d] = out[d] / total
            idx[y, i] = arg


def reference_fast(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    tables: LikelihoodTables | None = None,
    out: np.ndarray | None = None,
    rows: slice | None = None,
) -> Reference:
    """The reference of output rows ``rows`` (default all) by a compiled loop (2 threads here).

    ``out``, if given, receives the posterior: float64 of shape (rows, Wo, Dmax+2).
    """
    tables = tables if tables is not None else likelihood_tables(model)
    region = OutputRegion.of_features(left.shape, model.dmax)
    if rows is not None:
        left, right = left.band(rows), right.band(rows)
    shape = (left.shape[0], region.shape[1], model.hypotheses)
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64:
        raise ValueError(f"out must be float64 of shape {shape}, got {out.dtype} {out.shape}")
    idx = np.empty(shape[:2], dtype=np.int16)
    _reference_kernel(
        left.m25,
        right.m25,
        left.gh20,
        right.gh20,
        left.gv20,
        right.gv20,
        tables.m,
        tables.gh,
        tables.gv,
        tables.nomatch,
        model.dmax,
        out,
        idx,
    )
    idx[idx == model.dmax + 1] = -1
    return Reference(out, idx)


def reference_bands(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    band_rows: int | None = None,
    tables: LikelihoodTables | None = None,
) -> Iterator[tuple[slice, Reference]]:
    """The reference band by band: (output rows, their Reference), top to bottom.

    One posterior buffer is reused: a band's posterior is overwritten by the next band
    (copy it to keep it). Memory: one band, about ``BAND_PIXELS`` x (Dmax+2) x 8 bytes.
    """
    tables = tables if tables is not None else likelihood_tables(model)
    region = OutputRegion.of_features(left.shape, model.dmax)
    buffer: np.ndarray | None = None
    for rows in region.bands(band_rows):
        n = rows.stop - rows.start
        if buffer is None or buffer.shape[0] < n:
            buffer = np.empty((n, region.shape[1], model.hypotheses))
        yield rows, reference_fast(left, right, model, tables, out=buffer[:n], rows=rows)


def reference_map(
    left: FeatureSums, right: FeatureSums, model: ModelParams, band_rows: int | None = None
) -> np.ndarray:
    """The MAP (Ho, Wo) int16 (-1 = no match) of every output pixel, band by band."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    out = np.empty(region.shape, dtype=np.int16)
    for rows, band in reference_bands(left, right, model, band_rows):
        out[rows] = band.map
    return out


_warm = False


def warm_up() -> None:
    """Load (or compile) the numba kernel once, so timings measure the computation only."""
    global _warm
    if not _warm:
        img = np.zeros((6, 7), np.uint8)
        f = feature_sums(img)
        reference_fast(f, f, ModelParams(dmax=1))
        _warm = True


def reference_plain(left: FeatureSums, right: FeatureSums, model: ModelParams) -> Reference:
    """The reference by the plain vectorized float64 formula (memory-hungry: test oracle)."""
    lik, nm = likelihoods_plain(left, right, model)
    # Same product order as the fast kernel (m * gH * gV) so the unnormalized values are bit-identical.
    unnorm = np.concatenate([lik[..., 0] * lik[..., 1] * lik[..., 2], nm[..., None]], axis=-1)
    # np.argmax returns the first maximum: lowest index wins exact ties.
    index = np.argmax(unnorm, axis=-1)
    return Reference(unnorm / unnorm.sum(axis=-1, keepdims=True), map_from_index(index, model.dmax))


def reference(left: np.ndarray, right: np.ndarray, model: ModelParams) -> Reference:
    """Validate a gray pair and run the fast reference on it."""
    validate_pair(left, right, model.dmax)
    return reference_fast(feature_sums(left), feature_sums(right), model)
