"""The consistency column (a ``consistency(name)`` kind: census-lr's ``consistency("right")``): row d
1.0 or beta by lane d's window test on the other pass's MAP d_R(x - d) (:class:`ConsistencyTest`, fed one
MAP per pixel at a map column of an output row through the generator's ``<pass>_maps`` port), the
no-match row gamma when any lane is consistent, else 1.0 (0 without its no-match entry).

The pass it reads (``Consistency.feeds_from``: a pass of any name the model declares) must be one the
model runs before its own pass, with the right image as reference: its MAPs then cover every map column
of an output row (0 .. W - 2k - 1), one per pixel the own pass consults. Its own pass must be the model's
own (a declared pass reading another would need that pass's MAPs in its own order)."""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, ValueLike
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.columns import Consistency, Term
from bayesmachine.errors import ParameterError
from bayesmachine.hdl.signatures import map_layout, map_stream
from bayesmachine.models import ModelParams, Pass
from bayesmachine.params import MachineParams

from .base import Lanes, register

__all__ = ["ConsistencyLanes", "ConsistencyTest", "map_port"]


def map_port(term: Term) -> str:
    """The generator's port of the MAPs the column reads: ``<pass>_maps`` (census-lr: ``right_maps``)."""
    return f"{term.feeds_from}_maps"


class ConsistencyTest(wiring.Component):
    """The own pass's view of the other pass's MAPs: entry d = d_R(x - d), and each lane's window test.

    Parameters
    ----------
    dmax : int
        The largest disparity (0 .. 4094).
    map_width : int
        Bits of a MAP (the other pass's machine's ``map_width``).
    tolerance : int
        The window's half-width (``ModelParams.lr_tolerance``).

    Attributes
    ----------
    shift : ``In(1)``
        Shift ``entry`` in (as entry 0; entry d moves to d + 1).
    entry : ``In(map_layout(map_width))``
        The MAP of the next map column.
    consistent : ``Out(dmax + 1)``
        Bit d: entry d is a disparity and ``|entry d - d| <= tolerance`` (combinational from the
        shift register).
    any : ``Out(1)``
        Some lane is consistent.
    unknown : ``Out(dmax + 1)``
        Bit d: entry d is no MAP (the other pass's no match or timeout: with ``lr_neutral`` the lane
        is neutral; twin :func:`~bayesmachine.columns.lr_unknown`).
    """

    def __init__(self, *, dmax: int, map_width: int, tolerance: int) -> None:
        dmax, map_width, tolerance = (as_int(name, value, low, high) for name, value, low, high in (
            ("dmax", dmax, 0, 4094), ("map_width", map_width, 1, 16), ("tolerance", tolerance, 0, 4094)))
        self._dmax, self._map_width, self._tolerance = dmax, map_width, tolerance
        super().__init__({
            "shift": In(1),
            "entry": In(map_layout(map_width)),
            "consistent": Out(dmax + 1),
            "any": Out(1),
            "unknown": Out(dmax + 1),
        })

    @property
    def dmax(self) -> int:
        return self._dmax

    @property
    def map_width(self) -> int:
        return self._map_width

    @property
    def tolerance(self) -> int:
        return self._tolerance

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dmax, t = self._dmax, self._tolerance
        layout = map_layout(self._map_width)
        # Reset: no MAP (a frame's first pixels read entries of the row's own other pass only).
        line = [Signal(layout, name=f"right_map_{d}") for d in range(dmax + 1)]
        with m.If(self.shift):
            m.d.sync += line[0].eq(self.entry)
            m.d.sync += [line[d].eq(line[d - 1]) for d in range(1, dmax + 1)]
        bits = []
        for d, e in enumerate(line):
            # |map - d| <= t as two comparisons against constants (no subtractor), each left out where
            # the MAP's range makes it always true (verilator -Wall: no constant comparison).
            inside = Const(1)
            if d + t < (1 << self._map_width) - 1:
                inside = inside & (e.map <= d + t)
            if d - t > 0:
                inside = inside & (e.map >= d - t)
            bits.append(e.hit & inside)
        m.d.comb += [self.consistent.eq(Cat(*bits)), self.any.eq(Cat(*bits).any()),
                     self.unknown.eq(~Cat(*(e.hit for e in line)))]
        return m


@register(Consistency)
class ConsistencyLanes(Lanes):
    """A pixel whose ``consult`` is set takes the next MAP into the test, and waits for it."""

    @classmethod
    def flags(cls, term: Term) -> tuple[str, ...]:
        return ("consult",)

    @classmethod
    def members(cls, term: Term, params: MachineParams) -> dict[str, wiring.Member]:
        return {map_port(term): In(map_stream(params))}

    @classmethod
    def check(cls, term: Term, model: ModelParams, p: Pass) -> None:
        name = term.feeds_from
        fed = next((q for q in model.passes[:-1] if q.name == name), None)
        if p is not model.passes[-1]:
            raise ParameterError(f"model: the {p.name} pass's {term.name} column reads the {name} pass's "
                                 "MAPs; on chip only the model's own pass reads another pass's", "model")
        if fed is None:
            raise ParameterError(f"model: the {term.name} column reads the MAPs of a {name} pass, which the "
                                 f"{model.name} model does not run before its own", "model")
        if fed.reference != "right":
            raise ParameterError(f"model: the {term.name} column reads the {name} pass's MAPs; on chip it "
                                 f"reads a pass with the right image as reference (one MAP per map column "
                                 f"of a row), not the {fed.reference!r}", "model")

    def build(self) -> None:
        n, c = self.ctx, self.term
        self._maps = maps = n.map_stream(map_port(c))
        n.m.submodules[f"{c.feeds_from}_consistency"] = test = ConsistencyTest(
            dmax=n.dmax, map_width=n.params.map_width, tolerance=c.tolerance)
        shift = n.take & n.pixel.consult
        n.m.d.comb += [test.shift.eq(shift), test.entry.eq(maps.payload), maps.ready.eq(shift)]
        # Padded with 0 to every row a beat can reach (rows past Dmax are not read). A lane reading a
        # pixel without a MAP is neutral (factor 1) with lr_neutral.
        one_bits = test.consistent | test.unknown if c.neutral else test.consistent
        bits = Cat(one_bits, Const(0, n.n_beats * n.rows_per_beat))
        self._consistent = [n.aligned(bits.bit_select(n.row(j), 1), f"consistent{j}")
                            for j in range(n.rows_per_beat)]
        self._any = n.aligned(test.any, "any_consistent")
        q = c.table(n.form.table_bits)
        self._beta, self._gamma = n.form.value(q.values[1]), n.form.value(q.nomatch[0])

    def ready(self) -> Value:
        return ~self.ctx.pixel.consult | self._maps.valid

    def word(self, j: int) -> ValueLike:
        return Mux(self._consistent[j], self.ctx.one, self._beta)

    def nomatch(self) -> ValueLike:
        return Mux(self._any, self._gamma, self.ctx.one) if self.term.has_nomatch else self.ctx.zero
