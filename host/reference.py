"""Exact inference: the reference the machine is measured against, pass by pass, column by column.

Posterior over Dmax+2 hypotheses per output pixel: hypothesis h gets the product of its columns'
factors (a column's factor is its float64 table at the lane's cost: :mod:`bayesmachine.columns`),
normalized to sum 1. MAP = argmax of the unnormalized products (the same order as the posterior's,
without a division that could round two close values into a tie); exact ties go to the lowest index,
so no match wins only when strictly more probable.

The kernels specialize over the closed set of column kinds: the FEATURES columns' product (a feature
difference or a census Hamming distance per column, in operator order: ((m * gH) * gV) * census) is
one parallel numba loop over the pass's pixels; a PASS column (census-lr's consistency, from the right
pass's MAPs) is one more factor; the neighbour prior's left (FEEDBACK) and above (ABOVE) columns make the
pass sequential in raster order, each pixel's factors from the MAPs already taken: ``p = 1.0;
p *= f(|d - d_left|); p *= f(|d - d_above|)`` (a factor skipped for a neighbour called no match or
outside the output region), the unnormalized value ``data * p``. Bands go top to bottom, the last MAP
row of a band carried into the next (``above``), so the float64 posterior volume (H x W x (Dmax+2) x 8
bytes) is never held whole (:func:`reference_bands`, :func:`reference_map`).

``reference_quantized`` is the same inference on the W-bit words: each factor a word q/2^W, the
product exact in int64 (a PASS column's factor past 62 bits as a (high, low) pair), so a MAP is decided
exactly. It is what the machine samples from: the distribution an ideal machine's counters approach.

A model's declared passes run first (:func:`pass_reference_map`, e.g. census-lr's right pass over
:func:`~host.likelihoods.right_columns`), their MAPs feeding the PASS columns of the passes after them.
``reference_plain`` and ``reference_prior_plain`` are the plain oracles of the kernels.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numba
import numpy as np
from numba.extending import overload

from bayesmachine.columns import AbovePrior, Column, LeftPrior, Source
from bayesmachine.models import ModelParams, Pass
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion

from .features import FeatureSums, model_features
from .images import validate_pair
from .likelihoods import PassGrid, likelihoods_plain, need_planes, pass_grid

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
    "pass_reference",
    "pass_reference_map",
    "right_reference_map",
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


def _cost(a, b):  # pragma: no cover
    """A FEATURES column's cost of two pixels' values, by their type: census codes (uint64) their
    Hamming distance, feature sums their |difference| (chosen when numba compiles, no branch)."""
    raise NotImplementedError("compiled by numba only")


@overload(_cost, inline="always")
def _cost_for(a, b):  # pragma: no cover
    if a == numba.types.uint64:
        return lambda a, b: _popcount(a ^ b)
    return lambda a, b: abs(a - b)


# A pass's FEATURES columns the data kernel takes (the closed set's: m, gH, gV and census).
KERNEL_SLOTS = 4


@numba.njit(parallel=True, cache=True, fastmath=False, boundscheck=False)
def _data_kernel(r0, o0, t0, r1, o1, t1, r2, o2, t2, r3, o3, t3, nm_entry,  # pragma: no cover
                 nm_plane, nm_table, has_nm, first, step, last, dmax, data, idx):
    """data[y, j, h]: the product of the FEATURES columns of pixel (y, first + j), in operator order
    ((c0 * c1) * c2) * c3; a column slot k is None past the pass's columns.

    Column k: reference plane ``rk``, match plane ``ok``, table ``tk`` at ``_cost`` of the two pixels'
    values, the match at column x + step * d; a lane past ``last`` gets 0. The no-match row: column 0's
    ``nm_table[|nm_plane|]`` (the pass's rule) times the other columns' entries ``nm_entry[1:]``, or 0
    without one (``has_nm``). With ``idx`` (not None: a float pass without a prior or a PASS column)
    also normalize and take the MAP (-1: no match; the lowest index wins exact ties).
    """
    h = data.shape[0]
    wo = data.shape[1]
    zero = t0[0] * 0
    for y in numba.prange(h):
        for j in range(wo):
            x = first + j
            out = data[y, j]
            lanes = dmax + 1  # lanes 0 .. lanes - 1 have a match pixel (x + step * d <= last)
            if step > 0 and x + dmax > last:
                lanes = last - x + 1
            a0 = r0[y, x]
            if r1 is not None:
                a1 = r1[y, x]
            if r2 is not None:
                a2 = r2[y, x]
            if r3 is not None:
                a3 = r3[y, x]
            for d in range(lanes):
                xm = x + step * d
                v = t0[_cost(a0, o0[y, xm])]
                if r1 is not None:
                    v = v * t1[_cost(a1, o1[y, xm])]
                if r2 is not None:
                    v = v * t2[_cost(a2, o2[y, xm])]
                if r3 is not None:
                    v = v * t3[_cost(a3, o3[y, xm])]
                out[d] = v
            for d in range(lanes, dmax + 1):
                out[d] = zero
            v = zero
            if has_nm:
                v = nm_table[abs(nm_plane[y, x])]
                for e in nm_entry[1:]:
                    v = v * e
            out[dmax + 1] = v
            if idx is not None:
                idx[y, j] = _finish(out)


@numba.njit(cache=True, inline="always")
def _finish(out):  # pragma: no cover
    """Normalize a pixel's unnormalized values in place; its MAP (-1: no match), ties to the lowest."""
    m = out.shape[0]
    best = -1.0
    arg = 0
    total = 0.0
    for d in range(m):
        v = out[d]
        total += v
        if v > best:  # strict: the lowest index wins exact ties
            best = v
            arg = d
    for d in range(m):
        out[d] = out[d] / total
    return arg if arg < m - 1 else -1


@numba.njit(cache=True, inline="always")
def _neighbours(idx, above, y, i, has_left, has_above):  # pragma: no cover
    """The MAPs of pixel (y, i)'s left and above neighbours already taken (-1: none, or no such column)."""
    hl = idx[y, i - 1] if has_left and i > 0 else -1
    ha = -1
    if has_above:
        ha = above[i] if y == 0 else idx[y - 1, i]
    return hl, ha


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def _prior_pass_float(data, tl, nl, has_left, ta, na, has_above, above, post, idx):  # pragma: no cover
    """Raster order: the left and above factors from the MAPs already taken (``above``: the MAP row
    above the band), then normalize and take the MAP (ties to the lowest index)."""
    n, wo, m = data.shape
    dmax = m - 2
    for y in range(n):
        for i in range(wo):
            hl, ha = _neighbours(idx, above, y, i, has_left, has_above)
            src = data[y, i]
            out = post[y, i]
            best = -1.0
            arg = 0
            total = 0.0
            for d in range(dmax + 1):
                p = 1.0
                if hl >= 0:
                    p = p * tl[abs(d - hl)]
                if ha >= 0:
                    p = p * ta[abs(d - ha)]
                v = src[d] * p
                out[d] = v
                total += v
                if v > best:  # strict: the lowest index wins exact ties
                    best = v
                    arg = d
            p = 1.0
            if hl >= 0:
                p = p * nl
            if ha >= 0:
                p = p * na
            v = src[dmax + 1] * p
            out[dmax + 1] = v
            total += v
            if v > best:
                arg = -1
            for d in range(m):
                out[d] = out[d] / total
            idx[y, i] = arg


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def _prior_pass_words(data, tl, nl, has_left, ta, na, has_above, above, post, idx, extra,  # pragma: no cover
                      one):
    """The same on words: the left and above factor words (``one``, the word of 1.0, for a neighbour
    without a MAP) as factors of the exact int64 product (the machine's two prior columns).

    ``extra`` (n, wo, m) words, unless empty: one more factor (a PASS column), the product then held as
    (high, low) = (v * e >> 32, v * e & (2^32 - 1)) and compared exactly."""
    n, wo, m = data.shape
    dmax = m - 2
    has_extra = extra.shape[0] > 0
    mask32 = np.int64(0xFFFFFFFF)
    for y in range(n):
        for i in range(wo):
            hl, ha = _neighbours(idx, above, y, i, has_left, has_above)
            src = data[y, i]
            out = post[y, i]
            best = np.int64(-1)
            best_lo = np.int64(0)
            arg = 0
            total = 0.0
            for d in range(m):
                v = src[d]
                if has_left:
                    v = v * ((tl[abs(d - hl)] if d <= dmax else nl) if hl >= 0 else one)
                if has_above:
                    v = v * ((ta[abs(d - ha)] if d <= dmax else na) if ha >= 0 else one)
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


def _slots(ref: FeatureSums, other: FeatureSums, cols: list[Column], word_bits: int | None) -> tuple:
    """The data kernel's column slots: (reference plane, match plane, table) of each FEATURES column in
    operator order (tables float64, or int64 words), None past them, then the no-match entries."""
    if not 1 <= len(cols) <= KERNEL_SLOTS:
        raise ValueError(f"the reference kernel takes 1 to {KERNEL_SLOTS} feature columns, got {len(cols)}")
    dtype = np.float64 if word_bits is None else np.int64
    tabs = [c.table(word_bits) for c in cols]
    slots: list = []
    for c, t in zip(cols, tabs, strict=True):
        slots += [getattr(ref, c.plane), getattr(other, c.plane), np.asarray(t.values, dtype)]
    slots += [None] * (3 * (KERNEL_SLOTS - len(cols)))
    return (*slots, np.array([c.nomatch_entry(t) for c, t in zip(cols, tabs, strict=True)], dtype))


def _prior_args(p: Pass, word_bits: int | None) -> tuple:
    """(table, no-match factor, present) of the pass's left column, then of its above column."""
    dtype = np.float64 if word_bits is None else np.int64
    out: list = []
    for kind in (LeftPrior, AbovePrior):
        c = next((c for c in p.columns if isinstance(c, kind)), None)
        if c is None:
            out += [np.ones(1, dtype), dtype(1), False]
        else:
            t = c.table(word_bits)
            out += [np.asarray(t.values, dtype), dtype(t.nomatch[0]), True]
    return tuple(out)


def _check_word_bits(p: Pass, word_bits: int) -> None:
    # Every column but a PASS column is a factor of the exact int64 product (a PASS column's factor
    # goes past it as a (high, low) pair).
    factors = sum(c.source is not Source.PASS for c in p.columns)
    if not 1 <= word_bits <= 15 or factors * word_bits > 62:
        raise ParameterError(f"word_bits: {word_bits}-bit words: the exact product of {factors} words "
                             f"must fit 62 bits (word bits at most {62 // factors})", "word_bits")


def _above(above: np.ndarray | None, rows: slice | None, p: Pass, wo: int) -> np.ndarray:
    """The MAP row above the band (-1 = none): required when a band with an ABOVE column starts below
    row 0."""
    if above is None:
        if any(c.source is Source.ABOVE for c in p.columns) and rows is not None and (rows.start or 0) > 0:
            raise ValueError("the neighbour prior needs the MAP of the row above the band: pass above=")
        return np.full(wo, -1, np.int16)
    above = np.asarray(above, dtype=np.int16)
    if above.shape != (wo,):
        raise ValueError(f"above must be the MAP row above the band, shape ({wo},), got {above.shape}")
    return above


def _fed_factors(p: Pass, word_bits: int | None, region: OutputRegion, grid: PassGrid,
                 fed: Mapping[str, np.ndarray], n: int) -> list[np.ndarray]:
    """Each PASS column's factors (n, W, M) from the MAPs ``fed[its source pass]`` of the band's rows."""
    out = []
    for c in p.columns:
        if c.source is not Source.PASS:
            continue
        source = p.model.pass_named(c.feeds_from)
        src_grid = pass_grid(source, region)
        got = fed.get(c.feeds_from)
        if got is None or np.shape(got) != (n, src_grid.width):
            shape = None if got is None else np.shape(got)
            raise ValueError(f"the {p.model.name} model's {c.name} column needs the {c.feeds_from} pass's "
                             f"MAPs of its rows, shape {(n, src_grid.width)}, got {shape}")
        out.append(c.loaded(c.table(word_bits), np.asarray(got), src_grid.first, grid.columns))
    return out


def pass_reference(p: Pass, left: FeatureSums, right: FeatureSums, word_bits: int | None = None,
                   out: np.ndarray | None = None, rows: slice | None = None, above: np.ndarray | None = None,
                   fed: Mapping[str, np.ndarray] | None = None) -> Reference:
    """The reference of pass ``p`` over map rows ``rows`` (default all): float64 (``word_bits`` None) or
    on ``word_bits``-bit words. ``out``: the posterior's buffer (float64, (rows, W, Dmax+2)); ``above``:
    the MAP row above the band (an ABOVE column, rows not starting at 0); ``fed``: the declared passes'
    MAPs of these rows by name (a PASS column)."""
    model = p.model
    need_planes(p, left, right)
    if word_bits is not None:
        _check_word_bits(p, word_bits)
    region = OutputRegion.of_features(left.shape, model.dmax)
    grid = pass_grid(p, region)
    if rows is not None:
        left, right = left.band(rows), right.band(rows)
    ref, other = (left, right) if p.step < 0 else (right, left)
    shape = (ref.shape[0], grid.width, model.hypotheses)
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64:
        raise ValueError(f"out must be float64 of shape {shape}, got {out.dtype} {out.shape}")
    cols = [c for c in p.columns if c.source is Source.FEATURES]
    floor = model.nomatch.table(word_bits).values.astype(np.float64 if word_bits is None else np.int64)
    factors = _fed_factors(p, word_bits, region, grid, fed or {}, shape[0])
    priors = _prior_args(p, word_bits)
    finish = word_bits is None and not factors and not (priors[2] or priors[5])
    data = out if word_bits is None else np.empty(shape, np.int64)
    idx = np.empty(shape[:2], dtype=np.int16)
    _data_kernel(*_slots(ref, other, cols, word_bits), getattr(ref, model.nomatch.plane), floor, p.nomatch,
                 grid.first, p.step, grid.last, model.dmax, data, idx if finish else None)
    if finish:
        return Reference(out, idx)
    top = _above(above, rows, p, grid.width)
    if word_bits is None:
        for f in factors:  # ((((m * gH) * gV) * census) * lr), then the prior
            data *= f
        _prior_pass_float(data, *priors, top, out, idx)
    else:
        extra = factors[0].astype(np.int64) if factors else np.zeros((0, 0, 0), np.int64)
        if len(factors) > 1:
            raise ValueError("the exact word product takes one PASS column")
        _prior_pass_words(data, *priors, top, out, idx, extra, np.int64(1 << word_bits))
    return Reference(out, idx)


def pass_reference_map(p: Pass, left: FeatureSums, right: FeatureSums, word_bits: int | None = None,
                       band_rows: int | None = None,
                       fed: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """The MAPs (Ho, W) int16 of pass ``p`` over its grid, band by band (-1: its no-match row won)."""
    region = OutputRegion.of_features(left.shape, p.model.dmax)
    out = np.empty((region.shape[0], pass_grid(p, region).width), dtype=np.int16)
    above = None
    for rows in region.bands(band_rows):
        band = pass_reference(p, left, right, word_bits, rows=rows, above=above,
                              fed={k: v[rows] for k, v in (fed or {}).items()})
        out[rows] = band.map
        above = band.map[-1].copy()
    return out


def declared_maps(model: ModelParams, left: FeatureSums, right: FeatureSums, word_bits: int | None = None,
                  band_rows: int | None = None) -> dict[str, np.ndarray]:
    """Every declared pass's MAPs (whole frame), in order, each fed the ones before it."""
    fed: dict[str, np.ndarray] = {}
    for p in model.passes[:-1]:
        fed[p.name] = pass_reference_map(p, left, right, word_bits, band_rows, fed)
    return fed


def right_reference_map(left: FeatureSums, right: FeatureSums, model: ModelParams,
                        word_bits: int | None = None, band_rows: int | None = None) -> np.ndarray:
    """census-lr's right pass's MAPs (Ho, Wr) over :func:`~host.likelihoods.right_columns`: float64
    (``word_bits`` None) or on words. -1 only with ``lr_right_nomatch`` (its no-match row won)."""
    return pass_reference_map(model.pass_named("right"), left, right, word_bits, band_rows)


def _fed(model: ModelParams, right_map: np.ndarray | None) -> dict[str, np.ndarray]:
    return {} if right_map is None else {"right": right_map}


def reference_fast(left: FeatureSums, right: FeatureSums, model: ModelParams, out: np.ndarray | None = None,
                   rows: slice | None = None, above: np.ndarray | None = None,
                   right_map: np.ndarray | None = None) -> Reference:
    """The float64 reference of output rows ``rows`` (default all) by the compiled kernels.

    ``out``, if given, receives the posterior: float64 of shape (rows, Wo, Dmax+2). With the
    neighbour prior, ``above`` is the MAP row (Wo,) above ``rows`` (needed unless rows start at 0).
    census-lr needs ``right_map``, the right pass's MAPs of ``rows`` (:func:`right_reference_map`'s).
    """
    return pass_reference(model.passes[-1], left, right, None, out, rows, above, _fed(model, right_map))


def reference_quantized(left: FeatureSums, right: FeatureSums, model: ModelParams, word_bits: int,
                        out: np.ndarray | None = None, rows: slice | None = None,
                        above: np.ndarray | None = None, right_map: np.ndarray | None = None) -> Reference:
    """The exact inference on the ``word_bits``-bit words (any model), rows ``rows``: each hypothesis's
    value the exact integer product of its words, normalized (float64). census-lr: ``right_map`` the right
    pass's MAPs on words (:func:`right_reference_map` with ``word_bits``)."""
    return pass_reference(model.passes[-1], left, right, word_bits, out, rows, above, _fed(model, right_map))


def _bands(left: FeatureSums, right: FeatureSums, model: ModelParams, word_bits: int | None,
           band_rows: int | None) -> Iterator[tuple[slice, Reference]]:
    """The output pass band by band (declared passes first), one posterior buffer reused."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    fed = declared_maps(model, left, right, word_bits, band_rows)
    buffer: np.ndarray | None = None
    above = None  # an ABOVE column's row above the band: the previous band's last MAP row
    for rows in region.bands(band_rows):
        n = rows.stop - rows.start
        if buffer is None or buffer.shape[0] < n:
            buffer = np.empty((n, region.shape[1], model.hypotheses))
        band = pass_reference(model.passes[-1], left, right, word_bits, buffer[:n], rows, above,
                              {k: v[rows] for k, v in fed.items()})
        above = band.map[-1].copy()
        yield rows, band


def reference_bands(left: FeatureSums, right: FeatureSums, model: ModelParams,
                    band_rows: int | None = None) -> Iterator[tuple[slice, Reference]]:
    """The float64 reference band by band: (output rows, their Reference), top to bottom.

    One posterior buffer is reused: a band's posterior is overwritten by the next band
    (copy it to keep it). Memory: one band, about ``BAND_PIXELS`` x (Dmax+2) x 8 bytes.
    """
    return _bands(left, right, model, None, band_rows)


def reference_map(left: FeatureSums, right: FeatureSums, model: ModelParams,
                  band_rows: int | None = None) -> np.ndarray:
    """The MAP (Ho, Wo) int16 (-1 = no match) of every output pixel, band by band."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    out = np.empty(region.shape, dtype=np.int16)
    for rows, band in _bands(left, right, model, None, band_rows):
        out[rows] = band.map
    return out


def reference_quantized_map(left: FeatureSums, right: FeatureSums, model: ModelParams, word_bits: int,
                            band_rows: int | None = None) -> np.ndarray:
    """The quantized reference's MAP (Ho, Wo) int16 (-1 = no match), band by band."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    out = np.empty(region.shape, dtype=np.int16)
    for rows, band in _bands(left, right, model, word_bits, band_rows):
        out[rows] = band.map
    return out


_warm: set[str] = set()


def warm_up(model: ModelParams | None = None) -> None:
    """Load (or compile) the numba kernels ``model``'s passes use (default: the default model's), once,
    so that timings measure the computation only."""
    model = model if model is not None else ModelParams()
    if model.name in _warm:
        return
    small = model.replace(dmax=1)
    img = np.zeros((8, 9), np.uint8)  # room for a 7x7 census and Dmax 1
    f = model_features(img, small)
    reference_map(f, f, small)
    reference_quantized_map(f, f, small, 10)
    _warm.add(model.name)


def reference(left: np.ndarray, right: np.ndarray, model: ModelParams) -> Reference:
    """Validate a gray pair and run the fast reference on it (the declared passes first)."""
    validate_pair(left, right, model.dmax, model.margin)
    fl, fr = model_features(left, model), model_features(right, model)
    fed = declared_maps(model, fl, fr)
    return pass_reference(model.passes[-1], fl, fr, fed=fed)


def reference_plain(left: FeatureSums, right: FeatureSums, model: ModelParams) -> Reference:
    """The reference by the plain vectorized float64 formula (memory-hungry: test oracle; a model whose
    columns all come from the features)."""
    lik, nm = likelihoods_plain(left, right, model)
    cols = [c for c in model.columns if c.source is Source.FEATURES]
    if len(cols) != len(model.columns):
        raise ValueError(f"reference_plain: the {model.name} model has columns not from the features")
    unnorm = np.empty((*lik.shape[:2], model.hypotheses))
    unnorm[..., :-1] = lik[..., 0]
    unnorm[..., -1] = nm
    for k, c in enumerate(cols[1:], start=1):  # the kernel's order: ((m * gH) * gV) * census
        unnorm[..., :-1] *= lik[..., k]
        unnorm[..., -1] *= c.nomatch_values()[0] if c.nomatch_values() else 1.0
    # np.argmax returns the first maximum: lowest index wins exact ties.
    index = np.argmax(unnorm, axis=-1)
    return Reference(unnorm / unnorm.sum(axis=-1, keepdims=True), map_from_index(index, model.dmax))


def reference_prior_plain(left: FeatureSums, right: FeatureSums, model: ModelParams) -> Reference:
    """A model's reference pixel by pixel in plain Python over ``likelihoods_plain`` (test oracle; no PASS
    column). Slow and direct: the raster-order prior from each prior column's formula and the MAPs so far."""
    lik, nm = likelihoods_plain(left, right, model)
    ho, wo, _, _ = lik.shape
    dmax, m = model.dmax, model.hypotheses
    l_nm = 1.0  # the FEATURES columns' no-match entries but the rule's
    for c in model.columns:
        if c.source is Source.FEATURES and c.nomatch_values():
            l_nm = l_nm * c.nomatch_values()[0]
    left_prior = model.column(LeftPrior)
    above_prior = model.column(AbovePrior)
    post = np.empty((ho, wo, m))
    disp = np.full((ho, wo), -1, np.int16)
    for y in range(ho):
        for x in range(wo):
            hats = []  # (column, neighbour MAP) of the matched neighbours, left then above
            if left_prior is not None and x > 0 and disp[y, x - 1] >= 0:
                hats.append((left_prior, int(disp[y, x - 1])))
            if above_prior is not None and y > 0 and disp[y - 1, x] >= 0:
                hats.append((above_prior, int(disp[y - 1, x])))
            vals = []
            for d in range(dmax + 1):
                v = 1.0  # ((m * gH) * gV) * census, as the kernel multiplies
                for f in lik[y, x, d]:
                    v = v * float(f)
                p = 1.0
                for c, h in hats:
                    p = p * float(c.likelihood(np.int64(abs(d - h))))
                vals.append(v * p)
            p = 1.0
            for c, _ in hats:
                p = p * c.nomatch_factor
            vals.append(float(nm[y, x]) * l_nm * p)
            best = max(range(m), key=lambda j: (vals[j], -j))  # the lowest index wins exact ties
            disp[y, x] = best if best <= dmax else -1
            post[y, x] = np.array(vals) / sum(vals)
    return Reference(post, disp)
