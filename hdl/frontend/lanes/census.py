"""The census column: its table at the Hamming distance of the two census codes."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import ShapeLike, Value, unsigned
from amaranth.lib import wiring

from bayesmachine.columns import Census, PlaneColumn

from ..census import CensusFilter
from .base import PlaneFilter, PlaneLanes, register

__all__ = ["CensusLanes", "CensusPlanes", "popcount"]


def popcount(value: Value) -> Value:
    """The number of set bits of ``value``, as a balanced adder tree."""
    terms: list[Value] = [value[i] for i in range(len(value))]
    if not terms:
        return Value.cast(0)
    while len(terms) > 1:
        terms = [terms[i] + terms[i + 1] if i + 1 < len(terms) else terms[i] for i in range(0, len(terms), 2)]
    return terms[0]


@dataclass(frozen=True)
class CensusPlanes(PlaneFilter):
    """The census codes of ``window`` x ``window`` windows (:class:`~..census.CensusFilter`)."""

    window: int

    @property
    def name(self) -> str:
        return "census"

    @property
    def height(self) -> int:
        return self.window

    @property
    def shapes(self) -> dict[str, ShapeLike]:
        return {"census": unsigned(self.window * self.window - 1)}

    def build(self) -> wiring.Component:
        return CensusFilter(window=self.window)

    def outputs(self, filt: wiring.Component) -> dict[str, Value]:
        return {"census": filt.code}


@register(Census)
class CensusLanes(PlaneLanes):
    """The census column: its table at popcount(reference code xor match code); its no-match entry the
    table at ``census_nomatch_h``."""

    symmetric = True

    @classmethod
    def filter(cls, term: PlaneColumn, margin: int) -> PlaneFilter:
        assert isinstance(term, Census)
        return CensusPlanes(window=term.window)

    def cost(self, ref: Value, match: Value) -> Value:
        return popcount(ref ^ match)
