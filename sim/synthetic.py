"""Synthetic likelihood memories shaped like the paper's, for tests and benchmarks without images."""

from __future__ import annotations

import numpy as np

from bayesmachine.params import MachineParams

__all__ = ["synthetic_disparity_words"]


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
