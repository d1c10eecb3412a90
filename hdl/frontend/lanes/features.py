"""The paper's feature columns (m, gH, gV: a feature's difference of 5x5 sums) and the no-match rule's
floor (the no-match table at the reference pixel's |gV|)."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import ShapeLike, Value, ValueLike
from amaranth.lib import wiring

from bayesmachine.columns import FeatureColumn, NoMatchFloor, PlaneColumn, Term

from ..filters import FeatureFilter, feature_layout
from ..linebuffer import WINDOW
from .base import Lanes, PlaneFilter, PlaneLanes, register

__all__ = ["FeatureLanes", "FeaturePlanes", "FloorLanes"]


@dataclass(frozen=True)
class FeaturePlanes(PlaneFilter):
    """The 5x5 feature sums (:class:`~..filters.FeatureFilter`), ``lag`` columns behind a larger window's
    centre (a model of margin 3: 1)."""

    lag: int

    @property
    def name(self) -> str:
        return "filter"

    @property
    def height(self) -> int:
        return WINDOW

    @property
    def shapes(self) -> dict[str, ShapeLike]:
        return dict(feature_layout().members)

    def build(self) -> wiring.Component:
        return FeatureFilter(lag=self.lag)

    def outputs(self, filt: wiring.Component) -> dict[str, Value]:
        return {name: getattr(filt.features, name) for name in self.shapes}


def feature_planes(margin: int) -> FeaturePlanes:
    return FeaturePlanes(lag=margin - WINDOW // 2)


@register(FeatureColumn)
class FeatureLanes(PlaneLanes):
    """A feature column: its table at |reference sum - match sum|."""

    symmetric = True

    @classmethod
    def filter(cls, term: PlaneColumn, margin: int) -> PlaneFilter:
        return feature_planes(margin)

    def cost(self, ref: Value, match: Value) -> Value:
        return ref - match


@register(NoMatchFloor)
class FloorLanes(Lanes):
    """The no-match rule: the floor P_nm(gV) of the reference pixel, its table at |gV| (one read per
    pixel), in the no-match row of the pass's first FEATURES column."""

    @classmethod
    def filters(cls, term: Term, margin: int) -> tuple[PlaneFilter, ...]:
        return (feature_planes(margin),)

    @classmethod
    def planes(cls, term: Term, margin: int) -> dict[str, ShapeLike]:
        return {term.plane: feature_planes(margin).shapes[term.plane]}

    def build(self) -> None:
        n, t = self.ctx, self.term
        self._word = n.lookup(t.name, n.tables[t.name], [getattr(n.left, t.plane)])[0]

    def nomatch(self) -> ValueLike:
        return self._word
