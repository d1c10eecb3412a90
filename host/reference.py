"""Exact inference: the reference the machine is measured against, pass by pass, column by column.

Posterior over Dmax+2 hypotheses per output pixel: hypothesis h gets the product of its columns'
factors (a column's factor is its float64 table at the lane's cost: :mod:`bayesmachine.columns`),
normalized to sum 1. MAP = argmax of the unnormalized products (the same order as the posterior's,
without a division that could round two close values into a tie); exact ties go to the lowest index,
so no match wins only when strictly more probable.

The kernels specialize over the closed set of column sources, not over the kinds: a pass's FEATURES
columns, any number of them, are stacked (their planes (rows, W, K) int64 and their tables (K, longest),
each cost a Hamming distance of census codes or a |difference| of sums, as its kind says) and their
product, in operator order (((m * gH) * gV) * census) * ..., is one parallel numba loop over the
pass's pixels; each PASS column (census-lr's consistency, from the right pass's MAPs) is one more factor,
its own words (:meth:`~bayesmachine.columns.Column.words`); a FEEDBACK column (the left neighbour's) and
an ABOVE column (the above neighbour's) make the pass sequential in raster order, each pixel's factors
from the MAPs already taken: ``p = 1.0; p *= f(|d - d_left|); p *= f(|d - d_above|)`` (a factor skipped
for a neighbour called no match or outside the output region), the unnormalized value ``data * p``.
Bands go top to bottom, the last MAP row of a band carried into the next (``above``), so the float64
posterior volume (H x W x (Dmax+2) x 8 bytes) is never held whole (:func:`reference_bands`,
:func:`reference_map`).

``reference_quantized`` is the same inference on the W-bit words: each factor a word q/2^W, the product
exact whatever its width (:mod:`.products`: one int64 while it fits 62 bits, else 32-bit limbs), so a
MAP is decided exactly. It is what the machine samples from: the distribution an ideal machine's
counters approach.

A model's declared passes run first (:func:`declared_maps`, e.g. census-lr's right pass over its grid,
``host.likelihoods.pass_grid``), their MAPs feeding the PASS columns of the passes after them by pass
name. ``reference_plain`` and ``reference_prior_plain`` are the plain oracles of the kernels.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, MutableMapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numba import literal_unroll
from numba.extending import overload

from bayesmachine.checks import as_int
from bayesmachine.columns import AbovePrior, Column, LeftPrior, Source
from bayesmachine.models import ModelParams, Pass
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion

from .features import Planes, model_planes
from .images import validate_pair
from .likelihoods import likelihoods_plain, pass_context, pass_grid
from .products import TOP_BITS, exact_float, exact_greater, exact_store, exact_times, limbs_for

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
    "declared_maps",
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


@numba.njit(cache=True, inline="always")
def _lanes(x, step, last, dmax):  # pragma: no cover
    """Lanes 0 .. lanes - 1 of reference column x have a match pixel (x + step * d <= last)."""
    if step > 0 and x + dmax > last:
        return last - x + 1
    return dmax + 1


@numba.njit(nogil=True, cache=True, fastmath=False, boundscheck=False)
def _data_kernel(cols, one, nm_entry, nm_plane, nm_table, has_nm, first, step, last, dmax,  # pragma: no cover
                 data, idx):
    """data[y, j, h]: the product of the FEATURES columns ``cols`` of pixel (y, first + j), in operator
    order ((c0 * c1) * c2) * ... (``one``: 1.0, float64 factors; or 1, words, their product fitting one
    int64, stored exactly in data's form, :mod:`.products`): column k = (reference plane, match plane,
    table), its factor the table at ``_cost`` of the reference pixel's value and the match's, at column
    x + step * d; a lane past ``last`` gets 0. The no-match row: ``nm_table[|nm_plane|]`` (the pass's
    rule, in column 0) times the other columns' entries ``nm_entry[1:]``, or 0 without one (``has_nm``).
    With ``idx`` (not None: float64) also normalize and take the MAP (-1: no match; the lowest index wins
    exact ties)."""
    n, wo = data.shape[0], data.shape[1]
    for y in range(n):
        for j in range(wo):
            x = first + j
            out = data[y, j]
            lanes = _lanes(x, step, last, dmax)
            for d in range(lanes):
                xm = x + step * d
                v = one  # one * c0 is c0: the product ((c0 * c1) * c2) * ...
                for col in literal_unroll(cols):
                    ref, match, table = col
                    v = v * table[_cost(ref[y, x], match[y, xm])]
                exact_store(out, d, v)
            for d in range(lanes, dmax + 1):
                exact_store(out, d, 0)
            v = nm_table[abs(nm_plane[y, x])] if has_nm else one * 0
            for k in range(1, nm_entry.shape[0]):
                v = v * nm_entry[k]
            exact_store(out, dmax + 1, v)
            if idx is not None:
                idx[y, j] = _finish(out)


def _by_rows(cols: tuple, one: float | int, rule: tuple, data: np.ndarray, idx: np.ndarray | None) -> None:
    """:func:`_data_kernel` (which frees the GIL) over the band's rows, in as many parts as numba has
    threads, each on a thread of its own: a tuple cannot enter a numba parallel loop."""
    n = data.shape[0]
    parts = max(1, min(numba.get_num_threads(), n))
    cuts = [n * i // parts for i in range(parts + 1)]

    def part(i: int) -> None:
        rows = slice(cuts[i], cuts[i + 1])
        _data_kernel(tuple((ref[rows], match[rows], table) for ref, match, table in cols), one, rule[0],
                     rule[1][rows], *rule[2:], data[rows], None if idx is None else idx[rows])

    if parts == 1:
        part(0)
        return
    with ThreadPoolExecutor(parts) as pool:
        list(pool.map(part, range(parts)))


@numba.njit(parallel=True, cache=True, boundscheck=False)
def _times_words(data, factor, first=False):  # pragma: no cover
    """data *= ``factor`` (n, W, M) words, exactly (``first``: data = ``factor``)."""
    n, wo, m = data.shape[0], data.shape[1], data.shape[2]
    for y in numba.prange(n):
        for j in range(wo):
            v = data[y, j]
            for h in range(m):
                if first:
                    exact_store(v, h, np.int64(factor[y, j, h]))
                else:
                    exact_times(v, h, factor[y, j, h])


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


@numba.njit(parallel=True, cache=True, boundscheck=False)
def _finish_float(data, idx):  # pragma: no cover
    """Every pixel's :func:`_finish` (a pass without neighbour columns)."""
    for y in numba.prange(data.shape[0]):
        for j in range(data.shape[1]):
            idx[y, j] = _finish(data[y, j])


@numba.njit(cache=True, inline="always")
def _finish_exact(values, post):  # pragma: no cover
    """A pixel's exact values to ``post`` (normalized float64); its MAP (-1: no match), the exact
    comparison, ties to the lowest index."""
    m = values.shape[0]
    total = 0.0
    arg = 0
    for d in range(m):
        f = exact_float(values, d)
        post[d] = f
        total += f
        if d > 0 and exact_greater(values, d, arg):  # strict: the lowest index wins exact ties
            arg = d
    for d in range(m):
        post[d] = post[d] / total
    return arg if arg < m - 1 else -1


@numba.njit(parallel=True, cache=True, boundscheck=False)
def _finish_words(data, post, idx):  # pragma: no cover
    """Every pixel's :func:`_finish_exact` (a pass without neighbour columns)."""
    for y in numba.prange(data.shape[0]):
        for j in range(data.shape[1]):
            idx[y, j] = _finish_exact(data[y, j], post[y, j])


@numba.njit(cache=True, inline="always")
def _neighbours(idx, above, y, i, has_left, has_above):  # pragma: no cover
    """The MAPs of pixel (y, i)'s left and above neighbours already taken (-1: none, or no such column)."""
    hl = idx[y, i - 1] if has_left and i > 0 else -1
    ha = -1
    if has_above:
        ha = above[i] if y == 0 else idx[y - 1, i]
    return hl, ha


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def _raster_float(data, tl, nl, has_left, ta, na, has_above, above, post, idx):  # pragma: no cover
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
def _raster_words(data, tl, nl, has_left, ta, na, has_above, above, post, idx, one):  # pragma: no cover
    """The same on words: the left and above factor words (``one``, the word of 1.0, for a neighbour
    without a MAP) as factors of the exact product (the machine's two prior columns); ``data`` is
    overwritten."""
    n, wo, m = data.shape[0], data.shape[1], data.shape[2]
    dmax = m - 2
    for y in range(n):
        for i in range(wo):
            hl, ha = _neighbours(idx, above, y, i, has_left, has_above)
            values = data[y, i]
            for d in range(m):
                if has_left:
                    exact_times(values, d, ((tl[abs(d - hl)] if d <= dmax else nl) if hl >= 0 else one))
                if has_above:
                    exact_times(values, d, ((ta[abs(d - ha)] if d <= dmax else na) if ha >= 0 else one))
            idx[y, i] = _finish_exact(values, post[y, i])


def _kernel_plane(plane: np.ndarray, hamming: bool) -> np.ndarray:
    """A plane as the data kernels take it: census codes uint64 (their cost a Hamming distance), sums a
    signed integer type (their cost a |difference|)."""
    if hamming:
        return plane.astype(np.uint64, copy=False)
    return plane if plane.dtype.kind == "i" else plane.astype(np.int64)


def _columns(cols: list[Column], ref: Mapping[str, np.ndarray], other: Mapping[str, np.ndarray],
             word_bits: int | None) -> tuple[tuple, np.ndarray]:
    """The data kernels' FEATURES columns in operator order, each (reference plane, match plane, table)
    (float64, or int64 words), and their no-match entries."""
    dtype = np.float64 if word_bits is None else np.int64
    tabs = [c.table(word_bits) for c in cols]
    out = tuple((_kernel_plane(ref[c.plane], c.hamming), _kernel_plane(other[c.plane], c.hamming),
                 np.asarray(t.values, dtype)) for c, t in zip(cols, tabs, strict=True))
    return out, np.array([c.nomatch_entry(t) for c, t in zip(cols, tabs, strict=True)], dtype)


def _neighbour_args(p: Pass, word_bits: int | None) -> tuple:
    """(table, no-match factor, present) of the pass's left neighbour's column (its FEEDBACK column), then
    of its above neighbour's (its ABOVE column): a neighbour's factor is its table at |d - its MAP|."""
    dtype = np.float64 if word_bits is None else np.int64
    out: list = []
    for source in (Source.FEEDBACK, Source.ABOVE):
        c = next((c for c in p.columns if c.source is source), None)
        if c is None:
            out += [np.ones(1, dtype), dtype(1), False]
        else:
            t = c.table(word_bits)
            out += [np.asarray(t.values, dtype), dtype(t.nomatch[0]), True]
    return tuple(out)


def _check_word_bits(word_bits: int) -> None:
    if not 1 <= as_int("word_bits", word_bits) <= 15:
        raise ParameterError(f"word_bits: words of 1 to 15 bits, got {word_bits!r}", "word_bits")


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


def pass_reference(p: Pass, left: Planes, right: Planes, word_bits: int | None = None, *,
                   out: np.ndarray | None = None, rows: slice | None = None, above: np.ndarray | None = None,
                   results: Mapping[str, np.ndarray] | None = None,
                   carry: MutableMapping[str, Any] | None = None) -> Reference:
    """The reference of pass ``p`` over map rows ``rows`` (default all): float64 (``word_bits`` None) or
    on ``word_bits``-bit words, exact (module text). ``out``: the posterior's buffer (float64, (rows, W,
    Dmax+2)); ``above``: the MAP row above the band (an ABOVE column, rows not starting at 0);
    ``results``: the other passes' MAPs of these rows by name (a PASS column); ``carry``: what its columns
    carry from band to band (one dict per pass and frame, the bands in order: a semi-global column's)."""
    model = p.model
    if word_bits is not None:
        _check_word_bits(word_bits)
    ctx = pass_context(p, left, right, word_bits, rows=rows, results=results, carry=carry)
    grid = pass_grid(p, OutputRegion.of_features(left.shape, model.dmax))
    shape = (ctx.rows, grid.width, model.hypotheses)
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64:
        raise ValueError(f"out must be float64 of shape {shape}, got {out.dtype} {out.shape}")
    features = [c for c in p.columns if c.source is Source.FEATURES]
    # The data kernel takes the FEATURES columns whose words' product fits one int64 (on words: four at
    # least, every one of the package's models); the others are factors as the PASS columns are. In
    # float64 a fused column is its members' factors; on words its own words (they hold the rule), and so
    # are a semi-global column's in both (its factor is its own).
    if word_bits is None:
        kernel = [f for c in features if not _own_factor(c) for f in c.factors()]
    else:
        kernel = [c for c in features if not c.holds_rule][: TOP_BITS // word_bits]
    factors = [c.words(ctx).reshape(shape) for c in p.columns if c.source is Source.PASS or (
        c.source is Source.FEATURES and c not in kernel and (word_bits is not None or _own_factor(c)))]
    cols, entries = _columns(kernel, ctx.reference, ctx.match, word_bits)
    floor = model.nomatch.table(word_bits).values.astype(np.float64 if word_bits is None else np.int64)
    rule = (entries, ctx.reference[model.nomatch.plane], floor, p.nomatch, grid.first, p.step, grid.last,
            model.dmax)
    neighbours = _neighbour_args(p, word_bits)
    top = _above(above, rows, p, shape[1])
    idx = np.empty(shape[:2], dtype=np.int16)
    if word_bits is None:
        _float_reference(cols, rule, factors, neighbours, top, out, idx)
    else:
        limbs = limbs_for(len(p.columns), word_bits)
        data = np.empty(shape if limbs == 1 else (*shape, limbs), np.int64)
        if cols:
            _by_rows(cols, np.int64(1), rule, data, None)
        else:  # a fused column: its words are the first factor
            _times_words(data, factors.pop(0), True)
        for f in factors:
            _times_words(data, f)
        if neighbours[2] or neighbours[5]:
            _raster_words(data, *neighbours, top, out, idx, np.int64(1 << word_bits))
        else:
            _finish_words(data, out, idx)
    return Reference(out, idx)


def _own_factor(c: Column) -> bool:
    """Whether a FEATURES column's float64 factor is its own words (it holds the rule, and has no members
    the data kernel multiplies: a semi-global column)."""
    return c.holds_rule and c.factors() == (c,)


def _float_reference(cols: tuple, rule: tuple, factors: list[np.ndarray], neighbours: tuple, top: np.ndarray,
                     out: np.ndarray, idx: np.ndarray) -> None:
    """The float64 reference's kernels: the FEATURES columns' product, then the other factors in operator
    order ((((m * gH) * gV) * census) * lr), then the neighbours in raster order."""
    own = not cols  # a column whose factor is its own holds the rule: its factors come first
    if own:
        out[...] = factors.pop(0)
    plain = not factors and not (neighbours[2] or neighbours[5])
    if not own:
        _by_rows(cols, 1.0, rule, out, idx if plain else None)
        if plain:
            return
    for f in factors:
        out *= f
    if neighbours[2] or neighbours[5]:
        _raster_float(out, *neighbours, top, out, idx)
    else:
        _finish_float(out, idx)


def pass_reference_map(p: Pass, left: Planes, right: Planes, word_bits: int | None = None, *,
                       band_rows: int | None = None,
                       results: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """The MAPs (Ho, W) int16 of pass ``p`` over its grid, band by band (-1: its no-match row won);
    ``results``: the MAPs of the passes it reads (whole frame), by name."""
    region = OutputRegion.of_features(left.shape, p.model.dmax)
    out = np.empty((region.shape[0], pass_grid(p, region).width), dtype=np.int16)
    above = None
    carry: dict[str, Any] = {}
    for rows in region.bands(band_rows):
        band = pass_reference(p, left, right, word_bits, rows=rows, above=above,
                              results={k: v[rows] for k, v in (results or {}).items()}, carry=carry)
        out[rows] = band.map
        above = band.map[-1].copy()
    return out


def declared_maps(model: ModelParams, left: Planes, right: Planes, word_bits: int | None = None,
                  band_rows: int | None = None) -> dict[str, np.ndarray]:
    """Every declared pass's reference MAPs (whole frame, over its grid), by pass name, in order, each fed
    the ones before it: what the model's own pass reads (``results``)."""
    results: dict[str, np.ndarray] = {}
    for p in model.passes[:-1]:
        results[p.name] = pass_reference_map(p, left, right, word_bits, band_rows=band_rows, results=results)
    return results


def reference_fast(left: Planes, right: Planes, model: ModelParams, *, out: np.ndarray | None = None,
                   rows: slice | None = None, above: np.ndarray | None = None,
                   results: Mapping[str, np.ndarray] | None = None) -> Reference:
    """The float64 reference of output rows ``rows`` (default all) by the compiled kernels.

    ``out``, if given, receives the posterior: float64 of shape (rows, Wo, Dmax+2). With the
    neighbour prior, ``above`` is the MAP row (Wo,) above ``rows`` (needed unless rows start at 0).
    A model with declared passes needs their MAPs of ``rows`` by name, ``results`` (:func:`declared_maps`).
    """
    return pass_reference(model.passes[-1], left, right, None, out=out, rows=rows, above=above,
                          results=results)


def reference_quantized(left: Planes, right: Planes, model: ModelParams, word_bits: int, *,
                        out: np.ndarray | None = None, rows: slice | None = None,
                        above: np.ndarray | None = None,
                        results: Mapping[str, np.ndarray] | None = None) -> Reference:
    """The exact inference on the ``word_bits``-bit words (any model), rows ``rows``: each hypothesis's
    value the exact integer product of its words, normalized (float64). ``results``: the declared passes'
    MAPs on words (:func:`declared_maps` with ``word_bits``)."""
    return pass_reference(model.passes[-1], left, right, word_bits, out=out, rows=rows, above=above,
                          results=results)


def _bands(left: Planes, right: Planes, model: ModelParams, word_bits: int | None,
           band_rows: int | None) -> Iterator[tuple[slice, Reference]]:
    """The output pass band by band (declared passes first), one posterior buffer reused."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    results = declared_maps(model, left, right, word_bits, band_rows)
    buffer: np.ndarray | None = None
    above = None  # an ABOVE column's row above the band: the previous band's last MAP row
    carry: dict[str, Any] = {}
    for rows in region.bands(band_rows):
        n = rows.stop - rows.start
        if buffer is None or buffer.shape[0] < n:
            buffer = np.empty((n, region.shape[1], model.hypotheses))
        band = pass_reference(model.passes[-1], left, right, word_bits, out=buffer[:n], rows=rows,
                              above=above, results={k: v[rows] for k, v in results.items()}, carry=carry)
        above = band.map[-1].copy()
        yield rows, band


def reference_bands(left: Planes, right: Planes, model: ModelParams,
                    band_rows: int | None = None) -> Iterator[tuple[slice, Reference]]:
    """The float64 reference band by band: (output rows, their Reference), top to bottom.

    One posterior buffer is reused: a band's posterior is overwritten by the next band
    (copy it to keep it). Memory: one band, about ``BAND_PIXELS`` x (Dmax+2) x 8 bytes.
    """
    return _bands(left, right, model, None, band_rows)


def reference_map(left: Planes, right: Planes, model: ModelParams,
                  band_rows: int | None = None) -> np.ndarray:
    """The MAP (Ho, Wo) int16 (-1 = no match) of every output pixel, band by band."""
    region = OutputRegion.of_features(left.shape, model.dmax)
    out = np.empty(region.shape, dtype=np.int16)
    for rows, band in _bands(left, right, model, None, band_rows):
        out[rows] = band.map
    return out


def reference_quantized_map(left: Planes, right: Planes, model: ModelParams, word_bits: int,
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
    k = small.margin
    img = np.zeros((2 * k + 2, 2 * k + 3), np.uint8)  # room for the largest window and Dmax 1
    f = model_planes(img, small)
    reference_map(f, f, small)
    reference_quantized_map(f, f, small, 10)
    _warm.add(model.name)


def reference(left: np.ndarray, right: np.ndarray, model: ModelParams) -> Reference:
    """Validate a gray pair and run the fast reference on it (the declared passes first)."""
    validate_pair(left, right, model.dmax, model.margin)
    fl, fr = model_planes(left, model), model_planes(right, model)
    return pass_reference(model.passes[-1], fl, fr, results=declared_maps(model, fl, fr))


def reference_plain(left: Planes, right: Planes, model: ModelParams) -> Reference:
    """The reference by the plain vectorized float64 formula (memory-hungry: test oracle; a model whose
    columns all come from the planes)."""
    lik, nm = likelihoods_plain(left, right, model)
    if any(c.source is not Source.FEATURES for c in model.columns):
        raise ValueError(f"reference_plain: the {model.name} model has columns not from the planes")
    cols = [f for c in model.columns for f in c.factors()]
    unnorm = np.empty((*lik.shape[:2], model.hypotheses))
    unnorm[..., :-1] = lik[..., 0]
    unnorm[..., -1] = nm
    for k, c in enumerate(cols[1:], start=1):  # the kernel's order: ((m * gH) * gV) * census
        unnorm[..., :-1] *= lik[..., k]
        unnorm[..., -1] *= c.nomatch_values()[0] if c.nomatch_values() else 1.0
    # np.argmax returns the first maximum: lowest index wins exact ties.
    index = np.argmax(unnorm, axis=-1)
    return Reference(unnorm / unnorm.sum(axis=-1, keepdims=True), map_from_index(index, model.dmax))


def reference_prior_plain(left: Planes, right: Planes, model: ModelParams) -> Reference:
    """A model's reference pixel by pixel in plain Python over ``likelihoods_plain`` (test oracle; no PASS
    column). Slow and direct: the raster-order prior from each prior column's formula and the MAPs so far."""
    lik, nm = likelihoods_plain(left, right, model)
    ho, wo, _, _ = lik.shape
    dmax, m = model.dmax, model.hypotheses
    l_nm = 1.0  # the FEATURES columns' no-match entries but the rule's
    for c in model.columns:
        for f in c.factors() if c.source is Source.FEATURES else ():
            if f.nomatch_values():
                l_nm = l_nm * f.nomatch_values()[0]
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
