"""Likelihoods (paper eq. 2 and 4), their quantization, and the likelihood-memory words.

The likelihood of a feature f at disparity d is ``p0 + (1-p0) exp(-C / (2 sigma_f^2))`` with
``C = (f_l(x,y) - f_r(x-d,y))^2``. Because the host keeps the features as integer sums
(``f = s / k``), C is ``delta^2 / k^2`` with ``delta`` an integer difference of sums, so the
likelihood depends only on |delta|: one lookup table per feature, indexed by |delta|,
gives exactly the value the formula gives (same float operations on the same operands).
The no-match probability ``p_nm0 + (1-p_nm0) exp(-gV_l^2 / (2 sigma_nm^2))`` is a table
indexed by |gv20|.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from bayesmachine.params import MachineParams

from .features import MAX_ABS, SCALES, FeatureSums

__all__ = [
    "ModelParams",
    "LikelihoodTables",
    "likelihood_tables",
    "likelihood_formula",
    "likelihoods_plain",
    "quantize",
    "output_shape",
    "memory_words",
    "memory_words_plain",
]

FEATURES = ("m", "gh", "gv")


@dataclass(frozen=True)
class ModelParams:
    """The Bayesian disparity model of the paper (table 1 defaults), validated up front."""

    dmax: int = 80
    p0: float = 0.02
    sigma_m: float = 10.0
    sigma_gh: float = 10.0
    sigma_gv: float = 10.0
    p_nm0: float = 0.01
    sigma_nm: float = 8.0

    def __post_init__(self) -> None:
        if isinstance(self.dmax, bool) or not isinstance(self.dmax, int) or not 0 <= self.dmax <= 4094:
            raise ValueError(f"dmax must be an integer in [0, 4094], got {self.dmax!r}")
        for name in ("p0", "p_nm0"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not 0.0 <= float(v) <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {v!r}")
        if not self.p_nm0 > 0:
            # The floor of the no-match hypothesis keeps every pixel's posterior defined: without
            # it, a pixel whose likelihoods all underflow to 0 would have 0/0.
            raise ValueError("p_nm0 must be > 0: it keeps every pixel's posterior defined")
        for name in ("sigma_m", "sigma_gh", "sigma_gv", "sigma_nm"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")

    @property
    def hypotheses(self) -> int:
        """Dmax + 2: disparities 0..Dmax and no match (the machine's rows M)."""
        return self.dmax + 2

    def sigma(self, feature: str) -> float:
        return float(getattr(self, f"sigma_{feature}"))

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def likelihood_formula(delta: np.ndarray, scale: int, p0: float, sigma: float) -> np.ndarray:
    """Eq. 2 from integer differences of sums: C = delta^2 / scale^2, exact in float64.

    Both the lookup tables and the plain oracle go through this one function, so the
    two give bit-identical likelihoods.
    """
    d = np.asarray(delta, dtype=np.int64)
    cost = (d * d) / float(scale * scale)
    return p0 + (1.0 - p0) * np.exp(-cost / (2.0 * sigma * sigma))


@dataclass(frozen=True)
class LikelihoodTables:
    """float64 tables indexed by |delta| (features) and |gv20| (no match)."""

    m: np.ndarray
    gh: np.ndarray
    gv: np.ndarray
    nomatch: np.ndarray


def likelihood_tables(model: ModelParams) -> LikelihoodTables:
    """The per-feature lookup tables replacing exp in the fast paths."""
    tabs = {}
    for f in FEATURES:
        # |f_l - f_r| over 8-bit images is at most twice the largest |sum| of a signed
        # feature (gradients) or the largest sum (the mean, which is never negative).
        n = MAX_ABS[f] + 1 if f == "m" else 2 * MAX_ABS[f] + 1
        tabs[f] = likelihood_formula(np.arange(n), SCALES[f], model.p0, model.sigma(f))
    nm = likelihood_formula(np.arange(MAX_ABS["gv"] + 1), SCALES["gv"], model.p_nm0, model.sigma_nm)
    return LikelihoodTables(tabs["m"], tabs["gh"], tabs["gv"], nm)


def output_shape(feature_shape: tuple[int, int], dmax: int) -> tuple[int, int]:
    """Output region in map pixels: all map rows, map columns dmax .. W-5."""
    h4, w4 = feature_shape
    return h4, w4 - dmax


def likelihoods_plain(
    left: FeatureSums, right: FeatureSums, model: ModelParams
) -> tuple[np.ndarray, np.ndarray]:
    """All likelihoods by the plain vectorized formula (the test oracle).

    Returns ``lik`` (Ho, Wo, Dmax+1, 3) float64 (features m, gH, gV) and ``nomatch`` (Ho, Wo).
    """
    dmax = model.dmax
    h4, w4 = left.shape
    wo = w4 - dmax
    x = np.arange(dmax, w4)
    d = np.arange(dmax + 1)
    xr = x[:, None] - d[None, :]  # (Wo, D+1) right-map column of each hypothesis
    lik = np.empty((h4, wo, dmax + 1, 3))
    for k, f in enumerate(FEATURES):
        fl = getattr(left, f"{f}{SCALES[f]}")
        fr = getattr(right, f"{f}{SCALES[f]}")
        delta = fl[:, dmax:, None].astype(np.int64) - fr[:, xr].astype(np.int64)
        lik[..., k] = likelihood_formula(delta, SCALES[f], model.p0, model.sigma(f))
    nomatch = likelihood_formula(left.gv20[:, dmax:], SCALES["gv"], model.p_nm0, model.sigma_nm)
    return lik, nomatch


def quantize(p: np.ndarray | float, word_bits: int) -> np.ndarray:
    """Probability -> likelihood-memory word: q = round(p * 2^W), round half up, in [0, 2^W].

    ``p * 2^W`` is exact in float64 (a power-of-two scaling) and so is its fractional part,
    so "half up" is decided exactly (``floor(x + 0.5)`` would not be: 0.5 - 2^-54 + 0.5 rounds
    to 1.0). 0 maps to 0 and 1 to 2^W. Values outside [0, 1]
    or NaN are errors (they mean a bug upstream, not something to clip silently).
    """
    if not 1 <= word_bits <= 15:
        raise ValueError(f"word_bits must be in [1, 15] (words up to 2^15 fit uint16), got {word_bits}")
    arr = np.asarray(p, dtype=np.float64)
    bad = ~((arr >= 0.0) & (arr <= 1.0))  # NaN compares false, so it lands here too
    if bad.any():
        first = arr[bad].flat[0]
        raise ValueError(f"probabilities must be in [0, 1] to quantize, got {first!r} ({int(bad.sum())} bad)")
    one = 1 << word_bits
    scaled = arr * one
    q = np.floor(scaled)
    q += (scaled - q) >= 0.5
    return np.clip(q, 0, one).astype(np.uint16)


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


class QuantizedTables:
    """The likelihood tables quantized once to the machine's word (the fast word path)."""

    def __init__(self, tables: LikelihoodTables, word_bits: int) -> None:
        self.m = quantize(tables.m, word_bits)
        self.gh = quantize(tables.gh, word_bits)
        self.gv = quantize(tables.gv, word_bits)
        self.nomatch = quantize(tables.nomatch, word_bits)
        self.one = 1 << word_bits


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
    rows = rows if rows is not None else slice(None)
    h4, w4 = left.shape
    x = np.arange(dmax, w4)
    xr = x[:, None] - np.arange(dmax + 1)[None, :]
    lm, lgh, lgv = (a[rows] for a in left.as_tuple())
    rm, rgh, rgv = (a[rows] for a in right.as_tuple())
    n_rows = lm.shape[0]
    p = n_rows * (w4 - dmax)
    words = np.empty((p, model.hypotheses, machine.operator_columns), dtype=np.uint16)
    for k, (fl, fr, tab) in enumerate(((lm, rm, qtables.m), (lgh, rgh, qtables.gh), (lgv, rgv, qtables.gv))):
        delta = np.abs(fl[:, dmax:, None] - fr[:, xr])
        words[:, : dmax + 1, off + k] = tab[delta].reshape(p, dmax + 1)
    words[:, dmax + 1, off] = qtables.nomatch[np.abs(lgv[:, dmax:])].reshape(p)
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
