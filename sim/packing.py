"""Raw port values for the simulator: load beats and entropy values, packed at the layouts' offsets.

The positions come from the ports' :mod:`amaranth.lib.data` layouts (never hand shifts), and
the values are validated with the engines' own checks, so an out-of-range number cannot spill
into its neighbour's bits. Results go the other way through :func:`bayesmachine.sim.results.decode_results`.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from bayesmachine.params import MachineParams
from bayesmachine.sim.results import check_line_start, check_numbers, check_words, layout_fields

__all__ = ["element_offsets", "pack_beats", "pack_numbers"]


def element_offsets(layout: Any) -> list[int]:
    """Bit offsets of the elements of an array layout, in index order."""
    return [offset for offset, _ in layout_fields(layout).values()]


@functools.lru_cache(maxsize=32)
def _lane_offsets(params: MachineParams) -> tuple[tuple[int, ...], int | None]:
    """The bit offsets of a load beat's word lanes and of its ``line_start`` flag (None: no flag)."""
    from bayesmachine.hdl.signatures import load_layout

    fields = layout_fields(load_layout(params))
    flag = fields.pop("line_start", (None, 0))[0]
    return tuple(offset for offset, _ in fields.values()), flag


def _pack(offsets: list[int] | tuple[int, ...], values: np.ndarray) -> int:
    raw = 0
    for off, v in zip(offsets, values.tolist(), strict=False):
        raw |= v << off
    return raw


def pack_beats(params: MachineParams, words: np.ndarray, line_start: np.ndarray | None = None) -> list[int]:
    """Pixels' words (operator order) as raw load-stream beats, ``beats_per_pixel`` per pixel.

    ``words``: one pixel's ``words_per_pixel`` words, or (P, ...) pixels. Word o of a pixel goes
    to lane ``o % lanes`` of its beat ``o // lanes``; unused lanes of the last beat are 0. With a
    neighbour prior, ``line_start`` (one flag per pixel) goes into every beat of its pixel.
    """
    q = check_words(params, np.asarray(words).reshape(-1, params.words_per_pixel))
    flags = check_line_start(params, line_start, q.shape[0])
    lanes, (offsets, flag_offset) = params.words_per_beat, _lane_offsets(params)
    beats = []
    for i, pixel in enumerate(q):
        flag = int(flags[i]) << flag_offset if flags is not None else 0
        beats += [_pack(offsets, pixel[b * lanes : (b + 1) * lanes]) | flag
                  for b in range(params.beats_per_pixel)]
    return beats


def pack_numbers(params: MachineParams, layout: Any, numbers: np.ndarray) -> list[int]:
    """Rows of random numbers, one per compute cycle (B = ``samples_per_clock`` samples' numbers per
    operator: shape (cycles, B * operators), as ``NumberFeed.take_clocks`` gives them), as raw values
    of the ``entropy`` port of ``layout``."""
    per_clock = params.operators * params.samples_per_clock
    numbers = np.asarray(numbers)
    if numbers.ndim != 2 or numbers.shape[1] != per_clock:
        raise ValueError(f"random numbers must have shape (cycles, {per_clock}), got {numbers.shape}")
    rows = check_numbers(params, numbers.reshape(-1, params.operators)).reshape(-1, per_clock)
    offsets = element_offsets(layout)
    if len(offsets) != per_clock:
        raise ValueError(f"entropy layout {layout!r} has {len(offsets)} elements, not {per_clock}")
    return [_pack(offsets, row) for row in rows]
