"""The machine's overflow counters and its stop decision, built into the machine's module.

Per row an overflow counter (``counters.py``: with a registered "full" flag for one sample per
clock, a registered ``room`` for B samples) counts the 1s of its stochastic bus; the run stops,
registered, when a row overflows (known a cycle early with prefetched comparators, per group of
rows) or the watchdog expires; ``over_q`` keeps the rows that overflowed at the stop for the MAP
encoder, and with ``timeout_answer = "leading"`` a timed-out run's bubble searches them for the
leading row. The formal mutants drive these registers (``hdl.formal.mutants``): they stay in the
machine's own module.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value

from bayesmachine.params import MachineParams

from .counters import count_ones, overflow_counter_full, overflow_flags, room_width, sample_counter
from .nets import MachineNets, net, or_all
from .operator import bus_rows

__all__ = ["overflow_counters", "stop_decision"]


def overflow_counters(m: Module, n: MachineNets, p: MachineParams) -> None:
    """The overflow counters: with registered "full" flags (count == n_max) for one sample per
    clock, with registered ``room`` (n_max - count, capped at 2B) for B samples."""
    n.over = Signal(p.rows, name="over")
    if p.samples_per_clock > 1:
        # B samples: each row's flags F_i (overflowed by sample i) from its bits and room.
        b = p.samples_per_clock
        n.room = [Signal(room_width(b), name=f"room_{r}", init=min(p.counter_max, 2 * b))
                  for r in range(p.rows)]
        n.flags = [net(m, f"flags_{r}", overflow_flags(n.row[r * b:(r + 1) * b], n.room[r]))
                   for r in range(p.rows)]
        return
    n.full = Signal(p.rows, name="full")
    for r in range(p.rows):
        ov, nxt, nfull = overflow_counter_full(n.row[r], n.counts[r], n.full[r], p.counter_max)
        m.d.comb += n.over[r].eq(ov)
        n.next_counts.append(nxt)
        n.next_full.append(nfull)


def _group_flags(m: Module, n: MachineNets, p: MachineParams, terms: list[list[Value]], start: list[Value],
                 name: str) -> Value:
    """Per group of rows, a register holding the OR of its rows' ``terms`` (the next cycle's
    overflows, prefetched: loaded in a compute cycle) or ``start`` (its value after a swap, which
    takes priority); returns the OR over the groups, a function of registers only."""
    width = len(Cat(terms[0]))
    regs = [Signal(width, name=f"{name}_{g}") for g in range(n.groups)]
    for g in range(n.groups):
        group = range(g * n.rows_per_group, min(p.rows, (g + 1) * n.rows_per_group))
        with m.If(n.start_rep[g]):
            m.d.sync += regs[g].eq(start[g])
        with m.Elif(n.compute_rep[g]):
            m.d.sync += regs[g].eq(or_all([Cat(terms[r]) for r in group]))
    return or_all(regs)


def _overflow_detect(m: Module, n: MachineNets, p: MachineParams) -> None:
    """Whether some row overflows in this compute cycle (``any_over``) and, with B samples, the
    first sample at which one does (``G``, cumulative flags over the rows).

    With prefetched comparators that is known a cycle early, per group of rows: the next cycle's
    overflows from the next bits and the counters' next state, ORed over the group's rows into
    registers (their value after a swap: none can overflow in a run's first cycle, nor, without
    the bubble, in its second: counter max >= 2B). The stop is then an OR of registers."""
    cols, b = p.operator_columns, p.samples_per_clock
    if b == 1:
        if n.next_bits:
            terms = [[bus_rows(n.next_bits[r * cols:(r + 1) * cols], 1, cols) & n.next_full[r]]
                     for r in range(p.rows)]
            n.any_over = _group_flags(m, n, p, terms, [Const(0)] * n.groups, "over_group")
        else:
            n.any_over = n.over.any()
        n.hit = n.any_over  # an overflow within the watchdog's limit
        return
    if n.next_bits:
        # The next cycle's 1s of row r follow this cycle's (all counted: a cycle that stops is
        # followed by a swap, whose value takes priority). The buses are nets of their own: each
        # sample's flag reads them.
        def bus(name: str, bits: list[Value], r: int) -> Value:
            return net(m, f"{name}_{r}", bus_rows(bits[r * cols:(r + 1) * cols], 1, cols, b))

        terms = [[overflow_flags(bus("next_row", n.next_bits, r), n.room[r],
                                 count_ones(n.row[r * b:(r + 1) * b]))] for r in range(p.rows)]
        start = [Const(0, b)] * n.groups
        if not n.hidden and p.counter_max < b:  # a run's first cycle can overflow: its flags
            first = [overflow_flags(bus("swap_row", n.swap_bits, r), Const(p.counter_max))
                     for r in range(p.rows)]
            per = n.rows_per_group
            start = [or_all(first[g * per:(g + 1) * per]) for g in range(n.groups)]
        flags = _group_flags(m, n, p, terms, start, "over_group")
    else:
        flags = or_all(n.flags)
    # The watchdog stops at sample max_cycles: sample ``limit`` of the last cycle.
    limit = p.max_cycles - (p.max_clocks - 1) * b
    watchdog = Const(((1 << b) - 1) >> (limit - 1) << (limit - 1), b)
    n.G = Signal(b, name="stop_samples")
    m.d.comb += n.G.eq(flags | Mux(n.at_last, watchdog, 0))
    n.any_over = flags[b - 1]
    n.hit = flags[limit - 1] | ~n.at_last


def stop_decision(m: Module, n: MachineNets, p: MachineParams) -> None:
    """The registered stop: a row overflows or the watchdog expires; counters advance."""
    # A compute cycle: running and not yet stopped. The stop is registered (see "Timing" in
    # docs/architecture.md), so every wide enable is a function of registers only, never of
    # the matrix.
    m.d.comb += n.compute.eq(n.running & ~n.stop)
    # The watchdog, registered too: ``at_last`` is high in compute cycle k == max_clocks.
    n.at_last = Signal(name="at_last")
    _overflow_detect(m, n, p)
    finish = Signal()
    m.d.comb += finish.eq(n.compute & (n.any_over | n.at_last))
    n.over_q = Signal(p.rows, name="over_q")
    with m.If(n.compute):
        m.d.sync += [
            n.cycles_done.eq(n.cycles_done + 1),
            n.at_last.eq(n.cycles_done == p.max_clocks - 2),  # max_clocks >= 2: never at start
            n.stop.eq(finish),
        ]
    b = p.samples_per_clock
    if b > 1:
        # The first stop sample (one-hot, 0 if none) and the samples up to it, which count.
        first = net(m, "stop_sample", n.G & ~(n.G << 1)[:b])
        counted = net(m, "counted_samples", ~(n.G << 1)[:b])
        for r in range(p.rows):
            nxt, room = sample_counter(n.row[r * b:(r + 1) * b], n.counts[r], counted, p.counter_max)
            n.next_counts.append(nxt)
            m.d.comb += n.over[r].eq((n.flags[r] & first).any())
            with m.If(n.compute_rep[r // n.rows_per_group]):
                m.d.sync += [n.counts[r].eq(nxt), n.room[r].eq(room)]
    else:
        for r in range(p.rows):
            with m.If(n.compute_rep[r // n.rows_per_group]):
                m.d.sync += [n.counts[r].eq(n.next_counts[r]), n.full[r].eq(n.next_full[r])]
    _over_flags(m, n, p)


def _over_flags(m: Module, n: MachineNets, p: MachineParams) -> None:
    """``over_q``: the rows that overflowed at the stop, for the MAP encoder in the bubble. With
    ``timeout_answer = "leading"`` a timeout sets every row and a search keeps the rows with the
    largest count, a bit per two cycles from the top (``search``: the bubble waits for it)."""
    leading = p.timeout_answer == "leading"
    n.timeout_now = timeout_now = n.at_last & ~n.hit  # this compute cycle ends without an overflow
    if leading:
        n.timed_out = Signal(name="timed_out")
        n.search = Signal(name="search")
        phase = Signal(name="search_phase")
        bit = Signal(p.counter_width, name="search_bit", init=1 << (p.counter_width - 1))  # one-hot
        any_g = [Signal(name=f"search_any_{g}") for g in range(n.groups)]
        n.search_phase, n.search_bit, n.search_any = phase, bit, any_g
        last = Signal()
        m.d.comb += last.eq(n.search & phase & bit[0])
        n.search_n = Mux(n.compute, timeout_now, n.search & ~last)
        with m.If(n.compute):
            m.d.sync += [n.timed_out.eq(timeout_now), n.search.eq(timeout_now), phase.eq(0),
                         bit.eq(1 << (p.counter_width - 1))]
        with m.Elif(n.search):
            m.d.sync += [phase.eq(~phase), n.search.eq(~last)]
            with m.If(phase):
                m.d.sync += bit.eq(bit >> 1)
        step = n.search & phase
        any_set = or_all(any_g)
    for r in range(p.rows):
        g = r // n.rows_per_group
        with m.If(n.compute_rep[g]):
            over = n.over[r] | timeout_now if leading else n.over[r]
            m.d.sync += n.over_q[r].eq(over)
        if leading:
            set_bit = (n.counts[r] & bit).any()
            with m.Elif(step):
                m.d.sync += n.over_q[r].eq(n.over_q[r] & (set_bit | ~any_set))
    if leading:
        for g in range(n.groups):
            group = range(g * n.rows_per_group, min(p.rows, (g + 1) * n.rows_per_group))
            m.d.sync += any_g[g].eq(or_all([n.over_q[r] & (n.counts[r] & bit).any() for r in group]))

