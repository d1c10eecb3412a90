"""Likelihood memories: the per-pixel words the host loads into the machine.

The model (``ModelParams``), the likelihood formula and tables (paper eq. 2 and 4) and the
quantization live in :mod:`bayesmachine.likelihood`, shared with the on-chip front end;
they are re-exported here. This module gathers them per output pixel from the features
of a pair.
"""

from __future__ import annotations

import numpy as np

from bayesmachine.likelihood import (
    FEATURES,
    LikelihoodTables,
    ModelParams,
    QuantizedTables,
    likelihood_formula,
    likelihood_tables,
    quantize,
)
from bayesmachine.params import MachineParams

from .features import SCALES, FeatureSums
from .region import OutputRegion

__all__ = [
    "ModelParams",
    "LikelihoodTables",
    "QuantizedTables",
    "likelihood_tables",
    "likelihood_formula",
    "likelihoods_plain",
    "quantize",
    "memory_words",
    "memory_words_plain",
]


def likelihoods_plain(
    left: FeatureSums, right: FeatureSums, model: ModelParams
) -> tuple[np.ndarray, np.ndarray]:
    """All likelihoods by the plain vectorized formula (the test oracle).

    Returns ``lik`` (Ho, Wo, Dmax+1, 3) float64 (features m, gH, gV) and ``nomatch`` (Ho, Wo).
    """
    region = OutputRegion.of_features(left.shape, model.dmax)
    x, xr = region.map_slice, region.match_columns
    lik = np.empty((*region.shape, model.dmax + 1, 3))
    for k, f in enumerate(FEATURES):
        fl = getattr(left, f"{f}{SCALES[f]}")
        fr = getattr(right, f"{f}{SCALES[f]}")
        delta = fl[:, x, None].astype(np.int64) - fr[:, xr].astype(np.int64)
        lik[..., k] = likelihood_formula(delta, SCALES[f], model.p0, model.sigma(f))
    nomatch = likelihood_formula(left.gv20[:, x], SCALES["gv"], model.p_nm0, model.sigma_nm)
    return lik, nomatch


def _check_machine(model: ModelParams, machine: MachineParams) -> int:
    if machine.rows != model.hypotheses or not machine.nomatch_row:
        raise ValueError(
            f"machine has {machine.rows} rows (no-match row: {machine.nomatch_row}); the model needs "
            f"{model.hypotheses} = dmax + 2 with a no-match row: "
            f"use MachineParams.for_disparity({model.dmax})"
        )
    if machine.columns != 3:
        raise ValueError(f"the disparity model has 3 data terms, the machine has columns={machine.columns}")
    if quantize(model.p_nm0, machine.word_bits) == 0:
        # Then an occluded pixel (every row ~0) could only stop at the watchdog, max_cycles later.
        raise ValueError(
            f"p_nm0 = {model.p_nm0} quantizes to 0 with {machine.word_bits}-bit words, so a pixel with "
            f"no match could not stop before the watchdog; raise --word-bits or --p-nm0 "
            f"(p_nm0 >= 2^-{machine.word_bits + 1})"
        )
    return machine.operator_columns - machine.columns  # 1 with a loaded prior (column 0)


def memory_words(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    machine: MachineParams,
    rows: slice | None = None,
    qtables: QuantizedTables | None = None,
) -> np.ndarray:
    """Likelihood-memory words of the output pixels of map rows ``rows`` (default: all).

    Shape (P, M, operator_columns), row-major pixel order. Rows 0..Dmax hold the three
    quantized likelihoods (columns m, gH, gV); the no-match row holds [P(nomatch), 1, 1]
    (1 = 2^W). With a loaded prior, column 0 is a uniform prior (2^W everywhere).
    """
    off = _check_machine(model, machine)
    if qtables is None:
        qtables = QuantizedTables(likelihood_tables(model), machine.word_bits)
    dmax = model.dmax
    region = OutputRegion.of_features(left.shape, dmax)
    x, xr = region.map_slice, region.match_columns
    band_l = left.band(rows if rows is not None else slice(None))
    band_r = right.band(rows if rows is not None else slice(None))
    p = band_l.shape[0] * region.shape[1]
    words = np.empty((p, model.hypotheses, machine.operator_columns), dtype=np.uint16)
    tabs = (qtables.m, qtables.gh, qtables.gv)
    for k, (fl, fr, tab) in enumerate(zip(band_l.as_tuple(), band_r.as_tuple(), tabs, strict=True)):
        delta = np.abs(fl[:, x, None] - fr[:, xr])
        words[:, : dmax + 1, off + k] = tab[delta].reshape(p, dmax + 1)
    words[:, dmax + 1, off] = qtables.nomatch[np.abs(band_l.gv20[:, x])].reshape(p)
    words[:, dmax + 1, off + 1 :] = qtables.one
    if off:
        words[:, :, 0] = qtables.one
    return words


def memory_words_plain(
    left: FeatureSums, right: FeatureSums, model: ModelParams, machine: MachineParams
) -> np.ndarray:
    """The same words from the plain formula (a test oracle for ``memory_words``)."""
    off = _check_machine(model, machine)
    lik, nm = likelihoods_plain(left, right, model)
    p = lik.shape[0] * lik.shape[1]
    one = 1 << machine.word_bits
    words = np.full((p, model.hypotheses, machine.operator_columns), one, dtype=np.uint16)
    words[:, : model.dmax + 1, off:] = quantize(lik, machine.word_bits).reshape(p, model.dmax + 1, 3)
    words[:, model.dmax + 1, off] = quantize(nm, machine.word_bits).reshape(p)
    return words
