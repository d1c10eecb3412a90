"""The semi-global column's lanes: its member fused column's scan, the aggregation of its energies along
the causal paths, and the tempered sums back to words or codes (the rule of
``bayesmachine.columns.semiglobal``; docs/architecture.md, "The semi-global column on chip").

The member's scan (:meth:`FusedLanes.build_scan`) leaves each pixel's row sums D in its slot's entries and
its least sum D_min (and its no-match sum) in the slot's registers. The aggregation then walks the pixel's
beats again, a beat a cycle, at a fixed delay from their fetches (beat b of a pixel aggregated
``SCAN_LATENCY - 1 + n_beats`` cycles after its fetch: its pixel's last beat's scan is complete), so the
pixels' aggregations follow each other as their scans do, back to back. Per beat and lane row: E =
min(D − D_min, C) (C without a match pixel), and for each path r the step of the rule from the previous
point's costs L_r(q, ·) and their minimum m_r(q):

- the left path's q is the previous pixel: its costs and minimum are registers (the loop: a pixel's last
  beat's costs are written in the cycle before the next pixel's first beat reads them);
- an upper path's q is the row above (top: x, top-left: x − 1, top-right: x + 1): each keeps one word per
  output column of the row (every lane's cost and their minimum) in a memory (``amaranth.lib.memory``,
  block RAM), read the cycle before the pixel's first beat (held while its beats are aggregated) and
  written back at its last beat at x (top-left: the word read at x is held one pixel more, for x + 1).

A pixel's costs are collected beat by beat in registers; its last beat completes the word. A path starts
afresh (L = E) at the first output pixel of a row (left, top-left), at a frame's first output row
(the upper paths) and at a row's last output pixel (top-right). The sum S = Σ_r L_r of each lane row goes
into the slot's entry of the beat (distributed RAM), its minimum over the lanes with a match pixel (and
the no-match row's S_nm = n · E_nm where it can win) into the slot's registers at the last beat; the ring
takes the pixel once they are in (``scan_latency``). At each issue each lane's T = (A · (S − S_min) +
128) >> 8, clamped to the table's last entry, is the address of the member's way back (``fused_exp``: X
to words, the identity to codes).
"""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Cat, Const, Module, Mux, ShapeLike, Signal, Value, ValueLike, unsigned
from amaranth.lib import data, memory

from bayesmachine.columns import SemiGlobal, Term
from bayesmachine.columns.semiglobal import SCALE_BITS

from ..lookup import pick
from .base import Lanes, PlaneFilter, register
from .fused import SCAN_LATENCY, FusedLanes, delayed, smallest

__all__ = ["SemiGlobalLanes", "aggregation_delay", "upper_memory_bits"]


def aggregation_delay(n_beats: int) -> int:
    """Cycles from a beat's fetch to its aggregation, at ``n_beats`` beats per pixel: the member's scan of
    the pixel's last beat complete."""
    return SCAN_LATENCY - 1 + n_beats


def upper_memory_bits(term: SemiGlobal, output_columns: int) -> int:
    """Bits of the upper paths' memories of ``term`` for rows of ``output_columns`` pixels: per upper path
    and column, Dmax + 1 costs and their minimum of ``sgm_cost_bits`` each."""
    bits = int(term.values["sgm_cost_bits"])
    return (len(term.paths) - 1) * output_columns * (term.dmax + 2) * bits


@dataclass
class _Point:
    """The previous point's costs of one path, as the aggregation of a beat reads them: every lane's
    (``costs``: Dmax + 1) and their minimum; ``fresh``: the path starts at this pixel."""

    costs: list[Value]
    least: Value
    fresh: Value


@register(SemiGlobal)
class SemiGlobalLanes(Lanes):
    """A semi-global column (see the module's text): its member's lanes give the scan."""

    @classmethod
    def filters(cls, term: Term, margin: int) -> tuple[PlaneFilter, ...]:
        return FusedLanes.filters(term.member, margin)

    @classmethod
    def planes(cls, term: Term, margin: int) -> dict[str, ShapeLike]:
        return FusedLanes.planes(term.member, margin)

    @classmethod
    def flags(cls, term: Term) -> tuple[str, ...]:
        return ("row_start", "first_row")

    @classmethod
    def needs_row(cls, term: Term) -> bool:
        return True

    @classmethod
    def dealt(cls, term: Term) -> bool:
        return False

    @classmethod
    def scan_latency(cls, term: Term, n_beats: int) -> int:
        return aggregation_delay(n_beats) + 1

    def build(self) -> None:
        n, t = self.ctx, self.term
        self._member = FusedLanes(t.member, n)
        self._width = self._member.build_scan()
        self._cap = t.cap
        self._cost = unsigned(max(1, self._cap.bit_length()))
        self._sum_bits = max(1, (len(t.paths) * self._cap).bit_length())
        self._timing()
        energies, e_nm = self._energies()
        costs = self._paths(energies)
        self._sums_out(costs, e_nm)
        self._hand_over()
        self._words_out()

    def _timing(self) -> None:
        """Each fetch's flag, beat, slot, the pixel's position flags and each lane row's match, carried to
        the read ahead (``_ahead``: the cycle before the aggregation) and to the aggregation (``_agg``)."""
        n = self.ctx
        k = aggregation_delay(n.n_beats)
        px = n.scan_pixel
        oks = []
        for j in range(n.rows_per_beat):
            row = n.fetch_beat * n.rows_per_beat + j
            match = n.reference.match_ok(n, row, scanned=True)
            oks.append(row <= n.dmax if match is None else (row <= n.dmax) & match)
        values = {"fetched": n.fetch, "beat": n.fetch_beat, "slot": n.fetch_slot, "row_start": px.row_start,
                  "first_row": px.first_row, "ok": Cat(*oks)}
        chains = {name: delayed(n.m, v, k, f"sgm_{name}") for name, v in values.items()}
        self._ahead = {name: c[k - 2] for name, c in chains.items()}
        self._agg = {name: c[k - 1] for name, c in chains.items()}
        self._go = self._agg["fetched"]
        self._last = self._agg["beat"] == n.n_beats - 1

    def _energies(self) -> tuple[list[Signal], Signal]:
        """Each lane row's E of the beat aggregated, and the no-match row's E_nm."""
        n, fused, cap = self.ctx, self._member, self._cap
        read = fused.sums.read_port(domain="comb")
        slot = self._agg["slot"]
        n.m.d.comb += read.addr.eq(Cat(self._agg["beat"], slot))
        low = pick(fused.slot_mins, slot)
        out = []
        for j in range(n.rows_per_beat):
            diff = Signal(unsigned(self._width), name=f"sgm_d{j}")
            e = Signal(self._cost, name=f"sgm_e{j}")
            n.m.d.comb += [diff.eq(read.data[j] - low),
                           e.eq(Mux(self._agg["ok"][j] & (diff < cap), diff, cap))]
            out.append(e)
        d_nm = Signal(unsigned(self._width), name="sgm_d_nm")
        e_nm = Signal(self._cost, name="sgm_e_nm")
        n.m.d.comb += [d_nm.eq(pick(fused.slot_nm_sums, slot) - low), e_nm.eq(Mux(d_nm < cap, d_nm, cap))]
        return out, e_nm

    def _paths(self, energies: list[Signal]) -> list[list[Signal]]:
        """Every path's costs of the beat aggregated (path by path, lane row by lane row)."""
        n = self.ctx
        w = n.output_columns
        x = Signal(range(max(2, w)), name="sgm_x")  # the output column aggregated
        ahead = self._ahead["fetched"] & (self._ahead["beat"] == 0)
        x_next = Mux(self._ahead["row_start"], 0, x + 1)
        with n.m.If(ahead):
            n.m.d.sync += x.eq(x_next)
        first_row, row_start = self._agg["first_row"], self._agg["row_start"]
        out = []
        for path in self.term.paths:
            if path == "left":
                out.append(self._left(energies, row_start))
                continue
            reads = {"top": x_next, "top-left": x_next, "top-right": Mux(x_next + 1 < w, x_next + 1, 0)}
            fresh = {"top": first_row, "top-left": first_row | row_start,
                     "top-right": first_row | (x == w - 1)}
            out.append(self._upper(path, energies, reads[path], ahead, x, fresh[path]))
        return out

    def _left(self, energies: list[Signal], fresh: Value) -> list[Signal]:
        """The left path: the previous pixel's costs and minimum in registers."""
        n = self.ctx
        prev = [Signal(self._cost, name=f"sgm_left_prev{d}", reset_less=True) for d in range(n.dmax + 1)]
        least = Signal(self._cost, name="sgm_left_prev_min", reset_less=True)
        costs, word = self._step("left", energies, _Point(prev, least, fresh))
        with n.m.If(self._go & self._last):
            n.m.d.sync += [p.eq(c) for p, c in zip(prev, word[:-1], strict=True)]
            n.m.d.sync += least.eq(word[-1])
        return costs

    def _upper(self, path: str, energies: list[Signal], read_at: Value, ahead: Value, x: Signal,
               fresh: Value) -> list[Signal]:
        """An upper path: the row above's words in a memory, read ahead at ``read_at``, written back at
        ``x`` at the pixel's last beat (top-left: the word read held one pixel more)."""
        n = self.ctx
        layout = data.ArrayLayout(self._cost, n.dmax + 2)
        mem = memory.Memory(shape=layout, depth=max(2, n.output_columns), init=[])
        n.m.submodules[f"sgm_{path.replace('-', '_')}"] = mem
        write = mem.write_port()
        # Transparent: a word written in the clock it is read ahead (one output pixel a row) reads new.
        read = mem.read_port(transparent_for=(write,))
        n.m.d.comb += [read.en.eq(ahead), read.addr.eq(read_at)]
        word_in = read.data
        if path == "top-left":
            held = Signal(layout, name="sgm_top_left_held", reset_less=True)
            with n.m.If(ahead):
                n.m.d.sync += held.eq(read.data)
            word_in = held
        point = _Point([word_in[d] for d in range(n.dmax + 1)], word_in[n.dmax + 1], fresh)
        costs, word = self._step(path.replace("-", "_"), energies, point)
        n.m.d.comb += [write.en.eq(self._go & self._last), write.addr.eq(x), write.data.eq(Cat(*word))]
        return costs

    def _step(self, name: str, energies: list[Signal], q: _Point) -> tuple[list[Signal], list[Value]]:
        """One path's costs of the beat aggregated from the previous point ``q`` (the rule's step), and the
        pixel's whole word at its last beat (every lane's cost, then their minimum): the earlier beats'
        costs in registers, the running minimum in one."""
        n, cap = self.ctx, self._cap
        p1, p2 = self.term.penalties
        rows, beat = n.rows_per_beat, self._agg["beat"]
        costs = []
        for j in range(rows):
            here, below, above, has_below, has_above = _neighbours(q.costs, beat, j, rows, n.n_beats)
            v: Value = here
            v = Mux(has_below & (below + p1 < v), below + p1, v)
            v = Mux(has_above & (above + p1 < v), above + p1, v)
            v = Mux(q.least + p2 < v, q.least + p2, v)
            total = energies[j] + v - q.least
            cost = Signal(self._cost, name=f"sgm_{name}_l{j}")
            n.m.d.comb += cost.eq(Mux(q.fresh, energies[j], Mux(total > cap, cap, total)))
            costs.append(cost)
        inside = [beat * rows + j <= n.dmax for j in range(rows)]
        beat_min = smallest([Mux(ok, c, cap) for ok, c in zip(inside, costs, strict=True)])
        running = Signal(self._cost, name=f"sgm_{name}_running_min", reset_less=True)
        least = Signal(self._cost, name=f"sgm_{name}_min")
        n.m.d.comb += least.eq(Mux(beat == 0, beat_min, Mux(running < beat_min, running, beat_min)))
        kept = [Signal(self._cost, name=f"sgm_{name}_kept{d}", reset_less=True)
                for d in range((n.n_beats - 1) * rows)]
        with n.m.If(self._go):
            n.m.d.sync += running.eq(least)
            with n.m.Switch(beat):
                for b in range(n.n_beats - 1):
                    with n.m.Case(b):
                        n.m.d.sync += [kept[b * rows + j].eq(costs[j]) for j in range(rows)]
        word: list[Value] = [*kept, *costs][: n.dmax + 1]
        return costs, [*word, least]

    def _sums_out(self, costs: list[list[Signal]], e_nm: Signal) -> None:
        """Each lane row's S into the slot's entry of the beat; at the last beat the minimum over the lanes
        with a match pixel (and S_nm where it can win) and S_nm into the slot's registers."""
        n, top = self.ctx, (1 << self._sum_bits) - 1
        sums = [Signal(unsigned(self._sum_bits), name=f"sgm_s{j}") for j in range(n.rows_per_beat)]
        n.m.d.comb += [s.eq(sum(path[j] for path in costs)) for j, s in enumerate(sums)]
        s_nm = Signal(unsigned(self._sum_bits), name="sgm_s_nm")
        n.m.d.comb += s_nm.eq(len(costs) * e_nm)
        self._mem = memory.Memory(shape=data.ArrayLayout(unsigned(self._sum_bits), n.rows_per_beat),
                                  depth=n.slots << len(n.fetch_beat), init=[])
        n.m.submodules.sgm_sums = self._mem
        write = self._mem.write_port()
        slot, beat = self._agg["slot"], self._agg["beat"]
        n.m.d.comb += [write.en.eq(self._go), write.addr.eq(Cat(beat, slot)), write.data.eq(Cat(*sums))]
        beat_min = smallest([Mux(self._agg["ok"][j], s, top) for j, s in enumerate(sums)])
        running = Signal(unsigned(self._sum_bits), name="sgm_s_running_min", reset_less=True)
        low: Value = Mux(beat == 0, s_nm if self._member.live else top, running)
        least = smallest([low, beat_min])
        self._mins = [Signal(unsigned(self._sum_bits), name=f"sgm_min{k}", reset_less=True)
                      for k in range(n.slots)]
        self._nm_sums = [Signal(unsigned(self._sum_bits), name=f"sgm_nm{k}", reset_less=True)
                         for k in range(n.slots)]
        with n.m.If(self._go):
            n.m.d.sync += running.eq(least)
            for k, (low_k, nm_k) in enumerate(zip(self._mins, self._nm_sums, strict=True)):
                with n.m.If(self._last & (slot == k)):
                    n.m.d.sync += [low_k.eq(least), nm_k.eq(s_nm)]

    def _hand_over(self) -> None:
        """S_min and S_nm of the pixel the lanes take into the registers its issues read."""
        n = self.ctx
        self._min = Signal(unsigned(self._sum_bits), name="sgm_min", reset_less=True)
        self._nm = Signal(unsigned(self._sum_bits), name="sgm_nm", reset_less=True)
        with n.m.If(n.take):
            n.m.d.sync += [self._min.eq(pick(self._mins, n.take_slot)), self._nm.eq(pick(self._nm_sums,
                                                                                           n.take_slot))]

    def _words_out(self) -> None:
        """At each issue, each lane row's T of its S (the issued slot's entry of the beat), read in the
        member's way back (with the beat on the stream)."""
        n = self.ctx
        read = self._mem.read_port(domain="comb")
        n.m.d.comb += read.addr.eq(Cat(n.beat, n.issue_slot))
        table = n.tables["fused_exp"]
        values = [read.data[j] for j in range(n.rows_per_beat)]
        if self._member.live:
            values.append(self._nm)
        costs = [self._tempered(n.m, v, self._min, len(table) - 1, f"sgm_t{j}") for j, v in enumerate(values)]
        self._words = n.lookup("fused_exp", table, costs)

    def _tempered(self, m: Module, s: Value, low: Value, top: int, name: str) -> Signal:
        """min(T, ``top``), T = (A · (s − low) + 128) >> 8 (s >= low)."""
        diff = Signal(unsigned(self._sum_bits), name=f"{name}_diff")
        t = Signal(range(top + 1), name=name)
        scaled = (diff * self.term.scale + (1 << (SCALE_BITS - 1))) >> SCALE_BITS
        m.d.comb += [diff.eq(s - low), t.eq(Mux(scaled > top, top, scaled))]
        return t

    def word(self, j: int) -> ValueLike:
        return self._words[j]

    def nomatch(self) -> ValueLike:
        return self._words[-1] if self._member.live else self.ctx.zero


def _neighbours(costs: list[Value], beat: Signal, j: int, rows: int,
                n_beats: int) -> tuple[Value, Value, Value, Value, Value]:
    """Lane row j's cost of the previous point at its own disparity d = beat · R + j and at d − 1, d + 1,
    and whether those exist (0 <= d ± 1 <= Dmax), by the beat aggregated."""
    dmax = len(costs) - 1

    def at(d: int) -> Value:
        return costs[d] if 0 <= d <= dmax else Const(0, Value.cast(costs[0]).shape())

    beats = list(range(n_beats))
    here = pick([at(b * rows + j) for b in beats], beat)
    below = pick([at(b * rows + j - 1) for b in beats], beat)
    above = pick([at(b * rows + j + 1) for b in beats], beat)
    has_below = pick([Const(int(0 <= b * rows + j - 1 <= dmax), 1) for b in beats], beat)
    has_above = pick([Const(int(b * rows + j + 1 <= dmax), 1) for b in beats], beat)
    return here, below, above, has_below, has_above
