"""The disparity model's likelihoods (paper eq. 2 and 4) and their quantization to memory words.

Pure computation (NumPy only), shared by the host, which builds likelihood memories per
pixel, and the on-chip front end, which needs the same tables at elaboration.

The likelihood of a feature f at disparity d is ``p0 + (1-p0) exp(-C / (2 sigma_f^2))`` with
``C = (f_l(x,y) - f_r(x-d,y))^2``. The features are kept as integer sums (``f = s / k``,
k in :data:`SCALES`), so C is ``delta^2 / k^2`` with ``delta`` an integer difference of sums
and the likelihood depends only on |delta|: one lookup table per feature, indexed by
|delta|, gives exactly the value the formula gives (same float operations on the same
operands). The no-match probability ``p_nm0 + (1-p_nm0) exp(-gV_l^2 / (2 sigma_nm^2))`` is a
table indexed by |gv20|.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from numbers import Real

import numpy as np

from bayesmachine.params import DEFAULT_DMAX, ParameterError

__all__ = [
    "FEATURES",
    "SCALES",
    "MAX_ABS",
    "ModelParams",
    "LikelihoodTables",
    "likelihood_tables",
    "likelihood_formula",
    "quantize",
    "QuantizedTables",
]

FEATURES = ("m", "gh", "gv")
# Integer scale of each stored feature: f = sum / scale (5x5 mean: 25; gradients: 2 x 2 x 5 = 20).
SCALES = {"m": 25, "gh": 20, "gv": 20}
# Largest |sum| each feature can reach for 8-bit input (sizes the lookup tables).
MAX_ABS = {"m": 25 * 255, "gh": 10 * 255, "gv": 10 * 255}

# The command-line spelling of each model parameter, for error messages.
OPTION_NAMES = {
    "dmax": "--dmax",
    "p0": "--p0",
    "sigma_m": "--sigma-m/--sigma",
    "sigma_gh": "--sigma-gh/--sigma",
    "sigma_gv": "--sigma-gv/--sigma",
    "p_nm0": "--p-nm0",
    "sigma_nm": "--sigma-nm",
}


def _error(name: str, text: str) -> ParameterError:
    return ParameterError(f"{OPTION_NAMES[name]}: {name} {text}")


@dataclass(frozen=True)
class ModelParams:
    """The Bayesian disparity model of the paper (table 1 defaults), validated up front.

    Each check is what the computation needs: probabilities in [0, 1] (p_nm0 > 0, the
    floor that keeps every posterior defined) and sigmas whose ``2 sigma^2`` is a finite
    positive float64 (a sigma of 1e-300 would square to 0 and give NaN likelihoods).
    """

    dmax: int = DEFAULT_DMAX
    p0: float = 0.02
    sigma_m: float = 10.0
    sigma_gh: float = 10.0
    sigma_gv: float = 10.0
    p_nm0: float = 0.01
    sigma_nm: float = 8.0

    def __post_init__(self) -> None:
        if isinstance(self.dmax, bool) or not isinstance(self.dmax, int) or not 0 <= self.dmax <= 4094:
            raise _error("dmax", f"must be an integer in [0, 4094], got {self.dmax!r}")
        for name in ("p0", "p_nm0"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, Real) or not 0.0 <= float(v) <= 1.0:
                raise _error(name, f"must be a probability in [0, 1], got {v!r}")
        if not self.p_nm0 > 0:
            # The floor of the no-match hypothesis keeps every pixel's posterior defined: without
            # it, a pixel whose likelihoods all underflow to 0 would have 0/0.
            raise _error("p_nm0", "must be > 0: it keeps every pixel's posterior defined")
        for name in ("sigma_m", "sigma_gh", "sigma_gv", "sigma_nm"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, Real) or not (math.isfinite(v) and v > 0):
                raise _error(name, f"must be a finite number > 0, got {v!r}")
            two_s2 = 2.0 * float(v) * float(v)
            if not (math.isfinite(two_s2) and two_s2 > 0.0):
                raise _error(
                    name, f"= {v!r}: 2 sigma^2 = {two_s2!r} is not a finite positive float64 "
                    "(use a sigma between about 1e-150 and 1e150)"
                )

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
    """The per-feature lookup tables replacing exp in the fast paths; every value in [0, 1]."""
    tabs = {}
    for f in FEATURES:
        # |f_l - f_r| over 8-bit images is at most twice the largest |sum| of a signed
        # feature (gradients) or the largest sum (the mean, which is never negative).
        n = MAX_ABS[f] + 1 if f == "m" else 2 * MAX_ABS[f] + 1
        tabs[f] = likelihood_formula(np.arange(n), SCALES[f], model.p0, model.sigma(f))
    nm = likelihood_formula(np.arange(MAX_ABS["gv"] + 1), SCALES["gv"], model.p_nm0, model.sigma_nm)
    tables = LikelihoodTables(tabs["m"], tabs["gh"], tabs["gv"], nm)
    for name, tab in (("sigma_m", tables.m), ("sigma_gh", tables.gh), ("sigma_gv", tables.gv),
                      ("sigma_nm", tables.nomatch)):
        if not ((tab >= 0.0) & (tab <= 1.0)).all():  # NaN fails both comparisons
            raise _error(name, f"= {getattr(model, name)!r} gives likelihoods outside [0, 1]")
    return tables


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


class QuantizedTables:
    """The likelihood tables quantized once to the machine's word (the fast word path)."""

    def __init__(self, tables: LikelihoodTables, word_bits: int) -> None:
        self.m = quantize(tables.m, word_bits)
        self.gh = quantize(tables.gh, word_bits)
        self.gv = quantize(tables.gv, word_bits)
        self.nomatch = quantize(tables.nomatch, word_bits)
        self.one = 1 << word_bits
