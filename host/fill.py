"""Occlusion fill: a disparity for the pixels the machine leaves without one, from their row.

The pixels to fill are those the machine calls no match (its no-match row won, or a timeout it does not
answer) and, with a left-right consistency column, those whose MAP the left-right test rejects (the
right pass's MAP at x − d is not within the tolerance of d, nor unknown with ``lr_neutral``: the
column's factor beta, :meth:`~bayesmachine.columns.Consistency.rejects`). Each takes a disparity
from the matched pixels of its own row (``--fill``):

- ``background``: the lower of the nearest matched disparities to its left and to its right (an occluded
  pixel belongs to the farther surface); the one there is where only one side has any;
- ``left``: the nearest matched disparity to its left (causal: one register on chip), none at a row's
  start;
- ``none``: no fill.

A pixel whose row offers no value stays without a disparity. The machine's own results are kept beside
the filled map (``result.npz``: ``map`` and ``nomatch`` the machine's, ``filled_map`` and ``filled``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.columns import Consistency
from bayesmachine.errors import ParameterError
from bayesmachine.region import OutputRegion

from .likelihoods import pass_grid
from .records import MachineRun, Prepared

__all__ = ["FILLS", "DEFAULT_FILL", "Fill", "fill_rows", "run_holes", "run_fill"]

FILLS = ("background", "left", "none")
DEFAULT_FILL = "background"


@dataclass(frozen=True)
class Fill:
    """A filled map: ``map`` (Ho, Wo) int16 (-1: still none), ``filled`` (Ho, Wo) bool, the pixels that took
    a neighbour's value, ``source`` (Ho, Wo) int, the column of the row's matched pixel each took it from
    (its own column where not filled), ``holes`` (Ho, Wo) bool, every pixel that was to be filled, and the
    ``rule``."""

    map: np.ndarray
    filled: np.ndarray
    source: np.ndarray
    holes: np.ndarray
    rule: str

    def carried(self, values: np.ndarray) -> np.ndarray:
        """A per-pixel measure (Ho, Wo) with each filled pixel's taken from its source pixel: the filled
        map's confidence is the confidence of the pixel whose disparity it took."""
        rows = np.arange(self.map.shape[0])[:, None]
        return np.asarray(values)[rows, self.source]


def _check_rule(rule: str) -> None:
    if rule not in FILLS:
        raise ParameterError(f"fill must be one of {', '.join(FILLS)}, got {rule!r}", "fill")


def fill_rows(disp: np.ndarray, holes: np.ndarray, rule: str) -> Fill:
    """Fill ``disp`` (Ho, Wo; < 0: none) at ``holes`` (Ho, Wo bool; a pixel without a disparity is one
    too) by ``rule`` (module text)."""
    _check_rule(rule)
    d = np.asarray(disp).astype(np.int16)
    hole = np.asarray(holes, bool) | (d < 0)
    if d.ndim != 2 or hole.shape != d.shape:
        raise ValueError(f"disp and holes must be 2-D of one shape, got {d.shape} and {hole.shape}")
    w = d.shape[1]
    x = np.broadcast_to(np.arange(w), d.shape)
    if rule == "none" or not d.size:
        return Fill(np.where(hole, np.int16(-1), d), np.zeros(d.shape, bool), x.copy(), hole, rule)
    rows = np.arange(d.shape[0])[:, None]
    last = np.maximum.accumulate(np.where(hole, -1, x), axis=1)  # the nearest matched at or left of x
    left = np.where(last >= 0, d[rows, np.maximum(last, 0)], -1)
    source = last
    if rule == "background":
        nxt = np.minimum.accumulate(np.where(hole, w, x)[:, ::-1], axis=1)[:, ::-1]  # at or right of x
        right = np.where(nxt < w, d[rows, np.minimum(nxt, w - 1)], -1)
        take_right = (right >= 0) & ((left < 0) | (right < left))  # the lower; the left one on a tie
        source = np.where(take_right, nxt, last)
    value = np.where(source >= 0, d[rows, np.clip(source, 0, w - 1)], -1)
    out = np.where(hole, value, d).astype(np.int16)
    filled = hole & (out >= 0)
    return Fill(out, filled, np.where(filled, source, x), hole, rule)


def run_holes(prepared: Prepared, run: MachineRun) -> np.ndarray:
    """The pixels of ``run`` to fill: no disparity, or (with a consistency column) a MAP that column
    rejects (:meth:`~bayesmachine.columns.Consistency.rejects`: its lane gets beta)."""
    model = prepared.model
    holes = np.asarray(run.map) < 0
    column = model.column(Consistency)
    if column is None or column.feeds_from not in run.passes:
        return holes
    region = OutputRegion.of_features(prepared.planes[0].shape, model.dmax)  # the passes' grids' region
    first = pass_grid(model.pass_named(column.feeds_from), region).first
    return holes | column.rejects(run.map, run.passes[column.feeds_from].map, first, region.map_columns)


def run_fill(prepared: Prepared, run: MachineRun, rule: str) -> Fill:
    """``run``'s map filled by ``rule`` at :func:`run_holes`."""
    _check_rule(rule)
    return fill_rows(run.map, run_holes(prepared, run), rule)
