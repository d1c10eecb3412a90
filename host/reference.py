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

The census model (``ModelParams(name="census")``) multiplies in the census column (and the
no-match row's L_c(h_nm)), and, with the neighbour prior, pixel (y, x)'s prior from the
reference's OWN MAP of its left neighbour (y, x-1) and upper neighbour (y-1, x): row d gets
``p = 1.0; p *= f(|d - d_left|); p *= f(|d - d_above|)`` (a factor skipped for a neighbour called
no match or outside the output region), the no-match row ``prior_nomatch`` per matched
neighbour; the unnormalized value is (((m * gH) * gV) * census) * p. Raster order makes it
sequential: a parallel kernel forms every pixel's data products, a sequential pass over the
band applies the prior and takes the MAPs; bands go top to bottom, the last MAP row of a band
carried into the next (``above``).

``reference_quantized`` is the same inference on the W-bit quantized tables: each data column
a word q/2^W, and with the prior the left and the above neighbour's factor words as two more
factors (the neighbour-prior machine's feedback and loaded above columns, which its AND gates
multiply), the products exact in int64 (so a MAP is decided exactly, ties to the lowest index as
above). It is what the machine samples from: the distribution an ideal machine's counters
approach.

The census-lr model (issue 22) first runs the right pass (:func:`right_reference_map`: the census
model with the right image as reference over :func:`~host.likelihoods.right_columns`, raster order,
its own neighbour prior, no no-match row, lanes past the last output column 0), then the left pass
with the consistency column of those right MAPs
(:func:`~bayesmachine.likelihood.consistency_column`) as a fifth factor: float64
((((m * gH) * gV) * census) * lr) * p; on words the exact product of seven words, up to 2^70,
is compared exactly as a (high, low) pair of int64.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numba
import numpy as np

from bayesmachine.likelihood import QuantizedTables, likelihood_formula, lr_column
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion

from .features import FeatureSums, feature_sums, model_features
from .images import validate_pair
from .likelihoods import LikelihoodTables, ModelParams, likelihood_tables, likelihoods_plain, right_columns

__all__ = [
    "Reference",
    "reference",
    "reference_fast",
    "reference_bands",
    "reference_map",
    "reference_plain",
    "reference_quantized",
    "reference_quantized_map",
    "reference_prior_plain",
    "map_from_index",
    "warm_up",
    "right_reference_map",
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


_M1 = np.uint64(0x5555555555555555)
_M2 = np.uint64(0x3333333333333333)
_M4 = np.uint64(0x0F0F0F0F0F0F0F0F)
_H01 = np.uint64(0x0101010101010101)


@numba.njit(cache=True)
def _popcount(x):  # pragma: no cover
    """Bits set in a uint64 (SWAR; all constants uint64 so numba never goes through float)."""
    x = x - ((x >> np.uint64(1)) & _M1)
    x = (x & _M2) + ((x >> np.uint64(2)) & _M2)
    x = (x + (x >> np.uint64(4))) & _M4
    return np.int64((x * _H01) >> np.uint64(56))


@numba.njit(parallel=True, cache=True, fastmath=False, boundscheck=False)
def _data_kernel(ml, mr, ghl, ghr, gvl, gvr, cl, cr,  # pragma: no cover
                 tm, tgh, tgv, tnm, tc, h_nm, census, one, dmax, data):
    """data[y, i, d] = the product of the data columns of output pixel (y, i): float64 or int64 tables.

    ``one`` is the word of 1.0 (1.0, or 2^W for words): the no-match row's gH and gV words.
    """
    h, w4 = ml.shape
    wo = w4 - dmax
    for y in numba.prange(h):
        for i in range(wo):
            x = i + dmax
            a = ml[y, x]
            b = ghl[y, x]
            c = gvl[y, x]
            out = data[y, i]
            for d in range(dmax + 1):
                v = tm[abs(a - mr[y, x - d])] * tgh[abs(b - ghr[y, x - d])] * tgv[abs(c - gvr[y, x - d])]
                if census:
                    v = v * tc[_popcount(cl[y, x] ^ cr[y, x - d])]
                out[d] = v
            v = tnm[abs(c)] * one * one
            if census:
                v = v * tc[h_nm]
            out[dmax + 1] = v


@numba.njit(parallel=True, cache=True, fastmath=False, boundscheck=False)
def _right_data_kernel(ml, mr, ghl, ghr, gvl, gvr, cl, cr,  # pragma: no cover
                       tm, tgh, tgv, tnm, tc, h_nm, nm_row, one, first, last, dmax, data):
    """The census-lr right pass's data products: right map column xr = first + j, lane d reads left
    column xr + d (0 past ``last``); the no-match row the census model's (of the right pixel's gV)
    with ``nm_row``, else 0 (no no-match row)."""
    h = ml.shape[0]
    wr = data.shape[1]
    for y in numba.prange(h):
        for j in range(wr):
            xr = first + j
            a = mr[y, xr]
            b = ghr[y, xr]
            c = gvr[y, xr]
            out = data[y, j]
            for d in range(dmax + 1):
                xl = xr + d
                if xl > last:
                    out[d] = tm[0] * 0
                else:
                    v = tm[abs(a - ml[y, xl])] * tgh[abs(b - ghl[y, xl])] * tgv[abs(c - gvl[y, xl])]
                    out[d] = v * tc[_popcount(cr[y, xr] ^ cl[y, xl])]
            if nm_row:
                out[dmax + 1] = tnm[abs(c)] * one * one * tc[h_nm]
            else:
                out[dmax + 1] = tm[0] * 0


@numba.njit(cache=True, inline="always")
def _neighbours(idx, above, y, i, has_prior):  # pragma: no cover
    """The MAPs of pixel (y, i)'s left and above neighbours already taken (-1: none, or no prior)."""
    if not has_prior:
        return -1, -1
    hl = idx[y, i - 1] if i > 0 else -1
    ha = above[i] if y == 0 else idx[y - 1, i]
    return hl, ha


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def _prior_pass_float(data, tp, p_nm, has_prior, above, post, idx):  # pragma: no cover
    """Raster order: prior from the MAPs already taken (``above``: the MAP row above the band)."""
    n, wo, m = data.shape
    dmax = m - 2
    for y in range(n):
        for i in range(wo):
            hl, ha = _neighbours(idx, above, y, i, has_prior)
            src = data[y, i]
            out = post[y, i]
            best = -1.0
            arg = 0
            total = 0.0
            for d in range(dmax + 1):
                p = 1.0
                if hl >= 0:
                    p = p * tp[abs(d - hl)]
                if ha >= 0:
                    p = p * tp[abs(d - ha)]
                v = src[d] * p
                out[d] = v
                total += v
                if v > best:  # strict: the lowest index wins exact ties
                    best = v
                    arg = d
            p = 1.0
            if hl >= 0:
                p = p * p_nm
            if ha >= 0:
                p = p * p_nm
            v = src[dmax + 1] * p
            out[dmax + 1] = v
            total += v
            if v > best:
                arg = -1
            for d in range(m):
                out[d] = out[d] / total
            idx[y, i] = arg


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def _prior_pass_words(data, tp, q_nm, has_prior, word_bits, above, post, idx, extra):  # pragma: no cover
    """The same on words: the left and above factor words fL, fA as two factors of the exact int64
    product (the machine's two prior columns), data words (< 2^(4W)) * fL * fA < 2^(6W).

    ``extra`` (n, wo, m) words, unless empty: one more factor (census-lr's consistency column),
    the product then held as (high, low) = (v * e >> 32, v * e & (2^32 - 1)) and compared exactly."""
    n, wo, m = data.shape
    dmax = m - 2
    one = np.int64(1) << word_bits
    has_extra = extra.shape[0] > 0
    mask32 = np.int64(0xFFFFFFFF)
    for y in range(n):
        for i in range(wo):
            hl, ha = _neighbours(idx, above, y, i, has_prior)
            src = data[y, i]
            out = post[y, i]
            best = np.int64(-1)
            best_lo = np.int64(0)
            arg = 0
            total = 0.0
            for d in range(m):
                if d <= dmax:
                    fl = tp[abs(d - hl)] if hl >= 0 else one
                    fa = tp[abs(d - ha)] if ha >= 0 else one
                else:
                    fl = q_nm if hl >= 0 else one
                    fa = q_nm if ha >= 0 else one
                v = src[d] * fl * fa
                lo = np.int64(0)
                if has_extra:
                    e = extra[y, i, d]
                    low = (v & mask32) * e
                    v = (v >> 32) * e + (low >> 32)
                    lo = low & mask32
                    out[d] = float(v) * 4294967296.0 + float(lo)
                else:
                    out[d] = float(v)
                total += out[d]
                if v > best or (v == best and lo > best_lo):  # strict: the lowest index wins exact ties
                    best = v
                    best_lo = lo
                    arg = d if d <= dmax else -1
            for d in range(m):
                out[d] = out[d] / total
            idx[y, i] = arg


def _band_features(left: FeatureSums, right: FeatureSums, model: ModelParams, rows: slice | None):
    if model.census and (left.census is None or right.census is None):
        raise ParameterError("--model: the census model needs the census codes of both images "
                             "(features from host.features.model_features(image, model))")
    if rows is not None:
        left, right = left.band(rows), right.band(rows)
    return left, right


def _above(above: np.ndarray | None, rows: slice | None, model: ModelParams, wo: int) -> np.ndarray:
    """The MAP row above the band (-1 = none): required when a band with the prior starts below row 0."""
    if above is None:
        if model.has_prior and rows is not None and (rows.start or 0) > 0:
            raise ValueError("the neighbour prior needs the MAP of the row above the band: pass above=")
        return np.full(wo, -1, np.int16)
    above = np.asarray(above, dtype=np.int16)
    if above.shape != (wo,):
        raise ValueError(f"above must be the MAP row above the band, shape ({wo},), got {above.shape}")
    return above


def _run_model(left, right, model, tabs, prior, p_nm, words_bits, out, rows, above,
               right_pass=False, right_map=None, lr_values=None) -> Reference:
    """Census/quantized path: the data kernel (parallel) then the raster-order pass (sequential).

    ``right_pass``: census-lr's right pass over :func:`right_columns` (its MAPs; ``model`` its
    census-lr model). ``right_map`` (rows, Wr): the census-lr left pass's right MAPs of the band,
    turned into the consistency column with ``lr_values`` = (1, beta, gamma) in the tables' type.
    """
    region = OutputRegion.of_features(left.shape, model.dmax)
    left, right = _band_features(left, right, model, rows)
    xr = right_columns(region)
    width = xr.size if right_pass else region.shape[1]
    shape = (left.shape[0], width, model.hypotheses)
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64:
        raise ValueError(f"out must be float64 of shape {shape}, got {out.dtype} {out.shape}")
    top = _above(above, rows, model, shape[1])
    tm, tgh, tgv, tnm, tc = tabs
    census = model.census
    if census:
        cl, cr, h_nm = left.census, right.census, model.h_nm
    else:
        cl = cr = np.zeros((1, 1), np.uint64)
        tc, h_nm = tm[:1], 0
    data = out if words_bits is None else np.empty(shape, np.int64)
    one = tm[0] * 0 + (1.0 if words_bits is None else 1 << words_bits)  # 1.0 in the tables' type
    if right_pass:
        _right_data_kernel(left.m25, right.m25, left.gh20, right.gh20, left.gv20, right.gv20, cl, cr,
                           tm, tgh, tgv, tnm, tc, h_nm, model.lr_right_nomatch, one, int(xr[0]),
                           int(region.map_columns[-1]), model.dmax, data)
    else:
        _data_kernel(left.m25, right.m25, left.gh20, right.gh20, left.gv20, right.gv20, cl, cr,
                     tm, tgh, tgv, tnm, tc, h_nm, census, one, model.dmax, data)
    extra = np.zeros((0, 0, 0), np.int64)
    if model.lr and not right_pass:
        if right_map is None or np.shape(right_map) != (shape[0], xr.size):
            got = None if right_map is None else np.shape(right_map)
            raise ValueError(f"the census-lr left pass needs the right pass's MAPs of its rows, shape "
                             f"{(shape[0], xr.size)}, got {got}")
        rmap = np.asarray(right_map)
        if words_bits is None:
            # (((m * gH) * gV) * census) * lr, then the prior: the column is one more data factor.
            data *= lr_column(rmap, int(xr[0]), region.map_columns, model, 1.0, *lr_values[1:])
        else:
            extra = lr_column(rmap, int(xr[0]), region.map_columns, model, int(one),
                              *lr_values[1:]).astype(np.int64)
    idx = np.empty(shape[:2], dtype=np.int16)
    has_prior = model.has_prior
    if prior is None:
        prior = tm[:1]
    if words_bits is None:
        _prior_pass_float(data, prior, float(p_nm or 1.0), has_prior, top, out, idx)
    else:
        _prior_pass_words(data, prior, np.int64(p_nm or 0), has_prior, words_bits, top, out, idx, extra)
    return Reference(out, idx)


def reference_fast(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    tables: LikelihoodTables | None = None,
    out: np.ndarray | None = None,
    rows: slice | None = None,
    above: np.ndarray | None = None,
    right_map: np.ndarray | None = None,
) -> Reference:
    """The reference of output rows ``rows`` (default all) by a compiled loop (2 threads here).

    ``out``, if given, receives the posterior: float64 of shape (rows, Wo, Dmax+2). With the
    neighbour prior, ``above`` is the MAP row (Wo,) above ``rows`` (needed unless rows start at 0).
    The census-lr model needs ``right_map``, the right pass's MAPs of ``rows``
    (:func:`right_reference_map`'s rows).
    """
    tables = tables if tables is not None else likelihood_tables(model)
    if model.census:
        tabs = (tables.m, tables.gh, tables.gv, tables.nomatch, tables.census)
        prior, p_nm = tables.prior, tables.prior_nomatch
        lr_values = (1.0, tables.lr_beta, tables.lr_gamma) if model.lr else None
        return _run_model(left, right, model, tabs, prior, p_nm, None, out, rows, above,
                          right_map=right_map, lr_values=lr_values)
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
    right_map = right_reference_map(left, right, model, band_rows=band_rows) if model.lr else None
    buffer: np.ndarray | None = None
    above = None  # the neighbour prior's row above the band: the previous band's last MAP row
    for rows in region.bands(band_rows):
        n = rows.stop - rows.start
        if buffer is None or buffer.shape[0] < n:
            buffer = np.empty((n, region.shape[1], model.hypotheses))
        band = reference_fast(left, right, model, tables, out=buffer[:n], rows=rows, above=above,
                              right_map=None if right_map is None else right_map[rows])
        above = band.map[-1].copy()
        yield rows, band


def right_reference_map(
    left: FeatureSums, right: FeatureSums, model: ModelParams, word_bits: int | None = None,
    band_rows: int | None = None,
) -> np.ndarray:
    """The census-lr right pass's MAPs (Ho, Wr) int16 over :func:`~host.likelihoods.right_columns`:
    float64 (``word_bits`` None) or on ``word_bits``-bit words, raster order, band by band.

    -1 only with ``lr_right_nomatch`` (the census model's no-match row won); without it the MAP is
    the best lane, ties to the lowest d.
    """
    if not model.lr:
        raise ValueError(f"the {model.name} model has no right pass")
    rmodel = model.right_model
    tables = likelihood_tables(rmodel)
    region = OutputRegion.of_features(left.shape, model.dmax)
    wr = right_columns(region).size
    out = np.empty((region.shape[0], wr), dtype=np.int16)
    if word_bits is None:
        tabs = (tables.m, tables.gh, tables.gv, tables.nomatch, tables.census)
        prior, p_nm = tables.prior, tables.prior_nomatch
    else:
        _check_word_bits(rmodel, word_bits)
        q = QuantizedTables(tables, word_bits)
        tabs = tuple(np.asarray(t, np.int64) for t in (q.m, q.gh, q.gv, q.nomatch, q.census))
        prior, p_nm = np.asarray(q.prior, np.int64), q.prior_nomatch
    above = None
    for rows in region.bands(band_rows):
        band = _run_model(left, right, model, tabs, prior, p_nm, word_bits, None, rows, above,
                          right_pass=True)
        out[rows] = band.map
        above = band.map[-1].copy()
    return out


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
_warm_census = False
_warm_lr = False


def warm_up(model: ModelParams | None = None) -> None:
    """Load (or compile) the numba kernels once, so timings measure the computation only.

    The census model's kernels (float and words) too when ``model`` is a census model, and the
    right pass's and the (high, low) word product's for census-lr.
    """
    global _warm, _warm_census, _warm_lr
    img = np.zeros((8, 9), np.uint8)  # room for a 7x7 census and Dmax 1
    if not _warm:
        f = feature_sums(img)
        reference_fast(f, f, ModelParams(dmax=1))
        _warm = True
    if model is not None and model.census and not _warm_census:
        census = ModelParams(dmax=1, name="census")
        fc = model_features(img, census)
        reference_fast(fc, fc, census)
        reference_quantized(fc, fc, census, 10)
        _warm_census = True
    if model is not None and model.lr and not _warm_lr:
        lr = ModelParams(dmax=1, name="census-lr")
        fc = model_features(img, lr)
        reference_map(fc, fc, lr)  # the right pass's kernel and the left pass's
        reference_quantized_map(fc, fc, lr, 10)  # the words' pass with the (high, low) product
        _warm_lr = True


def reference_plain(left: FeatureSums, right: FeatureSums, model: ModelParams) -> Reference:
    """The reference by the plain vectorized float64 formula (memory-hungry: test oracle)."""
    lik, nm = likelihoods_plain(left, right, model)
    # Same product order as the fast kernel (m * gH * gV) so the unnormalized values are bit-identical.
    unnorm = np.concatenate([lik[..., 0] * lik[..., 1] * lik[..., 2], nm[..., None]], axis=-1)
    # np.argmax returns the first maximum: lowest index wins exact ties.
    index = np.argmax(unnorm, axis=-1)
    return Reference(unnorm / unnorm.sum(axis=-1, keepdims=True), map_from_index(index, model.dmax))


def reference_prior_plain(left: FeatureSums, right: FeatureSums, model: ModelParams) -> Reference:
    """The census model's reference pixel by pixel in plain Python over ``likelihoods_plain`` (test oracle).

    Slow and direct: the raster-order prior from the formula (no tables) and the MAPs so far.
    """
    lik, nm = likelihoods_plain(left, right, model)
    ho, wo, _, _ = lik.shape
    dmax, m = model.dmax, model.hypotheses
    l_nm = 1.0
    if model.census:
        l_nm = float(likelihood_formula(np.int64(model.h_nm), 1, model.census_p0, model.sigma_c))
    post = np.empty((ho, wo, m))
    disp = np.full((ho, wo), -1, np.int16)
    for y in range(ho):
        for x in range(wo):
            hats = []
            if model.has_prior:
                neighbours = (disp[y, x - 1] if x > 0 else -1, disp[y - 1, x] if y > 0 else -1)
                hats = [int(h) for h in neighbours if h >= 0]
            vals = []
            for d in range(dmax + 1):
                v = 1.0  # ((m * gH) * gV) * census, as the kernel multiplies
                for f in lik[y, x, d]:
                    v = v * float(f)
                p = 1.0
                for h in hats:
                    p = p * float(likelihood_formula(np.int64(abs(d - h)), 1, model.prior_eps, model.prior_s))
                vals.append(v * p)
            p = 1.0
            for _ in hats:
                p = p * model.prior_nm
            vals.append(float(nm[y, x]) * l_nm * p)
            best = max(range(m), key=lambda j: (vals[j], -j))  # the lowest index wins exact ties
            disp[y, x] = best if best <= dmax else -1
            post[y, x] = np.array(vals) / sum(vals)
    return Reference(post, disp)


def _check_word_bits(model: ModelParams, word_bits: int) -> None:
    # census-lr's consistency column is the one factor past the int64 product (a (high, low) pair).
    factors = min(model.columns, 4) + (2 if model.has_prior else 0)
    if not 1 <= word_bits <= 15 or factors * word_bits > 62:
        raise ParameterError(f"--word-bits: {word_bits}-bit words: the exact product of {factors} words "
                             f"must fit 62 bits (word bits at most {62 // factors})")


def reference_quantized(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    word_bits: int,
    qtables: QuantizedTables | None = None,
    out: np.ndarray | None = None,
    rows: slice | None = None,
    above: np.ndarray | None = None,
    right_map: np.ndarray | None = None,
) -> Reference:
    """The exact inference on the ``word_bits``-bit quantized tables (any model), rows ``rows``.

    Each hypothesis's value is the exact integer product of its words, with the prior the left and
    the above neighbour's factor words separately (the machine's feedback and above columns); the
    posterior is those products normalized (float64). census-lr: ``right_map`` as for
    :func:`reference_fast`, the right pass's MAPs on words (:func:`right_reference_map` with ``word_bits``).
    """
    _check_word_bits(model, word_bits)
    q = qtables if qtables is not None else QuantizedTables(likelihood_tables(model), word_bits)
    as64 = [None if t is None else np.asarray(t, np.int64) for t in (q.m, q.gh, q.gv, q.nomatch, q.census)]
    if as64[4] is None:
        as64[4] = as64[0][:1]
    prior = None if q.prior is None else np.asarray(q.prior, np.int64)
    lr_values = (q.one, q.lr_beta, q.lr_gamma) if model.lr else None
    return _run_model(left, right, model, tuple(as64), prior, q.prior_nomatch, word_bits, out, rows, above,
                      right_map=right_map, lr_values=lr_values)


def reference_quantized_map(
    left: FeatureSums, right: FeatureSums, model: ModelParams, word_bits: int, band_rows: int | None = None
) -> np.ndarray:
    """The quantized reference's MAP (Ho, Wo) int16 (-1 = no match), band by band."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    q = QuantizedTables(likelihood_tables(model), word_bits)
    right_map = right_reference_map(left, right, model, word_bits, band_rows) if model.lr else None
    out = np.empty(region.shape, dtype=np.int16)
    buffer: np.ndarray | None = None
    above = None
    for rows in region.bands(band_rows):
        n = rows.stop - rows.start
        if buffer is None or buffer.shape[0] < n:
            buffer = np.empty((n, region.shape[1], model.hypotheses))
        band = reference_quantized(left, right, model, word_bits, q, out=buffer[:n], rows=rows, above=above,
                                   right_map=None if right_map is None else right_map[rows])
        out[rows] = band.map
        above = band.map[-1].copy()
    return out


def reference(left: np.ndarray, right: np.ndarray, model: ModelParams) -> Reference:
    """Validate a gray pair and run the fast reference on it."""
    validate_pair(left, right, model.dmax, model.margin)
    fl, fr = model_features(left, model), model_features(right, model)
    right_map = right_reference_map(fl, fr, model) if model.lr else None  # census-lr: the right pass first
    return reference_fast(fl, fr, model, right_map=right_map)
