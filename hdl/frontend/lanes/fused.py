"""The fused column's lanes: its members' costs from the delay line's entries, their energy tables, the
sums per row, the pixel's smallest sum, and the exp table back to words (the rule of
``bayesmachine.columns.fused``; docs/architecture.md, "The fused column").

A word needs the pixel's smallest sum, so the word generator scans the pixel's beats first
(``WordNets.fetch``, one beat of delay-line entries a cycle, whatever the stream does): each lane row's
member costs (the members' own lane builders' ``costs``) are read in their energy tables (block RAM,
three cycles: cost, address, read), added (a register), kept per row in a register, and the beat's
minimum (a tree of compares, a register) folded into a running minimum (the no-match row's sum first,
when the pass's no-match row can win). When the lanes take the scanned
pixel its sums, minimum and no-match sum move into a second set of registers, from which its beats are
issued as any pass's while the next pixel's scan fills the first: each lane's sum minus the minimum is
the address of the exp table X (clamped to its last entry, 0), and the no-match row's word the same at
the no-match sum.
"""

from __future__ import annotations

from typing import Any

from amaranth.hdl import Const, Mux, Signal, Value, unsigned

from bayesmachine.columns import Fused

from .base import Lanes, PlaneFilter, lanes_for, register

__all__ = ["FusedLanes"]

# From a fetch to the scan's results complete: the cost and address registers and the table read (3),
# the sums (1), the beat's minimum (1), the running minimum (1); each step a register, for the clock.
SCAN_LATENCY = 6


@register(Fused)
class FusedLanes(Lanes):
    """A fused column (see the module's text): its members' lane builders give the costs."""

    @classmethod
    def filters(cls, term: Any, margin: int) -> tuple[PlaneFilter, ...]:
        out: dict[PlaneFilter, None] = {}
        for member in term.members:
            out.update(dict.fromkeys(lanes_for(member).filters(member, margin)))
        return tuple(out)

    @classmethod
    def planes(cls, term: Any, margin: int) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for member in term.members:
            out.update(lanes_for(member).planes(member, margin))
        return out

    @classmethod
    def scan_latency(cls, term: Any) -> int:
        return SCAN_LATENCY

    def build(self) -> None:
        n, t = self.nets, self.term
        rule = n.pass_.model.nomatch
        sums = self._member_sums()
        width = self._sum_bits()
        # The no-match row's sum: the rule's code at the reference pixel's |gV| (stable from the take on)
        # plus the other members' no-match codes.
        rule_code = n.lookup("nomatch_energy", n.tables["nomatch_energy"],
                             [getattr(n.left, rule.plane)], en=Const(1), bits=self._bits("nomatch_energy"))[0]
        extra = sum(int(m.nomatch_entry(e)) for m, e in zip(t.members[1:], t.energies()[1:], strict=True))
        self._scan_nm = Signal(unsigned(width), name="fused_scan_nm_sum")
        n.m.d.comb += self._scan_nm.eq(rule_code + extra)
        self._live = n.pass_.nomatch and not any(c.zeroes_nomatch for c in n.pass_.columns)
        self._store_and_min(sums, width)
        self._hand_over(width)
        self._words_out(width)

    def _bits(self, name: str) -> int:
        return max(1, int(max(self.nets.tables[name])).bit_length())

    def _sum_bits(self) -> int:
        n, t = self.nets, self.term
        top = sum(int(max(n.tables[f"{m.name}_energy"])) for m in t.members)
        nm = int(max(n.tables["nomatch_energy"])) + sum(
            int(m.nomatch_entry(e)) for m, e in zip(t.members[1:], t.energies()[1:], strict=True))
        return max(top, nm).bit_length()

    def _member_sums(self) -> list[Value]:
        """Each lane row's sum of its members' codes, three cycles after its fetch."""
        n = self.nets
        total: list[Value] = [Const(0)] * n.rows_per_beat
        for member in self.term.members:
            costs = lanes_for(member)(member, n).costs()
            name = f"{member.name}_energy"
            codes = n.lookup(name, n.tables[name], costs, en=Const(1), bits=self._bits(name))
            total = [a + b for a, b in zip(total, codes, strict=True)]
        return total

    def _delayed(self, value: Value, cycles: int, name: str) -> list[Signal]:
        """``value`` 1 .. ``cycles`` cycles later (every cycle: the scan runs whatever the stream does):
        element k is k + 1 cycles later."""
        out: list[Signal] = []
        for k in range(cycles):
            reg = Signal.like(Value.cast(value), name=f"{name}_{k}")
            self.nets.m.d.sync += reg.eq(out[-1] if out else value)
            out.append(reg)
        return out

    def _store_and_min(self, sums: list[Value], width: int) -> None:
        """A fetched beat's row sums into a register three cycles after its fetch (a row without a match
        pixel as the largest sum), each into its row's register and the beat's minimum (a tree of
        compares) the cycle after, and that into the running minimum the next (the no-match sum first at
        beat 0 when it can win)."""
        n = self.nets
        m, rows, dmax = n.m, n.rows_per_beat, n.dmax
        fetched = self._delayed(n.fetch, 5, "fused_fetched")
        beat = self._delayed(n.fetch_beat, 5, "fused_beat")
        top = (1 << width) - 1
        self._scan_rows = [Signal(unsigned(width), name=f"fused_scan_sum{r}", reset_less=True)
                           for r in range(dmax + 1)]
        self._scan_min = Signal(unsigned(width), name="fused_scan_min", reset_less=True)
        sums_q = [Signal(unsigned(width), name=f"fused_beat_sum{j}", reset_less=True) for j in range(rows)]
        for j, (s, q) in enumerate(zip(sums, sums_q, strict=True)):
            ok = beat[2] * rows + j <= dmax
            match = n.reference.match_ok(n, beat[2] * rows + j, scanned=True)
            m.d.sync += q.eq(Mux(ok if match is None else ok & match, s, top))
        beat_min = Signal(unsigned(width), name="fused_beat_min", reset_less=True)
        m.d.sync += beat_min.eq(_smallest(list(sums_q)))
        with m.If(fetched[3]):
            for b in range(n.n_beats):  # each row's sum register loads at its own beat
                for j in range(rows):
                    if b * rows + j <= dmax:
                        with m.If(beat[3] == b):
                            m.d.sync += self._scan_rows[b * rows + j].eq(sums_q[j])
        low: Value = Mux(beat[4] == 0, self._scan_nm if self._live else top, self._scan_min)
        with m.If(fetched[4]):
            m.d.sync += self._scan_min.eq(_smallest([low, beat_min]))

    def _hand_over(self, width: int) -> None:
        """The scanned pixel's sums, minimum and no-match sum into the registers its issues read, when the
        lanes take it (the next pixel's scan then writes the scan's registers while these issue)."""
        n = self.nets
        self._rows = [Signal(unsigned(width), name=f"fused_sum{r}", reset_less=True)
                      for r in range(n.dmax + 1)]
        self._min = Signal(unsigned(width), name="fused_min", reset_less=True)
        self._nm_sum = Signal(unsigned(width), name="fused_nm_sum", reset_less=True)
        with n.m.If(n.take):
            n.m.d.sync += [a.eq(b) for a, b in zip(self._rows, self._scan_rows, strict=True)]
            n.m.d.sync += [self._min.eq(self._scan_min), self._nm_sum.eq(self._scan_nm)]

    def _words_out(self, width: int) -> None:
        """At each issue, each lane row's sum minus the minimum, read in X (with the beat on the stream)."""
        n = self.nets
        m, rows, dmax = n.m, n.rows_per_beat, n.dmax
        diffs = [Signal(unsigned(width), name=f"fused_diff{j}") for j in range(rows)]
        unused = range(n.n_beats, 1 << len(n.beat))  # never occur; in the last case: a complete case
        with m.Switch(n.beat):
            for b in range(n.n_beats):
                with m.Case(b, *(unused if b == n.n_beats - 1 else ())):
                    for j in range(rows):
                        r = b * rows + j
                        m.d.comb += diffs[j].eq(self._rows[r] - self._min if r <= dmax else 0)
        costs: list[Value] = list(diffs)
        if self._live:
            costs.append(self._nm_sum - self._min)
        self._words = n.lookup("fused_exp", n.tables["fused_exp"], costs)

    def word(self, j: int) -> Any:
        return self._words[j]

    def nomatch(self) -> Any:
        return self._words[-1] if self._live else self.nets.zero


def _smallest(values: list[Value]) -> Value:
    """The smallest of ``values``, by a tree of compares."""
    while len(values) > 1:
        pairs = [Mux(a < b, a, b) for a, b in zip(values[::2], values[1::2], strict=False)]
        values = pairs + ([values[-1]] if len(values) % 2 else [])
    return values[0]
