"""Likelihood memories: the per-pixel words the host loads into the machine.

The model (``ModelParams``), the likelihood formula and tables (paper eq. 2 and 4) and the
quantization live in :mod:`bayesmachine.likelihood`, shared with the on-chip front end;
they are re-exported here. This module gathers them per output pixel from the features
of a pair.

The census model (``ModelParams(name="census")``) adds a fourth data column, the census
likelihood at the Hamming distance h = popcount(C_l(x) xor C_r(x - d)) of the pixels' census
codes (``FeatureSums.census``, from :func:`host.features.model_features`), and the no-match
row's census entry L_c(h_nm). Its neighbour prior runs on the machine
:func:`bayesmachine.likelihood.disparity_machine` builds (``prior="neighbour"``): the left
neighbour's factor is the machine's own feedback column, the above neighbour's factor its loaded
column 0, whose words (:func:`bayesmachine.likelihood.neighbour_words`) come from the machine's
results of the previous map row, so ``memory_words`` takes them as an argument.

The census-lr model (issue 22) adds the left-right consistency column, a fifth data column whose
words (:func:`bayesmachine.likelihood.lr_column` of the right pass's MAPs) ``memory_words``
takes as an argument too; :func:`right_memory_words` builds the right pass's words (the census
model with the right image as reference: lane d pairs right map column x_r with left map column
x_r + d; word 0 in the lanes past the last output column, and in the no-match row without
``lr_right_nomatch``).
"""

from __future__ import annotations

import numpy as np

from bayesmachine.likelihood import (
    FEATURES,
    LikelihoodTables,
    ModelParams,
    QuantizedTables,
    check_disparity_machine,
    likelihood_formula,
    likelihood_tables,
    quantize,
    right_lanes_valid,
)
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.region import OutputRegion

from .features import SCALES, FeatureSums

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
    "hamming",
    "hamming_plain",
    "right_columns",
    "right_memory_words",
]


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances popcount(a xor b) of uint64 census codes (broadcast), int64."""
    return np.bitwise_count(np.bitwise_xor(a, b)).astype(np.int64)


def hamming_plain(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The same by unpacking the bytes (a test oracle independent of ``np.bitwise_count``)."""
    x = np.ascontiguousarray(np.bitwise_xor(a, b), dtype=np.uint64)
    return np.unpackbits(x.view(np.uint8).reshape(*x.shape, 8), axis=-1).sum(axis=-1).astype(np.int64)


def _need_census(left: FeatureSums, right: FeatureSums, model: ModelParams) -> None:
    if model.census and (left.census is None or right.census is None):
        raise ParameterError(
            "--model: the census model needs the census codes of both images "
            "(features from host.features.model_features(image, model))")


def likelihoods_plain(
    left: FeatureSums, right: FeatureSums, model: ModelParams
) -> tuple[np.ndarray, np.ndarray]:
    """All likelihoods by the plain vectorized formula (the test oracle).

    Returns ``lik`` (Ho, Wo, Dmax+1, 3 or 4) float64 (features m, gH, gV; census with the
    census models, from :func:`hamming_plain`; not census-lr's consistency column) and
    ``nomatch`` (Ho, Wo), P_nm(gV) (the no-match
    row's census entry is the constant L_c(h_nm)).
    """
    _need_census(left, right, model)
    region = OutputRegion.of_features(left.shape, model.dmax)
    x, xr = region.map_slice, region.match_columns
    lik = np.empty((*region.shape, model.dmax + 1, 4 if model.census else 3))
    for k, f in enumerate(FEATURES):
        fl = getattr(left, f"{f}{SCALES[f]}")
        fr = getattr(right, f"{f}{SCALES[f]}")
        delta = fl[:, x, None].astype(np.int64) - fr[:, xr].astype(np.int64)
        lik[..., k] = likelihood_formula(delta, SCALES[f], model.p0, model.sigma(f))
    if model.census:
        h = hamming_plain(left.census[:, x, None], right.census[:, xr])
        lik[..., 3] = likelihood_formula(h, 1, model.census_p0, model.sigma_c)
    nomatch = likelihood_formula(left.gv20[:, x], SCALES["gv"], model.p_nm0, model.sigma_nm)
    return lik, nomatch


def memory_words(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    machine: MachineParams,
    rows: slice | None = None,
    qtables: QuantizedTables | None = None,
    prior: np.ndarray | None = None,
    consistency: np.ndarray | None = None,
) -> np.ndarray:
    """Likelihood-memory words of the output pixels of map rows ``rows`` (default: all).

    Shape (P, M, loaded_columns), row-major pixel order. Rows 0..Dmax hold the quantized
    likelihoods (columns m, gH, gV, and census for the census model); the no-match row holds
    [P(nomatch), 1, 1] (1 = 2^W), [P(nomatch), 1, 1, L_c(h_nm)] for the census model. With a
    loaded prior column (``prior="loaded"``, or the above column of ``prior="neighbour"``),
    column 0 is ``prior`` ((P, M) words), else a uniform prior (2^W everywhere). A model with
    the neighbour prior needs ``prior``: the above neighbours' factor words
    (:func:`~bayesmachine.likelihood.neighbour_words` of the machine's results of the previous
    map row), which the words of a band cannot wait for; the left neighbour's factor is the
    machine's own feedback column, not loaded. The census-lr model needs ``consistency``: its
    consistency column's words (P, M) (:func:`~bayesmachine.likelihood.consistency_column` of the
    right pass's MAPs), the last loaded column.
    """
    check_disparity_machine(model, machine)
    off = machine.loaded_columns - machine.columns  # loaded prior columns before the data columns
    _need_census(left, right, model)
    if model.has_prior and prior is None:
        raise ParameterError(
            "--neighbour-prior: the above neighbour's prior words come from the machine's own results "
            "of the previous map row (neighbour_words): pass prior=, or turn the neighbour prior off")
    if model.lr and consistency is None:
        raise ParameterError("--model census-lr: the consistency column's words come from the right pass's "
                             "MAPs (consistency_column): pass consistency=")
    if consistency is not None and not model.lr:
        raise ParameterError(f"consistency words given but the {model.name} model has no consistency column")
    if prior is not None and not off:
        raise ParameterError("--prior: prior words given but the machine has no loaded prior column")
    if qtables is None:
        qtables = QuantizedTables(likelihood_tables(model), machine.word_bits)
    dmax = model.dmax
    region = OutputRegion.of_features(left.shape, dmax)
    x, xr = region.map_slice, region.match_columns
    band_l = left.band(rows if rows is not None else slice(None))
    band_r = right.band(rows if rows is not None else slice(None))
    p = band_l.shape[0] * region.shape[1]
    words = np.empty((p, model.hypotheses, machine.loaded_columns), dtype=np.uint16)
    tabs = (qtables.m, qtables.gh, qtables.gv)
    for k, (fl, fr, tab) in enumerate(zip(band_l.as_tuple(), band_r.as_tuple(), tabs, strict=True)):
        delta = np.abs(fl[:, x, None] - fr[:, xr])
        words[:, : dmax + 1, off + k] = tab[delta].reshape(p, dmax + 1)
    if model.census:
        if qtables.census is None:
            raise ValueError("qtables lack the census table: build them from the census model")
        h = hamming(band_l.census[:, x, None], band_r.census[:, xr])
        words[:, : dmax + 1, off + 3] = qtables.census[h].reshape(p, dmax + 1)
    words[:, dmax + 1, off] = qtables.nomatch[np.abs(band_l.gv20[:, x])].reshape(p)
    words[:, dmax + 1, off + 1 :] = qtables.one
    if model.census:
        words[:, dmax + 1, off + 3] = qtables.census_nomatch
    if consistency is not None:
        cw = np.asarray(consistency)
        if cw.shape != (p, model.hypotheses):
            raise ValueError(f"consistency words must have shape {(p, model.hypotheses)}, got {cw.shape}")
        words[:, :, off + 4] = cw
    if off:
        if prior is None:
            words[:, :, 0] = qtables.one
        else:
            pw = np.asarray(prior)
            if pw.shape != (p, model.hypotheses):
                raise ValueError(f"prior words must have shape {(p, model.hypotheses)}, got {pw.shape}")
            words[:, :, 0] = pw
    return words


def right_columns(region: OutputRegion) -> np.ndarray:
    """The right pass's map columns: every right column an output pixel reads, x_first - Dmax .. x_last."""
    cols = region.map_columns
    return np.arange(int(cols[0]) - region.dmax, int(cols[-1]) + 1)


def right_memory_words(
    left: FeatureSums,
    right: FeatureSums,
    model: ModelParams,
    machine: MachineParams,
    rows: slice | None = None,
    qtables: QuantizedTables | None = None,
    prior: np.ndarray | None = None,
) -> np.ndarray:
    """The census-lr right pass's words (Pr, M, loaded columns) of map rows ``rows``, row-major over
    :func:`right_columns`: ``model.right_model``'s words with the right image as reference (lane d of
    right column x_r reads left column x_r + d); every column of a lane past the last output column
    is word 0 (it never fires), and so is the no-match row unless ``lr_right_nomatch`` (then the
    census model's no-match row of the right pixel's gV). Column 0
    is ``prior``, the above neighbours' factor words (:func:`~bayesmachine.likelihood.neighbour_words`
    of the right pass's previous row)."""
    if not model.lr:
        raise ValueError(f"the {model.name} model has no right pass")
    rmodel = model.right_model
    check_disparity_machine(rmodel, machine)
    _need_census(left, right, rmodel)
    if prior is None:
        raise ParameterError("the right pass's above prior words come from its own previous row: pass prior=")
    if qtables is None:
        qtables = QuantizedTables(likelihood_tables(rmodel), machine.word_bits)
    dmax = model.dmax
    region = OutputRegion.of_features(left.shape, dmax)
    xr = right_columns(region)
    last = int(region.map_columns[-1])
    valid = right_lanes_valid(xr, dmax, last)
    xl = np.minimum(xr[:, None] + np.arange(dmax + 1)[None, :], last)  # clamped: invalid lanes zeroed below
    band_l = left.band(rows if rows is not None else slice(None))
    band_r = right.band(rows if rows is not None else slice(None))
    n = band_l.shape[0]
    p = n * xr.size
    off = machine.loaded_columns - machine.columns
    words = np.zeros((p, model.hypotheses, machine.loaded_columns), dtype=np.uint16)
    tabs = (qtables.m, qtables.gh, qtables.gv)
    for k, (fl, fr, tab) in enumerate(zip(band_l.as_tuple(), band_r.as_tuple(), tabs, strict=True)):
        delta = np.abs(fr[:, xr, None] - fl[:, xl])
        words[:, : dmax + 1, off + k] = tab[delta].reshape(p, dmax + 1)
    h = hamming(band_r.census[:, xr, None], band_l.census[:, xl])
    words[:, : dmax + 1, off + 3] = qtables.census[h].reshape(p, dmax + 1)
    lanes = np.broadcast_to(valid[None], (n, *valid.shape)).reshape(p, dmax + 1)
    words[:, : dmax + 1, off:] *= lanes[:, :, None]
    if model.lr_right_nomatch:  # the census model's no-match row, of the right pixel's gV
        words[:, dmax + 1, off] = qtables.nomatch[np.abs(band_r.gv20[:, xr])].reshape(p)
        words[:, dmax + 1, off + 1 : off + 3] = qtables.one
        words[:, dmax + 1, off + 3] = qtables.census_nomatch
    pw = np.asarray(prior)
    if pw.shape != (p, model.hypotheses):
        raise ValueError(f"prior words must have shape {(p, model.hypotheses)}, got {pw.shape}")
    words[:, :, 0] = pw
    return words


def memory_words_plain(
    left: FeatureSums, right: FeatureSums, model: ModelParams, machine: MachineParams
) -> np.ndarray:
    """The same words from the plain formula (a test oracle for ``memory_words``; uniform prior)."""
    if model.lr:
        raise ValueError("memory_words_plain: the census-lr model's consistency column needs the right pass")
    check_disparity_machine(model, machine)
    off = machine.loaded_columns - machine.columns
    lik, nm = likelihoods_plain(left, right, model)
    p = lik.shape[0] * lik.shape[1]
    one = 1 << machine.word_bits
    words = np.full((p, model.hypotheses, machine.loaded_columns), one, dtype=np.uint16)
    cols = model.columns
    words[:, : model.dmax + 1, off:] = quantize(lik, machine.word_bits).reshape(p, model.dmax + 1, cols)
    words[:, model.dmax + 1, off] = quantize(nm, machine.word_bits).reshape(p)
    if model.census:
        l_nm = likelihood_formula(np.int64(model.h_nm), 1, model.census_p0, model.sigma_c)
        words[:, model.dmax + 1, off + 3] = quantize(l_nm, machine.word_bits)
    return words
