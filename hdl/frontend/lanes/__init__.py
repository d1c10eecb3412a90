"""One lane builder per column kind (:mod:`.base`: the contract and the registry; :mod:`.context`: the
typed view of the word generator's pipeline a lane builder builds on). Importing the package
registers every kind's: :mod:`.features` (m, gH, gV and the no-match floor), :mod:`.census`,
:mod:`.prior` (the left and above neighbours), :mod:`.consistency`, :mod:`.gradient` (the gradient
magnitude), :mod:`.fused` (the fused column), :mod:`.semiglobal` (the semi-global column over a fused
one)."""

from . import census, consistency, features, fused, gradient, prior, semiglobal
from .base import Lanes, PlaneFilter, PlaneLanes, lanes_for, register
from .context import LaneContext

__all__ = ["LaneContext", "Lanes", "PlaneFilter", "PlaneLanes", "census", "consistency", "features", "fused",
           "gradient", "lanes_for", "prior", "register", "semiglobal"]
