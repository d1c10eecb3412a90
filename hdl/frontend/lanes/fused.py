"""The fused column's lanes: its members' costs from the delay line's entries, their energy tables, the
sums per row, the pixel's smallest sum, and the exp table back to words (the rule of
``bayesmachine.columns.fused``; docs/architecture.md, "The fused column").

A word needs the pixel's smallest sum, so the word generator scans the pixel's beats first
(``LaneContext.fetch``, one beat of delay-line entries a cycle, whatever the stream does, the pixels' scans
back to back, each into the pixel's slot of the generator's ring, ``ScanRing``): each lane row's
member costs (the members' own lane builders' ``costs``) are read in their energy tables (block RAM,
three cycles: cost, address, read), added (a register), kept in the slot's entry of the beat (a
memory of slots × beats entries of a beat's row sums: distributed RAM), and the beat's minimum (a tree
of compares, a register) folded into a running minimum (the no-match row's sum first, when the pass's
no-match row can win), at the last beat into the slot's minimum. When the lanes take the scanned pixel
its minimum and no-match sum move into the registers its issues read, and its beats are issued as any
pass's from its slot's entries while the next pixels' scans fill other slots: each lane's sum minus the
minimum is the address of the exp table X (clamped to its last entry, 0), and the no-match row's word
the same at the no-match sum.

When the model's passes share the sums (:mod:`..shared`: the generator's ``fused_share``), the right pass
writes each beat's row sums into the shared memories as it stores them, and the own pass reads its beat's
sums there (a read two cycles after the fetch, its data where the tables' reads would be) instead of
computing its members' costs and codes; each pass takes an output pixel from its stream only when the
shared memories allow (``LaneContext.hold_scan``).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, ShapeLike, Signal, Value, ValueLike, unsigned
from amaranth.lib import data, memory, wiring

from bayesmachine.columns import Fused, Term

from ..lookup import pick
from ..tables import FrontEndTables
from .base import Lanes, PlaneFilter, lanes_for, register

__all__ = ["SCAN_LATENCY", "FusedLanes", "delayed", "fused_sum_bits", "smallest"]

# From a fetch to the scan's results complete: the cost and address registers and the table read (3),
# the sums (1), the beat's minimum (1), the running minimum (1); each step a register, for the clock.
SCAN_LATENCY = 6


def _bits(tables: FrontEndTables, name: str) -> int:
    return max(1, int(max(tables[name])).bit_length())


def fused_sum_bits(term: Fused, tables: FrontEndTables) -> int:
    """Bits of a fused column ``term``'s row sums and no-match sum, by its pass's ``tables``."""
    top = sum(int(max(tables[f"{m.name}_energy"])) for m in term.members)
    nm = int(max(tables["nomatch_energy"])) + sum(
        int(m.nomatch_entry(e)) for m, e in zip(term.members[1:], term.energies()[1:], strict=True))
    return max(top, nm).bit_length()


@register(Fused)
class FusedLanes(Lanes):
    """A fused column (see the module's text): its members' lane builders give the costs."""

    @classmethod
    def filters(cls, term: Term, margin: int) -> tuple[PlaneFilter, ...]:
        out: dict[PlaneFilter, None] = {}
        for member in term.members:
            out.update(dict.fromkeys(lanes_for(member).filters(member, margin)))
        return tuple(out)

    @classmethod
    def planes(cls, term: Term, margin: int) -> dict[str, ShapeLike]:
        out: dict[str, ShapeLike] = {}
        for member in term.members:
            out.update(lanes_for(member).planes(member, margin))
        return out

    @classmethod
    def scan_latency(cls, term: Term, n_beats: int) -> int:
        return SCAN_LATENCY

    def build(self) -> None:
        width = self.build_scan()
        self._hand_over(width)
        self._words_out(width)

    def build_scan(self) -> int:
        """The scan alone (module text): each fetched beat's row sums into the slot's entries
        (``sums``), the slot's minimum and no-match sum (``slot_mins``, ``slot_nm_sums``) ``SCAN_LATENCY``
        cycles after the pixel's last fetch; the sums' width. A semi-global column's lanes build on it."""
        n, t = self.ctx, self.term
        rule = n.pass_.model.nomatch
        share = n.fused_share
        port = None if share is None else n.shared_port("fused_sums")
        width = fused_sum_bits(t, n.tables)
        # The no-match row's sum: the rule's code at the reference pixel's |gV| (three cycles after the
        # take from the stream, beside beat 0's member codes) plus the other members' no-match codes.
        rule_code = n.lookup("nomatch_energy", n.tables["nomatch_energy"],
                             [getattr(n.left, rule.plane)], en=Const(1),
                             bits=_bits(n.tables, "nomatch_energy"))[0]
        extra = sum(int(m.nomatch_entry(e)) for m, e in zip(t.members[1:], t.energies()[1:], strict=True))
        self._scan_nm = Signal(unsigned(width), name="fused_scan_nm_sum")
        n.m.d.comb += self._scan_nm.eq(rule_code + extra)
        self._live = n.pass_.nomatch and not any(c.zeroes_nomatch for c in n.pass_.columns)
        # Each fetch's flag, beat and slot, 1 .. 5 cycles later (element k: k + 1), for the steps after it.
        self._steps = [self._delayed(v, 5, f"fused_{name}") for v, name in
                       ((n.fetch, "fetched"), (n.fetch_beat, "beat"), (n.fetch_slot, "slot"))]
        if share is not None:  # a position is the latest taken pixel's while its beats are fetched
            self._at = self._delayed(port.position, 4, "fused_at")
            n.m.d.comb += port.take.eq(n.fed_take & n.fed.output)
        role = None if share is None else share.role
        sums_q = self._store(self._read_shared(port) if role == "import" else self._member_sums(), width)
        if role == "export":
            self._write_shared(port, sums_q)
        self._scan_min(sums_q, width)
        return width

    @property
    def sums(self) -> memory.Memory:
        """The slots' row sums, a beat an entry at ``Cat(beat, slot)`` (after :meth:`build_scan`)."""
        return self._sums

    @property
    def slot_mins(self) -> list[Signal]:
        """Each slot's minimum sum (after :meth:`build_scan`)."""
        return self._mins

    @property
    def slot_nm_sums(self) -> list[Signal]:
        """Each slot's no-match sum (after :meth:`build_scan`)."""
        return self._nm_sums

    @property
    def live(self) -> bool:
        """Whether the pass's no-match row can win (its sum is among those the minimum is of)."""
        return self._live

    def _member_sums(self) -> list[Value]:
        """Each lane row's sum of its members' codes, three cycles after its fetch."""
        n = self.ctx
        total: list[Value] = [Const(0)] * n.rows_per_beat
        for member in self.term.members:
            costs = lanes_for(member)(member, n).costs()
            name = f"{member.name}_energy"
            codes = n.lookup(name, n.tables[name], costs, en=Const(1), bits=_bits(n.tables, name))
            total = [a + b for a, b in zip(total, codes, strict=True)]
        return total

    def _read_shared(self, port: wiring.PureInterface) -> list[Value]:
        """The importer: each lane row's sum from the shared memories, three cycles after its fetch (the
        read two cycles after, at the pixel's position and the beat); an output pixel is taken only once
        its sums are all written."""
        n = self.ctx
        n.hold_scan(port.ready)
        n.m.d.comb += [port.row_start.eq(n.fed.row_start), port.en.eq(self._steps[0][1]),
                       port.at.eq(self._at[1]), port.beat.eq(self._steps[1][1])]
        return [port.sums[j] for j in range(n.rows_per_beat)]

    def _write_shared(self, port: wiring.PureInterface, sums_q: list[Signal]) -> None:
        """The exporter: each fetched beat's row sums into the shared memories as they are stored (four
        cycles after the fetch); an output pixel is taken only while the memories have room for it."""
        n = self.ctx
        n.hold_scan(port.room)
        fetched, beat, _ = (steps[3] for steps in self._steps)
        n.m.d.comb += [port.en.eq(fetched), port.at.eq(self._at[3]), port.beat.eq(beat),
                       port.last.eq(beat == n.n_beats - 1), port.sums.eq(Cat(*sums_q))]

    def _delayed(self, value: Value, cycles: int, name: str) -> list[Signal]:
        return delayed(self.ctx.m, value, cycles, name)

    def _store(self, sums: list[Value], width: int) -> list[Signal]:
        """A fetched beat's row sums into a register three cycles after its fetch (a row without a match
        pixel, flagged at its fetch, as the largest sum), and into the slot's row sums (distributed RAM,
        a beat an entry) the cycle after."""
        n = self.ctx
        m, rows, dmax = n.m, n.rows_per_beat, n.dmax
        top = (1 << width) - 1
        kept = []
        for j in range(rows):
            row = n.fetch_beat * rows + j
            match = n.reference.match_ok(n, row, scanned=True)
            ok = row <= dmax if match is None else (row <= dmax) & match
            kept.append(self._delayed(ok, 3, f"fused_kept{j}")[-1])
        sums_q = [Signal(unsigned(width), name=f"fused_beat_sum{j}", reset_less=True) for j in range(rows)]
        m.d.sync += [q.eq(Mux(k, s, top)) for q, k, s in zip(sums_q, kept, sums, strict=True)]
        fetched, beat, slot = (steps[3] for steps in self._steps)
        self._sums = memory.Memory(shape=data.ArrayLayout(unsigned(width), rows),
                                   depth=n.slots << len(n.fetch_beat), init=[])
        m.submodules.fused_sums = self._sums
        write = self._sums.write_port()
        m.d.comb += [write.en.eq(fetched), write.addr.eq(Cat(beat, slot)), write.data.eq(Cat(*sums_q))]
        return sums_q

    def _scan_min(self, sums_q: list[Signal], width: int) -> None:
        """The beat's minimum (a tree of compares) into a register, four cycles after its fetch, and that
        into the running minimum the next (the no-match sum first at beat 0 when it can win, carried
        beside beat 0's sums); at the pixel's last beat the minimum and the no-match sum into its
        slot's registers."""
        n = self.ctx
        m = n.m
        top = (1 << width) - 1
        fetched, beat, slot = (steps[4] for steps in self._steps)
        nm_sum = self._delayed(self._scan_nm, 2, "fused_scan_nm")[-1]
        beat_min = Signal(unsigned(width), name="fused_beat_min", reset_less=True)
        m.d.sync += beat_min.eq(smallest(list(sums_q)))
        running = Signal(unsigned(width), name="fused_scan_min", reset_less=True)
        low: Value = Mux(beat == 0, nm_sum if self._live else top, running)
        least = smallest([low, beat_min])
        self._mins = [Signal(unsigned(width), name=f"fused_min{k}", reset_less=True) for k in range(n.slots)]
        self._nm_sums = [Signal(unsigned(width), name=f"fused_nm_sum{k}", reset_less=True)
                         for k in range(n.slots)]
        with m.If(fetched):
            m.d.sync += running.eq(least)
            for k, (low_k, nm_k) in enumerate(zip(self._mins, self._nm_sums, strict=True)):
                with m.If((beat == n.n_beats - 1) & (slot == k)):
                    m.d.sync += [low_k.eq(least), nm_k.eq(nm_sum)]

    def _hand_over(self, width: int) -> None:
        """The minimum and the no-match sum of the pixel the lanes take into the registers its issues read
        (its row sums stay in its slot until its last issue)."""
        n = self.ctx
        self._min = Signal(unsigned(width), name="fused_min", reset_less=True)
        self._nm_sum = Signal(unsigned(width), name="fused_nm_sum", reset_less=True)
        with n.m.If(n.take):
            n.m.d.sync += [self._min.eq(pick(self._mins, n.take_slot)),
                           self._nm_sum.eq(pick(self._nm_sums, n.take_slot))]

    def _words_out(self, width: int) -> None:
        """At each issue, each lane row's sum (the issued slot's entry of the beat) minus the minimum,
        read in X (with the beat on the stream); rows past Dmax are not read."""
        n = self.ctx
        read = self._sums.read_port(domain="comb")
        n.m.d.comb += read.addr.eq(Cat(n.beat, n.issue_slot))
        diffs = [Signal(unsigned(width), name=f"fused_diff{j}") for j in range(n.rows_per_beat)]
        n.m.d.comb += [d.eq(read.data[j] - self._min) for j, d in enumerate(diffs)]
        costs: list[Value] = list(diffs)
        if self._live:  # the no-match sum is among those the minimum is of: an unsigned cost too
            nm_diff = Signal(unsigned(width), name="fused_nm_diff")
            n.m.d.comb += nm_diff.eq(self._nm_sum - self._min)
            costs.append(nm_diff)
        self._words = n.lookup("fused_exp", n.tables["fused_exp"], costs)

    def word(self, j: int) -> ValueLike:
        return self._words[j]

    def nomatch(self) -> ValueLike:
        return self._words[-1] if self._live else self.ctx.zero


def delayed(m: Module, value: ValueLike, cycles: int, name: str) -> list[Signal]:
    """``value`` 1 .. ``cycles`` cycles later (every cycle: a scan runs whatever the stream does): element
    k is k + 1 cycles later."""
    out: list[Signal] = []
    for k in range(cycles):
        reg = Signal.like(Value.cast(value), name=f"{name}_{k}")
        m.d.sync += reg.eq(out[-1] if out else value)
        out.append(reg)
    return out


def smallest(values: list[Value]) -> Value:
    """The smallest of ``values``, by a tree of compares."""
    while len(values) > 1:
        pairs = [Mux(a < b, a, b) for a, b in zip(values[::2], values[1::2], strict=False)]
        values = pairs + ([values[-1]] if len(values) % 2 else [])
    return values[0]
