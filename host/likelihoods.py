"""Likelihood memories: the per-pixel words the host loads into the machine, column by column.

A pass (:class:`~bayesmachine.models.Pass`) labels the pixels of its reference image: the left image
(lane d pairs map column x with right column x - d: a model's own pass, its output) or the right (lane d
pairs right column x_r with left column x_r + d, over every right column an output pixel reads:
census-lr's right pass), :func:`pass_grid`. :func:`pass_words` asks each of its loaded columns for its
words (:meth:`~bayesmachine.columns.Column.words`, the host's twin of the column's lanes on chip) from one
:class:`~bayesmachine.columns.PassContext` (:func:`pass_context`): both images' planes, the pass's own
MAPs of the map row above (``above``: an ABOVE column's), the other passes' MAPs of the same rows by
pass name (``results``: a PASS column's). A FEEDBACK column is formed by the machine, not loaded. The
pass's no-match rule (P_nm(gV)) sits in the no-match row of its first FEATURES column
(:attr:`~bayesmachine.models.Pass.rule_column`; a fused column's words hold it themselves); a pass
without a no-match row has 0 there in every FEATURES column.
"""

from __future__ import annotations

from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesmachine.columns import PassContext, PlaneColumn, hamming, quantize
from bayesmachine.columns.census import _hamming_plain as hamming_plain
from bayesmachine.models import ModelParams, Pass, check_disparity_machine
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.region import OutputRegion

from .features import Planes

__all__ = [
    "PassGrid",
    "pass_grid",
    "pass_context",
    "pass_words",
    "memory_words",
    "likelihoods_plain",
    "memory_words_plain",
    "hamming",
    "hamming_plain",
    "need_planes",
]


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
    an output pixel reads, x_first - Dmax .. x_last, lane d pairing it with x + d (right reference)."""
    last = int(region.map_columns[-1])
    d = np.arange(region.dmax + 1)
    if p.step < 0:
        cols = region.map_columns
        return PassGrid(cols, cols[:, None] - d[None, :], None, last)
    cols = np.arange(int(region.map_columns[0]) - region.dmax, last + 1)
    match = cols[:, None] + d[None, :]
    return PassGrid(cols, np.minimum(match, last), match <= last, last)


def need_planes(p: Pass, left: Planes, right: Planes) -> None:
    """ParameterError unless both images' planes hold every plane the pass's columns read."""
    for term in p.terms:
        for name in term.planes():
            if name not in left or name not in right:
                raise ParameterError(f"{p.where}'s {term.name} column needs the {name} plane of both images "
                                     "(planes from host.features.model_planes(image, model))")


def pass_context(p: Pass, left: Planes, right: Planes, word_bits: int | None, *, rows: slice | None = None,
                 above: np.ndarray | None = None,
                 results: Mapping[str, np.ndarray] | None = None,
                 carry: MutableMapping[str, Any] | None = None) -> PassContext:
    """What pass ``p``'s columns build their words (``word_bits``; None: float64 factors) from, for map
    rows ``rows`` (default all): its reference image's planes and the other's, its grid, ``above`` (its
    own MAPs of the row above), ``results`` (the other passes' MAPs of these rows, by name) and ``carry``
    (what its columns carry from band to band: one dict per pass and frame, the bands in order)."""
    need_planes(p, left, right)
    region = OutputRegion.of_features(left.shape, p.model.dmax)
    grid = pass_grid(p, region)
    ref, other = (left, right) if p.step < 0 else (right, left)
    band = rows if rows is not None else slice(None)
    grids = {q.name: (g.first, g.width) for q in p.model.passes for g in (pass_grid(q, region),)}
    return PassContext(where=p.where, reference=ref.band(band), match=other.band(band), columns=grid.columns,
                       match_columns=grid.match, valid=grid.valid, nomatch=p.nomatch, word_bits=word_bits,
                       above=above, results=dict(results or {}), grids=grids, rule=p.model.nomatch,
                       nomatch_live=p.nomatch and not any(c.zeroes_nomatch for c in p.columns),
                       first_row=band.start or 0, carry=carry)


def _given(words: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    w = np.asarray(words)
    if w.shape != shape:
        raise ValueError(f"prior words must have shape {shape}, got {w.shape}")
    return w


def pass_words(p: Pass, left: Planes, right: Planes, machine: MachineParams, *, rows: slice | None = None,
               above: np.ndarray | None = None, results: Mapping[str, np.ndarray] | None = None,
               prior: np.ndarray | None = None, carry: MutableMapping[str, Any] | None = None) -> np.ndarray:
    """The likelihood-memory words (P, M, loaded columns) of pass ``p``'s pixels of map rows ``rows``
    (default: all), row-major over its grid (:func:`pass_grid`), on ``machine``: each loaded column's
    (module text). ``above``: the pass's own MAPs of the map row above (W,), -1 for none (an ABOVE
    column's: required then, one row at a time); ``results``: the other passes' MAPs of these rows by
    name (a PASS column's); ``prior``: the words (P, M) of the machine's own loaded prior column
    (``prior="loaded"``; default 1.0); ``carry``: what its columns carry from band to band (a semi-global
    column's path costs: one dict per pass and frame, the bands in order from row 0). What the machine's
    integrator kind loads (``kind.column_entries``): with ``integrator = "log"`` each column's energy codes
    instead
    (``Column.codes``: ``bayesmachine.columns.energy.log_codes`` of its float64 factors, its
    ``Term.energy()`` codes, 511 for a factor of 0; a fused column's summed codes), ``prior`` codes too."""
    model = p.model
    check_disparity_machine(model, machine)
    kind = machine.kind  # what its machine loads: words, or energy codes of the float64 factors
    ctx = pass_context(p, left, right, kind.table_bits(machine), rows=rows, above=above, results=results,
                       carry=carry)
    loaded = [c for c in p.columns if c.source.loaded]
    own = machine.loaded_columns - len(loaded)  # the machine's own loaded prior column (prior="loaded")
    if prior is not None and not own:
        raise ParameterError("prior: prior words given but the machine has no loaded prior column of its own "
                             "(prior='loaded')", "prior")
    n = ctx.rows * ctx.columns.size
    words = np.empty((n, model.hypotheses, machine.loaded_columns), dtype=np.uint16)
    if own:
        flat = kind.flat(machine)  # 1.0: the word 2^W, the code 0
        words[:, :, 0] = flat if prior is None else _given(prior, (n, model.hypotheses))
    for k, c in enumerate(loaded, start=own):
        words[:, :, k] = kind.column_entries(c, ctx)
    if p.nomatch and not p.rule_column.holds_rule:
        words[:, -1, own + loaded.index(p.rule_column)] = kind.entries(model.nomatch.floor(ctx), machine)
    return words


def memory_words(left: Planes, right: Planes, model: ModelParams, machine: MachineParams, *,
                 rows: slice | None = None, above: np.ndarray | None = None,
                 results: Mapping[str, np.ndarray] | None = None,
                 prior: np.ndarray | None = None,
                 carry: MutableMapping[str, Any] | None = None) -> np.ndarray:
    """The words (P, M, loaded columns) of ``model``'s own pass (the output pixels of map rows ``rows``,
    row-major): :func:`pass_words` (``results``: e.g. census-lr's right pass's MAPs, ``{"right": ...}``)."""
    return pass_words(model.passes[-1], left, right, machine, rows=rows, above=above, results=results,
                      prior=prior, carry=carry)


def likelihoods_plain(left: Planes, right: Planes, model: ModelParams) -> tuple[np.ndarray, np.ndarray]:
    """All likelihoods of the model's FEATURES columns (a fused column's members) by each kind's plain cost
    and formula (the test oracle): ``lik`` (Ho, Wo, Dmax+1, columns) float64 and ``nomatch`` (Ho, Wo),
    P_nm(gV)."""
    p = model.passes[-1]
    need_planes(p, left, right)
    region = OutputRegion.of_features(left.shape, model.dmax)
    x, xr = region.map_slice, region.match_columns
    cols = [f for c in model.columns for f in c.factors() if isinstance(f, PlaneColumn)]
    lik = np.empty((*region.shape, model.dmax + 1, len(cols)))
    for k, c in enumerate(cols):
        a, b = left[c.plane], right[c.plane]
        lik[..., k] = c.likelihood(c.plain_cost(a[:, x, None], b[:, xr]))
    return lik, model.nomatch.likelihood(left[model.nomatch.plane][:, x])


def memory_words_plain(left: Planes, right: Planes, model: ModelParams, machine: MachineParams) -> np.ndarray:
    """The same words from the plain formula (a test oracle for ``memory_words``; uniform prior; models
    whose loaded columns all come from the planes)."""
    cols = [c for c in model.columns if c.source.loaded]
    if not all(isinstance(c, PlaneColumn) for c in cols):
        raise ValueError(f"memory_words_plain: the {model.name} model has loaded columns not from the planes")
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
