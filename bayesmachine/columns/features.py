"""The paper's feature columns m, gH, gV (paper eq. 2) and the no-match row's floor (eq. 4).

The features are kept as integer sums (``f = s / k``, k in :data:`SCALES`), so the cost of lane d is
``|s_l(x) - s_r(x - d)|`` and the likelihood ``p0 + (1-p0) exp(-C / (2 sigma_f^2))`` with
``C = delta^2 / k^2`` depends on it alone: one table per feature, indexed by |delta|, gives exactly
what the formula gives. The no-match row's floor ``p_nm0 + (1-p_nm0) exp(-gV_l^2 / (2 sigma_nm^2))`` is a
table indexed by the reference pixel's |gv20|; a pass's no-match row holds it in its first column.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from bayesmachine.errors import ParameterError

from .base import (
    Option,
    PassContext,
    PlaneColumn,
    Term,
    check_probability,
    check_sigma,
    likelihood_formula,
    quantize,
)
from .planes import SUM_PLANES, Plane

__all__ = ["FEATURES", "SCALES", "MAX_ABS", "FeatureColumn", "Mean", "GradH", "GradV", "NoMatchFloor",
           "FEATURE_COLUMNS"]

FEATURES = ("m", "gh", "gv")
# Integer scale of each stored feature: f = sum / scale (5x5 mean: 25; gradients: 2 x 2 x 5 = 20).
SCALES = {"m": 25, "gh": 20, "gv": 20}
# Largest |sum| each feature can reach for 8-bit input (sizes the lookup tables).
MAX_ABS = {"m": 25 * 255, "gh": 10 * 255, "gv": 10 * 255}


def _probability(name: str, value: object, values: object) -> None:
    check_probability(name, value)


def _sigma(name: str, value: object, values: object) -> None:
    check_sigma(name, value)


P0 = Option("p0", "float", 0.02, _probability, "base match likelihood p0 of the m, gH and gV columns")
SIGMAS = {f: Option(f"sigma_{f}", "float", 10.0, _sigma, f"sigma of the {what} feature", alias="--sigma")
          for f, what in (("m", "mean"), ("gh", "horizontal gradient"), ("gv", "vertical gradient"))}


class FeatureColumn(PlaneColumn):
    """A 5x5 feature's column: cost |difference of the two pixels' sums|, the paper's likelihood.

    A subclass names its feature (``class Mean(FeatureColumn, feature="m")``): its plane
    (:data:`~.planes.SUM_PLANES`: ``m25``), its options (``p0``, shared by the three, and ``sigma_m``)
    follow."""

    feature: ClassVar[str]

    def __init_subclass__(cls, feature: str, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.name = cls.feature = feature
        cls.plane = SUM_PLANES[feature].name
        cls.options = (P0, SIGMAS[feature])
        cls.table_parameter = f"sigma_{feature}"

    def planes(self) -> dict[str, Plane]:
        return {self.plane: SUM_PLANES[self.feature]}

    @property
    def scale(self) -> int:
        return SCALES[self.feature]

    @property
    def sigma(self) -> float:
        return float(self.values[f"sigma_{self.feature}"])

    def cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.abs(a - b)

    def plain_cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return a.astype(np.int64) - b.astype(np.int64)  # signed: the formula squares it

    def costs(self) -> np.ndarray:
        # |f_l - f_r| over 8-bit images is at most twice the largest |sum| of a signed feature (the
        # gradients) or the largest sum (the mean, never negative).
        top = MAX_ABS[self.feature] if self.feature == "m" else 2 * MAX_ABS[self.feature]
        return np.arange(top + 1)

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        return likelihood_formula(cost, self.scale, float(self.values["p0"]), self.sigma)


class Mean(FeatureColumn, feature="m"):
    """The 5x5 window's mean."""


class GradH(FeatureColumn, feature="gh"):
    """The horizontal gradient: the window's two right columns minus its two left ones."""


class GradV(FeatureColumn, feature="gv"):
    """The vertical gradient: the window's two bottom rows minus its two top ones."""


FEATURE_COLUMNS: tuple[type[FeatureColumn], ...] = (Mean, GradH, GradV)


def _floor(name: str, value: object, values: object) -> None:
    # The floor of the no-match hypothesis keeps every pixel's posterior defined: without it, a pixel
    # whose likelihoods all underflow to 0 would have 0/0.
    check_probability(name, value, positive="it keeps every pixel's posterior defined")


class NoMatchFloor(Term):
    """The paper's no-match row (eq. 4): ``P_nm(gV)`` of the reference pixel in the pass's first column,
    the other columns' own no-match entries beside it ([P_nm(gV), 1, 1] for the paper's three)."""

    name = "nomatch"
    plane = SUM_PLANES["gv"].name
    options = (
        Option("p_nm0", "float", 0.01, _floor, "base no-match probability p_nm0"),
        Option("sigma_nm", "float", 8.0, _sigma, "no-match sigma"),
    )
    table_parameter = "sigma_nm"

    def planes(self) -> dict[str, Plane]:
        return {self.plane: SUM_PLANES["gv"]}

    def costs(self) -> np.ndarray:
        return np.arange(MAX_ABS["gv"] + 1)

    def cost(self, gv: np.ndarray) -> np.ndarray:
        return np.abs(gv)

    def floor(self, ctx: PassContext) -> np.ndarray:
        """Its value (P,) for each of the pass's pixels of ``ctx``: its table at the reference pixel's
        |gV| (the entry of the pass's first FEATURES column in the no-match row)."""
        values = self.table(ctx.word_bits).values[self.cost(ctx.reference[self.plane][:, ctx.columns])]
        return values.reshape(-1)

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        v = self.values
        return likelihood_formula(cost, SCALES["gv"], float(v["p_nm0"]), float(v["sigma_nm"]))

    def check_machine(self, machine: Any) -> None:
        # Then an occluded pixel (every row ~0) could only stop at the watchdog, max_cycles later.
        w, p = machine.word_bits, float(self.values["p_nm0"])
        if int(quantize(p, w)) == 0:
            raise ParameterError(f"p_nm0: {p} quantizes to 0 with {w}-bit words, so a pixel with no match "
                                 f"could not stop before the watchdog; raise word_bits or p_nm0 "
                                 f"(p_nm0 >= 2^-{w + 1})", "p_nm0")
