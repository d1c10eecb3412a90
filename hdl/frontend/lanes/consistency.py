"""The consistency column (census-lr's left pass): row d 1.0 or beta by lane d's window test on the
other pass's MAP d_R(x - d) (:class:`~..lr.ConsistencyTest`, fed one MAP per pixel at a map column of an
output row through the ``<pass>_map`` port), the no-match row gamma when any lane is consistent, else 1.0
(0 without its no-match entry)."""

from __future__ import annotations

from typing import Any

from amaranth.hdl import Cat, Const, Mux, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In

from bayesmachine.columns import Consistency
from bayesmachine.params import MachineParams

from .base import Lanes, register

__all__ = ["ConsistencyLanes", "map_port"]


def map_port(term: Any) -> str:
    """The generator's port of the MAPs the column reads (``right_map``)."""
    return f"{term.feeds_from}_map"


@register(Consistency)
class ConsistencyLanes(Lanes):
    """A pixel whose ``consult`` is set takes the next MAP into the test, and waits for it."""

    @classmethod
    def flags(cls, term: Any) -> tuple[str, ...]:
        return ("consult",)

    @classmethod
    def members(cls, term: Any, params: MachineParams) -> dict[str, wiring.Member]:
        from ..lr import right_map_layout

        return {map_port(term): In(stream.Signature(right_map_layout(params.map_width)))}

    def build(self) -> None:
        from ..lr import ConsistencyTest

        n, c = self.nets, self.term
        self._maps = maps = getattr(n.generator, map_port(c))
        n.m.submodules.consistency = test = ConsistencyTest(dmax=n.dmax, map_width=n.params.map_width,
                                                            tolerance=c.tolerance)
        shift = n.take & n.pixel.consult
        n.m.d.comb += [test.shift.eq(shift), test.entry.eq(maps.payload), maps.ready.eq(shift)]
        # Padded with 0 to every row a beat can reach (rows past Dmax are not read). A lane reading a
        # pixel without a MAP is neutral (factor 1) with lr_neutral.
        one_bits = test.consistent | test.unknown if c.neutral else test.consistent
        bits = Cat(one_bits, Const(0, n.n_beats * n.rows_per_beat))
        self._consistent = [n.aligned(bits.bit_select(n.row(j), 1), f"consistent{j}")
                            for j in range(n.rows_per_beat)]
        self._any = n.aligned(test.any, "any_consistent")
        q = c.table(n.params.word_bits)
        self._beta, self._gamma = int(q.values[1]), int(q.nomatch[0])

    def ready(self) -> Value:
        return ~self.nets.pixel.consult | self._maps.valid

    def word(self, j: int) -> Any:
        return Mux(self._consistent[j], self.nets.one, self._beta)

    def nomatch(self) -> Any:
        return Mux(self._any, self._gamma, self.nets.one) if self.term.has_nomatch else 0
