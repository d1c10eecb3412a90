"""Testbench helpers: stream handshakes, packing of load beats and results, synthetic pixels.

The stream helpers follow the ``amaranth.lib.stream`` testbench idiom (as in Glasgow):
``await stream_put(ctx, dut.load, beat)`` / ``payload = await stream_get(ctx, dut.result)``.
Packing works on the raw bits of the ports (Python ints), which is much faster in the
simulator than going through the layouts field by field.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from amaranth.lib import stream
from amaranth.sim import SimulatorContext

from bayesmachine.params import MachineParams

__all__ = [
    "pack_beats",
    "pack_numbers",
    "stream_get",
    "stream_put",
    "synthetic_disparity_words",
    "unpack_result",
]


async def stream_put(ctx: SimulatorContext, stream_: stream.Interface, payload: object) -> None:
    """Hold ``valid`` with ``payload`` until the sink takes it (one handshake)."""
    ctx.set(stream_.valid, 1)
    ctx.set(stream_.payload, payload)
    await ctx.tick().until(stream_.ready)
    ctx.set(stream_.valid, 0)


async def stream_get(ctx: SimulatorContext, stream_: stream.Interface) -> object:
    """Hold ``ready`` until the source offers a payload; returns it (one handshake)."""
    ctx.set(stream_.ready, 1)
    (payload,) = await ctx.tick().sample(stream_.payload).until(stream_.valid)
    ctx.set(stream_.ready, 0)
    return payload


def pack_beats(params: MachineParams, words: np.ndarray) -> list[int]:
    """One pixel's ``words_per_pixel`` words (operator order) as raw load-stream beats.

    Word o goes to lane ``o % lanes`` of beat ``o // lanes``; unused lanes of the last beat are 0.
    """
    flat = [int(x) for x in np.asarray(words).reshape(-1)]
    if len(flat) != params.words_per_pixel:
        raise ValueError(f"a pixel has {params.words_per_pixel} words, got {len(flat)}")
    ww = params.memory_word_width
    beats = []
    for b in range(params.beats_per_pixel):
        raw = 0
        for lane, word in enumerate(flat[b * params.lanes : (b + 1) * params.lanes]):
            raw |= word << (lane * ww)
        beats.append(raw)
    return beats


def pack_numbers(params: MachineParams, numbers: Sequence[int]) -> int:
    """One compute cycle's random numbers (one per operator) as the raw ``entropy`` port value."""
    raw = 0
    w = params.word_bits
    for o, n in enumerate(numbers):
        raw |= int(n) << (o * w)
    return raw


def unpack_result(params: MachineParams, raw: int) -> tuple[int, int, int, int, list[int]]:
    """A raw ``result`` payload as ``(map, nomatch, timeout, cycles, counts)`` (field order of
    :func:`bayesmachine.hdl.machine.result_layout`)."""
    pos = 0

    def take(width: int) -> int:
        nonlocal pos
        v = (raw >> pos) & ((1 << width) - 1)
        pos += width
        return v

    map_ = take(params.map_width)
    nomatch = take(1)
    timeout = take(1)
    cycles = take(params.cycle_width)
    counts = [take(params.counter_width) for _ in range(params.rows)]
    return map_, nomatch, timeout, cycles, counts


def synthetic_disparity_words(
    params: MachineParams,
    pixels: int,
    rng: np.random.Generator,
    *,
    p0: float = 0.02,
    p_nm0: float = 0.01,
    sigma: float = 10.0,
    sigma_nm: float = 8.0,
    occluded: float = 0.1,
) -> np.ndarray:
    """Likelihood memories shaped like the paper's (eqs. 2 and 6), without images.

    Per pixel a true disparity; each feature's matching cost is small at the true disparity
    (and by chance elsewhere), ``p = p0 + (1 - p0) exp(-delta^2 / (2 sigma^2))``; a fraction
    ``occluded`` of the pixels has no match (costs high everywhere). The no-match row holds
    ``[P(nomatch), 1, ...]`` with ``P(nomatch) = p_nm0 + (1 - p_nm0) exp(-g^2 / (2 sigma_nm^2))``
    for a random vertical gradient g. For a machine without a no-match row every row is a
    hypothesis. With a loaded prior, column 0 is a uniform prior word (1.0). Returns
    (pixels, rows, operator_columns) int32 words.
    """
    rows, cols, one = params.rows, params.columns, params.word_one
    hyps = rows - 1 if params.nomatch_row else rows
    lik = np.empty((pixels, rows, cols))
    for i in range(pixels):
        # Feature differences: wide for wrong disparities, narrow at the true one.
        delta = rng.normal(0.0, 40.0, size=(hyps, cols))
        if rng.random() >= occluded:
            d = rng.integers(hyps)
            delta[d] = rng.normal(0.0, 4.0, size=cols)
        lik[i, :hyps] = p0 + (1 - p0) * np.exp(-(delta**2) / (2 * sigma**2))
        if params.nomatch_row:
            g = rng.normal(0.0, 30.0)
            lik[i, hyps] = 1.0
            lik[i, hyps, 0] = p_nm0 + (1 - p_nm0) * np.exp(-(g**2) / (2 * sigma_nm**2))
    words = np.clip(np.rint(lik * one), 0, one).astype(np.int32)
    if params.prior == "loaded":
        words = np.concatenate([np.full((pixels, rows, 1), one, np.int32), words], axis=2)
    return words
