"""The fused sums computed once for both passes: census-lr's (and census-sgm's) right pass writes each
pair's sum of its fused column's member codes, its own pass reads them instead of computing them again
(census-sgm's passes then aggregate them along their own paths: :func:`fused_term`).

The own pass (left reference) pairs left x with right x - d, a right-reference pass right x_r with left
x_r + d: the same pair of pixels when x_r = x - d, and a fused column's members' codes depend on the pair
alone when each member's cost is symmetric (|cost(a, b)| = |cost(b, a)|: a feature difference, a census
Hamming distance). So the pass that runs first (the exporter, the right pass) writes the sum of the members'
codes of its output pixel at position p, row d, into lane row j's memory (d = b·R + j: beat b, R rows per
beat) at position p + d, and the own pass (the importer) reads its output pixel at position q, row d, at
position q in every lane row's memory: one address for the beat, whatever the lane row. Positions count a
map row's W4 map columns (``r·W4 + x``): the right pass's output pixels are every map column of a row, in
order; the own pass's are columns Dmax .. W4 - 1, so its position steps by 1, or by Dmax + 1 at a row's
first output pixel (``row_start``).

:class:`SharedSums` holds the memories (per lane row ``depth`` positions × the beats, block RAM) and the
flow control between the two: the importer takes an output pixel once every sum of it is written (the
exporter's pixels up to its position are done), the exporter takes one while its writes (positions up to
p + the last row) cannot reach a position the importer may still read (from its previous pixel's on).
Both decisions are registers, computed from the positions each pass will have after this cycle's take.
Its twin: the own pass's sums are ``Fused.sums`` of its pixels, which the right pass computed for the
same pairs (the word tests compare the own pass's words with the host's).
"""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Cat, Module, Mux, Shape, Signal, Value, unsigned
from amaranth.lib import data, memory, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.columns import Fused, SemiGlobal
from bayesmachine.models import Pass
from bayesmachine.params import ParameterError

__all__ = ["SHARE_ROLES", "FusedShare", "SharedSums", "fused_term"]

# A pass's part in the sharing: it writes its sums (the right pass), or reads them (the own pass).
SHARE_ROLES = ("export", "import")


def fused_term(p: Pass) -> Fused | None:
    """The fused column whose sums pass ``p`` computes, to share: its one fused column, itself or the member
    of a semi-global column (whose aggregation each pass runs on the sums in its own direction); None
    without exactly one."""
    found = [c.member if isinstance(c, SemiGlobal) else c
             for c in p.columns if isinstance(c, Fused | SemiGlobal)]
    return found[0] if len(found) == 1 and isinstance(found[0], Fused) else None


@dataclass(frozen=True)
class FusedShare:
    """One pass's part in sharing its fused column's sums (see the module text).

    Parameters
    ----------
    role : str
        "export" (writes its sums: a right-reference pass) or "import" (reads them: the own pass).
    rows, beats : int
        Lane rows per beat (R) and beats per pixel, the same in both passes.
    width : int
        Bits of a sum (``fused_sum_bits``).
    dmax : int
        The largest disparity.
    depth : int
        Positions each lane row's memory holds (N): a power of two above ``beats·rows + 2·dmax + 1``, so
        that the exporter may run Dmax + 1 pixels ahead of the importer's last position.
    """

    role: str
    rows: int
    beats: int
    width: int
    dmax: int
    depth: int

    def __post_init__(self) -> None:
        if not isinstance(self.role, str):
            raise TypeError(f"role must be a str, not {type(self.role).__name__}")
        if self.role not in SHARE_ROLES:
            raise ParameterError(f"fused_share: role must be one of {', '.join(SHARE_ROLES)}, got "
                                 f"{self.role!r}", "fused_share")
        for name, low in (("rows", 1), ("beats", 1), ("width", 1), ("dmax", 0), ("depth", 2)):
            as_int(name, getattr(self, name), low)
        least = self.reach + 2 * self.dmax + 2
        if self.depth & (self.depth - 1) or self.depth <= least:
            raise ParameterError(f"fused_share: depth must be a power of two above {least} (beats x rows + "
                                 f"2 x Dmax + 1), got {self.depth}", "fused_share")

    @property
    def reach(self) -> int:
        """The last row a pixel's beats hold (its sums reach position p + ``reach``)."""
        return self.beats * self.rows - 1

    @property
    def position_bits(self) -> int:
        """Bits of a position (modulo 2·``depth``: the passes' positions compared)."""
        return self.depth.bit_length()

    @property
    def beat_shape(self) -> Shape:
        return Shape.cast(range(max(2, self.beats)))

    @property
    def sums_layout(self) -> data.ArrayLayout:
        return data.ArrayLayout(unsigned(self.width), self.rows)

    def signature(self) -> wiring.Signature:
        """The word generator's port (``fused_sums``, ``Out``): as it writes (the exporter) or reads."""
        pos = unsigned(self.position_bits)
        common = {"take": Out(1), "position": In(pos), "en": Out(1), "at": Out(pos),
                  "beat": Out(self.beat_shape)}
        if self.role == "export":
            return wiring.Signature({**common, "room": In(1), "last": Out(1), "sums": Out(self.sums_layout)})
        return wiring.Signature({**common, "row_start": Out(1), "ready": In(1), "sums": In(self.sums_layout)})


class SharedSums(wiring.Component):
    """The memories of the fused sums between the exporting and the importing pass, and the flow control
    between them (see the module text).

    Parameters
    ----------
    writer, reader : FusedShare
        The exporter's and the importer's parts (the same geometry).

    Attributes
    ----------
    writer : ``In(writer.signature())``
        The exporter's port: ``take`` (an output pixel taken for its scan: its position is the next),
        ``position`` (the latest taken pixel's), ``room`` (an output pixel may be taken), and a beat's
        sums to write (``en``, ``at``: the scanned pixel's position, ``beat``, ``last``: its last beat,
        ``sums``).
    reader : ``In(reader.signature())``
        The importer's port: ``take`` and ``row_start`` (of the pixel offered: its position steps by
        Dmax + 1), ``position``, ``ready`` (the offered output pixel's sums are all written), and a
        beat's read (``en``, ``at``, ``beat``; ``sums`` the cycle after).
    """

    def __init__(self, *, writer: FusedShare, reader: FusedShare) -> None:
        for name, share, role in (("writer", writer, "export"), ("reader", reader, "import")):
            if not isinstance(share, FusedShare):
                raise TypeError(f"{name} must be a FusedShare, not {type(share).__name__}")
            if share.role != role:
                raise ParameterError(f"{name}: a FusedShare of role {role!r}, got {share.role!r}", name)
        if (writer.rows, writer.beats, writer.width, writer.dmax, writer.depth) != (
                reader.rows, reader.beats, reader.width, reader.dmax, reader.depth):
            raise ParameterError("reader: the same rows, beats, width, Dmax and depth as the writer's",
                                 "reader")
        self._writer, self._reader = writer, reader
        super().__init__({"writer": In(writer.signature()), "reader": In(reader.signature())})

    @property
    def share(self) -> FusedShare:
        """The writer's part (the geometry both share)."""
        return self._writer

    def elaborate(self, platform: object) -> Module:
        m = Module()
        s, w, r = self._writer, self.writer, self.reader
        low = (s.depth - 1).bit_length()  # position bits of an address: modulo N
        mask = (1 << s.position_bits) - 1
        for j in range(s.rows):
            m.submodules[f"row{j}"] = mem = memory.Memory(shape=unsigned(s.width),
                                                          depth=s.depth << len(w.beat), init=[])
            write, read = mem.write_port(), mem.read_port()
            at = (w.at + w.beat * s.rows + j)[:low]  # row b·R + j of pixel p: position p + b·R + j
            m.d.comb += [write.en.eq(w.en), write.addr.eq(Cat(at, w.beat)), write.data.eq(w.sums[j]),
                         read.en.eq(r.en), read.addr.eq(Cat(r.at[:low], r.beat)), r.sums[j].eq(read.data)]
        self._flow(m, mask)
        return m

    def _flow(self, m: Module, mask: int) -> None:
        """The positions (modulo 2N), the exporter's pixels done, and the two registered decisions."""
        s, w, r = self._writer, self.writer, self.reader
        bits = s.position_bits
        written = Signal(bits, init=mask)  # the exporter's latest taken pixel (-1: none)
        reading = Signal(bits, init=mask)  # the importer's
        done = Signal(bits)  # the exporter's pixels whose sums are all written
        w_next = Signal(bits)
        r_next = Signal(bits)
        m.d.comb += [w_next.eq(Mux(w.take, written + 1, written)),
                     r_next.eq(Mux(r.take, reading + 1 + Mux(r.row_start, s.dmax, 0), reading)),
                     w.position.eq(written), r.position.eq(reading)]
        m.d.sync += [written.eq(w_next), reading.eq(r_next)]
        with m.If(w.en & w.last):
            m.d.sync += done.eq(done + 1)

        def gap(a: Value, b: Value) -> Value:  # a - b modulo 2N
            return (a - b)[:bits]

        def readable(ahead: Value) -> Value:  # the exporter is done past the position, not N ahead
            return (ahead != 0) & ~ahead[-1]

        # The exporter's next pixel writes up to position + reach; the importer may still read from its
        # previous pixel on (at least its position - Dmax - 1): the writes stay within N of that.
        room, step_ok, jump_ok = Signal(init=1), Signal(), Signal()
        m.d.sync += [room.eq(gap(w_next + 1, reading) < s.depth - s.reach - s.dmax - 1),
                     step_ok.eq(readable(gap(done, r_next + 1))),
                     jump_ok.eq(readable(gap(done, r_next + 1 + s.dmax)))]
        m.d.comb += [w.room.eq(room), r.ready.eq(Mux(r.row_start, jump_ok, step_ok))]
