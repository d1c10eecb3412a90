"""The neighbour prior's columns: the left neighbour's (formed by the machine from its own previous
result; its lanes only mark a row's first output pixel ``line_start``) and the above neighbour's (a
loaded column: the prior table at |row - MAP above|, from a line of the pass's own MAPs)."""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, Value, ValueLike
from amaranth.lib import data, memory, stream, wiring
from amaranth.lib.wiring import In

from bayesmachine.columns import AbovePrior, LeftPrior, Term
from bayesmachine.hdl.signatures import map_layout, map_stream
from bayesmachine.params import MachineParams

from .base import Lanes, register

__all__ = ["AboveLanes", "LeftLanes"]


@register(LeftPrior)
class LeftLanes(Lanes):
    """The left neighbour's factor, formed by the machine: each beat of a row's first output pixel
    carries ``line_start`` (the machine's left factor is then 1.0)."""

    @classmethod
    def flags(cls, term: Term) -> tuple[str, ...]:
        return ("row_start",)

    def build(self) -> None:
        n = self.ctx
        n.m.d.comb += n.beats.line_start.eq(n.aligned(n.taken("row_start"), "line_start"))


@register(AbovePrior)
class AboveLanes(Lanes):
    """The above neighbour's factor: a line of the machine's own MAPs (a ``Memory`` of the output width,
    written as results leave through the ``maps`` stream, read when the pixel is taken) through the prior
    table clamped where it stops changing (the machine's ``feedback_words``); 1.0 in a frame's first output
    row and after a no-match or timeout above.

    An output pixel waits until the result above it is in the line of MAPs, and a result is written only
    over an entry already read: ``unread`` = results written - output pixels taken (+ an output row with
    ``leads``: the first map row reads no result). An output pixel is taken while unread >= 1, a result
    written while unread < the row. Both tests are on the counts of the next cycle, registered (a
    register toward the take, no path from the result): ``maps.ready``. With one machine this is "fewer
    than an output row's pixels taken and not yet out", always true when a result leaves. ``frame_reset``
    (several machines: every machine idle at a frame's first pixel) restarts the counts."""

    @classmethod
    def flags(cls, term: Term) -> tuple[str, ...]:
        return ("first_row",)

    @classmethod
    def members(cls, term: Term, params: MachineParams) -> dict[str, wiring.Member]:
        return {"maps": In(map_stream(params)), "frame_reset": In(1)}

    def build(self) -> None:
        n = self.ctx
        wo = n.output_columns
        if wo is None:
            raise ValueError("AboveLanes: the generator has no output_columns (its line of MAPs' length)")
        maps = n.map_stream("maps")
        written = Signal()  # a result into the line of MAPs
        n.m.d.comb += written.eq(maps.valid & maps.ready)
        self._room = self._counts(n.m, maps, wo, written)
        above = self._line(n.m, maps, wo, written)
        first_row = n.taken("first_row")
        # The read data holds from the cycle after the take until the next output pixel's take (in the
        # cycle of this pixel's last issue), so each issue sees this pixel's MAP above.
        self._hit = n.aligned(~first_row & above.hit, "hit")
        table = n.params.feedback_words  # the quantized prior clamped where it stops changing
        self._words = n.lookup("prior", table, [n.row(j) - above.map for j in range(n.rows_per_beat)])

    def _counts(self, m: Module, maps: stream.Interface, wo: int, written: Value) -> Value:
        frame_reset = self.ctx.signal_port("frame_reset")
        start = wo if self.ctx.leads else 0
        unread = Signal(range(wo + 1), init=start)
        room = Signal(init=start >= 1)
        write_room = Signal(init=start < wo)
        m.d.comb += maps.ready.eq(write_room)
        unread_next = Signal.like(unread)
        m.d.comb += unread_next.eq(unread + written - (self.ctx.take & self.ctx.pixel.output))
        with m.If(frame_reset):  # every machine idle: a frame starts afresh
            m.d.sync += [unread.eq(start), room.eq(start >= 1), write_room.eq(start < wo)]
        with m.Else():
            m.d.sync += [unread.eq(unread_next), room.eq(unread_next >= 1), write_room.eq(unread_next < wo)]
        return room

    def _line(self, m: Module, maps: stream.Interface, wo: int, written: Value) -> data.View:
        """The line of MAPs: written as results leave, read at an output pixel's take."""
        n = self.ctx
        layout = map_layout(n.params.map_width)
        m.submodules.above_line = line = memory.Memory(shape=layout, depth=wo, init=[])
        wr = line.write_port()
        rd = line.read_port()  # not transparent: a result written this cycle is read the next
        wr_ptr = Signal(range(wo))
        rd_ptr = Signal(range(wo))
        m.d.comb += [wr.en.eq(written), wr.addr.eq(wr_ptr), wr.data.eq(maps.payload)]
        with m.If(written):
            m.d.sync += wr_ptr.eq(Mux(wr_ptr == wo - 1, 0, wr_ptr + 1))
        out_take = n.take & n.pixel.output
        m.d.comb += [rd.en.eq(out_take), rd.addr.eq(rd_ptr)]
        with m.If(out_take):
            m.d.sync += rd_ptr.eq(Mux(rd_ptr == wo - 1, 0, rd_ptr + 1))
        with m.If(self.ctx.signal_port("frame_reset")):  # (back at 0 after whole rows; said, not assumed)
            m.d.sync += [wr_ptr.eq(0), rd_ptr.eq(0)]
        return rd.data

    def ready(self) -> Value:
        return ~self.ctx.pixel.output | self._room

    def word(self, j: int) -> ValueLike:
        return Mux(self._hit, self._words[j], self.ctx.one)

    def nomatch(self) -> ValueLike:
        return Mux(self._hit, self.ctx.params.feedback_nomatch_word, self.ctx.one)
