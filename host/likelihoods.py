"""Likelihood memories: the per-pixel words the host loads into the machine, column by column.

A pass (:class:`~bayesmachine.models.Pass`) labels the pixels of its reference image: its own pass (the
left image, lane d pairs map column x with right column x - d) or a declared one (census-lr's right
pass: the right image, lane d pairs right column x_r with left column x_r + d, over
:func:`right_columns`). :func:`pass_words` gathers its words from its columns
(:mod:`bayesmachine.columns`): a FEATURES column's word of lane d is its table at the cost of the two
pixels' features (0 for a lane without a match pixel: right of the last output column), its no-match
entry in the no-match row (the pass's no-match rule in its first column: P_nm(gV); 0 in every column of
a pass without a no-match row). The words of a loaded column that does not come from the features are
arguments: ``prior`` (an ABOVE column's: the above neighbours' factor words, formed from the
machine's results of the previous map row, or the machine's own loaded prior column) and ``fed`` (a
PASS column's: census-lr's consistency words of the right pass's MAPs); a FEEDBACK column is formed by
the machine, not loaded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.columns import Column, Source, hamming
from bayesmachine.columns.census import _hamming_plain as hamming_plain
from bayesmachine.models import ModelParams, Pass, check_disparity_machine
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.region import OutputRegion

from .features import FeatureSums

__all__ = [
    "PassGrid",
    "pass_grid",
    "pass_words",
    "memory_words",
    "right_memory_words",
    "right_columns",
    "likelihoods_plain",
    "memory_words_plain",
    "hamming",
    "hamming_plain",
    "need_planes",
]


def right_columns(region: OutputRegion) -> np.ndarray:
    """The right pass's map columns: every right column an output pixel reads, x_first - Dmax .. x_last."""
    cols = region.map_columns
    return np.arange(int(cols[0]) - region.dmax, int(cols[-1]) + 1)


@dataclass(frozen=True)
class PassGrid:
    """Where a pass's pixels and their lanes are: reference map ``columns`` (W,), the ``match`` column of
    each lane (W, Dmax+1; clamped to ``last``, the last output column), ``valid`` lanes (None: all)."""

    columns: np.ndarray
    match: np.ndarray
    valid: np.ndarray | None
    last: int

    @property
    def first(self) -> int:
        return int(self.columns[0])

    @property
    def width(self) -> int:
        return int(self.columns.size)


def pass_grid(p: Pass, region: OutputRegion) -> PassGrid:
    """The grid of pass ``p`` over ``region``: the output columns (left reference), or every right column
    an output pixel reads (:func:`right_columns`), lane d pairing it with x + d (right reference)."""
    last = int(region.map_columns[-1])
    d = np.arange(region.dmax + 1)
    if p.step < 0:
        cols = region.map_columns
        return PassGrid(cols, cols[:, None] - d[None, :], None, last)
    cols = right_columns(region)
    match = cols[:, None] + d[None, :]
    return PassGrid(cols, np.minimum(match, last), match <= last, last)


def need_planes(p: Pass, left: FeatureSums, right: FeatureSums) -> None:
    """ParameterError unless both images' features hold every plane the pass's columns read."""
    for c in p.columns:
        missing = c.source is Source.FEATURES and (getattr(left, c.plane) is None
                                                   or getattr(right, c.plane) is None)
        if missing:
            raise ParameterError(f"the {p.model.name} model's {c.name} column needs the {c.plane} maps of "
                                 "both images (features from host.features.model_features(image, model))")


def _feature_words(c: Column, p: Pass, ref: FeatureSums, other: FeatureSums, grid: PassGrid,
                   word_bits: int, floor: np.ndarray | None) -> np.ndarray:
    """(P, Dmax+2) words of FEATURES column ``c``: its table at each lane's cost, its no-match entry
    (``floor``: the pass's no-match rule's words, in its first column)."""
    table = c.table(word_bits)
    a, b = getattr(ref, c.plane), getattr(other, c.plane)
    words = table.values[c.cost(a[:, grid.columns, None], b[:, grid.match])]
    if grid.valid is not None:  # a lane without a match pixel never fires
        words = words * grid.valid[None]
    n = words.shape[0] * grid.width
    out = np.empty((n, grid.match.shape[1] + 1), np.uint16)
    out[:, :-1] = words.reshape(n, -1)
    out[:, -1] = 0 if not p.nomatch else floor if floor is not None else c.nomatch_entry(table)
    return out


def _given(words: np.ndarray | None, shape: tuple[int, int], parameter: str, source: str) -> np.ndarray:
    """The words (P, M) given as ``parameter`` for a column that does not come from the features."""
    if words is None:
        raise ParameterError(f"{parameter}: {source}: pass {parameter}=", parameter)
    w = np.asarray(words)
    if w.shape != shape:
        raise ValueError(f"{parameter} words must have shape {shape}, got {w.shape}")
    return w


def pass_words(p: Pass, left: FeatureSums, right: FeatureSums, machine: MachineParams,
               rows: slice | None = None, prior: np.ndarray | None = None,
               fed: np.ndarray | None = None) -> np.ndarray:
    """The likelihood-memory words (P, M, loaded columns) of pass ``p``'s pixels of map rows ``rows``
    (default: all), row-major over its grid (:func:`pass_grid`), on ``machine``.

    ``prior``: the words (P, M) of its loaded prior column (an ABOVE column's, required then; or the
    machine's own ``prior="loaded"`` column, 1.0 without them). ``fed``: the words (P, M) of its PASS
    column (required then)."""
    model = p.model
    check_disparity_machine(model, machine)
    need_planes(p, left, right)
    ref, other = (left, right) if p.step < 0 else (right, left)
    region = OutputRegion.of_features(left.shape, model.dmax)
    grid = pass_grid(p, region)
    band = rows if rows is not None else slice(None)
    ref, other = ref.band(band), other.band(band)
    n = ref.shape[0] * grid.width
    shape = (n, model.hypotheses)
    loaded = [c for c in p.columns if c.source is not Source.FEEDBACK]
    own = machine.loaded_columns - len(loaded)  # the machine's own loaded prior column (prior="loaded")
    if prior is not None and not (own or any(c.source is Source.ABOVE for c in loaded)):
        raise ParameterError("prior: prior words given but the machine has no loaded prior column", "prior")
    if fed is not None and not any(c.source is Source.PASS for c in loaded):
        raise ParameterError(f"fed: words given but the {model.name} model has no column fed by another pass",
                             "fed")
    words = np.empty((n, model.hypotheses, machine.loaded_columns), dtype=np.uint16)
    if own:
        words[:, :, 0] = machine.word_one if prior is None else _given(prior, shape, "prior", "")
    floor = None
    if p.nomatch:
        floor = model.nomatch.table(machine.word_bits).values[model.nomatch.cost(ref.gv20[:, grid.columns])]
        floor = floor.reshape(n)
    for k, c in enumerate(loaded, start=own):
        if c.source is Source.FEATURES:
            words[:, :, k] = _feature_words(c, p, ref, other, grid, machine.word_bits, floor)
            floor = None  # the no-match rule sits in the first data column
        elif c.source is Source.ABOVE:
            words[:, :, k] = _given(prior, shape, "prior", "the above neighbours' factor words come from the "
                                    "machine's own results of the previous map row (AbovePrior.loaded)")
        else:
            words[:, :, k] = _given(fed, shape, "fed", f"the {c.name} column's words come from the "
                                    f"{c.feeds_from} pass's results (Consistency.loaded)")
    return words


def memory_words(left: FeatureSums, right: FeatureSums, model: ModelParams, machine: MachineParams,
                 rows: slice | None = None, prior: np.ndarray | None = None,
                 fed: np.ndarray | None = None) -> np.ndarray:
    """The words (P, M, loaded columns) of ``model``'s own pass (the output pixels of map rows ``rows``,
    row-major): :func:`pass_words` (``fed``: census-lr's consistency words of the right MAPs)."""
    return pass_words(model.passes[-1], left, right, machine, rows, prior, fed)


def right_memory_words(left: FeatureSums, right: FeatureSums, model: ModelParams, machine: MachineParams,
                       rows: slice | None = None, prior: np.ndarray | None = None) -> np.ndarray:
    """The words (Pr, M, loaded columns) of census-lr's right pass over :func:`right_columns`
    (:func:`pass_words` of ``model.pass_named("right")``; ``prior``: its above words)."""
    return pass_words(model.pass_named("right"), left, right, machine, rows, prior)


def likelihoods_plain(left: FeatureSums, right: FeatureSums,
                      model: ModelParams) -> tuple[np.ndarray, np.ndarray]:
    """All likelihoods of the model's FEATURES columns by each kind's plain cost and formula (the test
    oracle): ``lik`` (Ho, Wo, Dmax+1, columns) float64 and ``nomatch`` (Ho, Wo), P_nm(gV)."""
    p = model.passes[-1]
    need_planes(p, left, right)
    region = OutputRegion.of_features(left.shape, model.dmax)
    x, xr = region.map_slice, region.match_columns
    cols = [c for c in model.columns if c.source is Source.FEATURES]
    lik = np.empty((*region.shape, model.dmax + 1, len(cols)))
    for k, c in enumerate(cols):
        a, b = getattr(left, c.plane), getattr(right, c.plane)
        lik[..., k] = c.likelihood(c.plain_cost(a[:, x, None], b[:, xr]))
    return lik, model.nomatch.likelihood(left.gv20[:, x])


def memory_words_plain(left: FeatureSums, right: FeatureSums, model: ModelParams,
                       machine: MachineParams) -> np.ndarray:
    """The same words from the plain formula (a test oracle for ``memory_words``; uniform prior; models
    whose loaded columns all come from the features)."""
    from bayesmachine.columns import quantize

    cols = [c for c in model.columns if c.source is not Source.FEEDBACK]
    if any(c.source is not Source.FEATURES for c in cols):
        raise ValueError(f"memory_words_plain: the {model.name} model has loaded columns not from features")
    check_disparity_machine(model, machine)
    off = machine.loaded_columns - len(cols)
    lik, nm = likelihoods_plain(left, right, model)
    n = lik.shape[0] * lik.shape[1]
    w = machine.word_bits
    words = np.full((n, model.hypotheses, machine.loaded_columns), machine.word_one, dtype=np.uint16)
    words[:, : model.dmax + 1, off:] = quantize(lik, w).reshape(n, model.dmax + 1, len(cols))
    words[:, model.dmax + 1, off] = quantize(nm, w).reshape(n)
    for k, c in enumerate(cols[1:], start=off + 1):
        entry = c.nomatch_values()
        words[:, model.dmax + 1, k] = quantize(entry[0], w) if entry else machine.word_one
    return words
