"""The gradient-magnitude column: its table at the difference of |gH| + |gV| of the reference pixel and
of each lane's match, formed from the gH and gV planes the feature filter already gives (no filter of
its own)."""

from __future__ import annotations

from amaranth.hdl import ShapeLike, Signal, Value, signed, unsigned

from bayesmachine.columns import GradMag, PlaneColumn

from .base import PlaneFilter, PlaneLanes, register
from .features import feature_planes

__all__ = ["GradMagLanes"]

PLANES = ("gh20", "gv20")
G_BITS = 13  # |gh20| + |gv20| <= 2 x 2550 < 2^13


@register(GradMag)
class GradMagLanes(PlaneLanes):
    """Per lane row the cost g_ref - g_match, g = |gh20| + |gv20| (a 14-bit signed difference)."""

    symmetric = True

    @classmethod
    def filter(cls, term: PlaneColumn, margin: int) -> PlaneFilter:
        return feature_planes(margin)

    @classmethod
    def planes(cls, term: PlaneColumn, margin: int) -> dict[str, ShapeLike]:
        shapes = feature_planes(margin).shapes
        return {name: shapes[name] for name in PLANES}

    def _magnitude(self, planes: list[Value], name: str) -> Signal:
        g = Signal(unsigned(G_BITS), name=name)
        self.ctx.m.d.comb += g.eq(abs(planes[0]) + abs(planes[1]))
        return g

    def costs(self) -> list[Value]:
        n = self.ctx
        ref = self._magnitude([getattr(n.left, p) for p in PLANES], "g_ref")
        costs = []
        for j in range(n.rows_per_beat):
            match = self._magnitude([n.entry(p, j) for p in PLANES], f"g_match{j}")
            cost = Signal(signed(G_BITS + 1), name=f"g_cost{j}")
            n.m.d.comb += cost.eq(ref - match)
            costs.append(cost)
        return costs
