"""Properties of the overflow counter, on the very function the machine instantiates
(``hdl.machine.counters.overflow_counter_full``), driven as the machine drives it: a ``clear`` (the run's
start, which empties the counters) and an ``enable`` (a compute cycle) per clock, and the row's
stochastic bus bit, all three free."""

from __future__ import annotations

from collections.abc import Callable

from amaranth.hdl import Assert, Cover, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In

from bayesmachine.checks import as_int
from bayesmachine.hdl.machine.counters import overflow_counter_full

__all__ = ["CounterFn", "CounterProperties"]

CounterFn = Callable[[Value, Value, Value, int], tuple[Value, Value, Value]]


class CounterProperties(wiring.Component):
    """A formal-only wrapper: one overflow counter (with its registered full flag) and its properties.

    Parameters
    ----------
    n_max : int
        The counter max (>= 1).
    counter : callable
        The counter's logic, ``(row, count, full, n_max) -> (over, next_count, next_full)``;
        ``overflow_counter_full`` (the machine's) unless a mutant is being checked.
    clear_full : bool
        Whether ``clear`` empties the full flag as well as the count (as the machine's run start
        does); False only for a mutant.

    Attributes
    ----------
    row : ``In(1)``
        The row's stochastic bus bit (free).
    enable : ``In(1)``
        A compute cycle: the counter advances (free).
    clear : ``In(1)``
        The run's start: the counter and its flag restart empty (free; wins over ``enable``, as
        the machine's start assignments come after its compute-cycle ones).
    """

    def __init__(self, *, n_max: int, counter: CounterFn = overflow_counter_full,
                 clear_full: bool = True) -> None:
        n_max = as_int("n_max", n_max, 1)
        if not callable(counter):
            raise TypeError("counter must be callable")
        self._n_max = n_max
        self._counter = counter
        self._clear_full = bool(clear_full)
        super().__init__({"row": In(1), "enable": In(1), "clear": In(1)})

    @property
    def n_max(self) -> int:
        return self._n_max

    def elaborate(self, platform: object) -> Module:
        m = Module()
        n_max = self._n_max
        width = n_max.bit_length()
        count = Signal(width)
        full = Signal()
        over, next_count, next_full = self._counter(self.row, count, full, n_max)
        with m.If(self.clear):  # as the machine's _start: the counter and its flag restart empty
            m.d.sync += count.eq(0)
            if self._clear_full:
                m.d.sync += full.eq(0)
        with m.Elif(self.enable):
            m.d.sync += [count.eq(next_count), full.eq(next_full)]

        # The reference: the 1s counted since the last clear, saturating one past n_max.
        ones = Signal(range(n_max + 2))
        with m.If(self.clear):
            m.d.sync += ones.eq(0)
        with m.Elif(self.enable & self.row & (ones <= n_max)):
            m.d.sync += ones.eq(ones + 1)

        # The counter holds the 1s seen since the run's start, up to n_max, and stays at n_max
        # after overflowing: it never wraps (so the result's counts are p_j * n_max).
        m.d.comb += Assert(count == Mux(ones > n_max, n_max, ones), "count is min(ones seen, n_max)")
        # The full flag is exactly count == n_max (the machine's overflow is one AND with it).
        m.d.comb += Assert(full == (count == n_max), "full flag == (count == n_max)")
        # It overflows on its (n_max + 1)-th 1 and on no earlier one (and, held at n_max, on every
        # later 1); the machine stops on the first.
        m.d.comb += Assert(over == (self.row & (ones >= n_max)), "overflow exactly from the (n_max+1)-th 1")
        # Not vacuous: the first overflow, and a counter that overflowed and was cleared for the next
        # pixel (restarting empty: the asserts above hold right after the clear).
        first = Signal()
        m.d.sync += first.eq(self.enable & over & (ones == n_max))
        m.d.comb += Cover(self.enable & over & (ones == n_max))
        m.d.comb += Cover(first & self.clear)
        return m

