"""The gradient-magnitude column: the paper's likelihood of the windows' L1 gradient magnitudes.

Plane ``g20`` = |gH| + |gV| of the 5x5 sums (scale 20, as the gradients'), so the cost of lane d is
``|g_l(x) - g_r(x - d)|`` (at most 2 x 2550 for 8-bit images) and the likelihood ``p0 + (1-p0)
exp(-C / (2 sigma_g^2))`` with ``C = delta^2 / 20^2``: one table indexed by |delta|. Its no-match entry
is 1. On the host its plane has a filter of its own (:func:`~.planes.gradmag_sums`); on chip it needs no
new filter: the front end's lane builder forms |gH| + |gV| of the reference and of each lane's match from
the gH and gV planes in its delay line. The paper model has it when its switch :data:`GRADIENT_MAGNITUDE`
is on (off by default: every default result unchanged); a model may also list it outright.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .base import Option, PlaneColumn, check_sigma, check_switch, likelihood_formula
from .features import MAX_ABS, P0, SCALES
from .planes import G20, Plane

__all__ = ["GRADIENT_MAGNITUDE", "GradMag"]


def _sigma(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_sigma(name, value)


# The paper model's switch that adds the column (a model's switch, ModelDef.switches).
GRADIENT_MAGNITUDE = Option("gradient_magnitude", "bool", False, check_switch,
                            "a column of the windows' gradient magnitude |gH| + |gV| (off: the model's own "
                            "columns alone)")


class GradMag(PlaneColumn):
    """The gradient-magnitude column (``plane`` "g20": |gh20| + |gv20| of both images)."""

    name = "g"
    plane = G20.name
    scale = SCALES["gh"]
    options = (P0, Option("sigma_g", "float", 10.0, _sigma, "sigma of the gradient-magnitude column"))
    table_parameter = "sigma_g"

    def planes(self) -> dict[str, Plane]:
        return {self.plane: G20}

    def cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.abs(a - b)

    def plain_cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return a.astype(np.int64) - b.astype(np.int64)  # signed: the formula squares it

    def costs(self) -> np.ndarray:
        return np.arange(MAX_ABS["gh"] + MAX_ABS["gv"] + 1)  # g is in [0, 2550 + 2550]

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        return likelihood_formula(cost, self.scale, float(self.values["p0"]), float(self.values["sigma_g"]))
