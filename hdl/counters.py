"""Overflow counters: one per row of the matrix, counting the 1s of the row's bus signal.

Per compute cycle (``docs/architecture.md``)::

    over  = row & (count == n_max)      # overflow on the (n_max + 1)-th 1
    count = count + (row & ~over)       # an overflowing counter stays at n_max

so a counter is ``bit_length(n_max)`` bits and never wraps: at the stop the winner holds
n_max and the others their counts, the estimate p_j ~ count_j / n_max.
"""

from __future__ import annotations

from amaranth.hdl import Value

__all__ = ["overflow_counter", "overflow_counter_full", "overflow_counter_full_twin", "overflow_counter_twin"]


def overflow_counter(row: Value, count: Value, n_max: int) -> tuple[Value, Value]:
    """One counter's logic: returns ``(over, next_count)`` (``next_count`` as wide as ``count``)."""
    over = row & (count == n_max)
    return over, (count + (row & ~over))[: len(count)]


def overflow_counter_twin(row: int, count: int, n_max: int) -> tuple[int, int]:
    """Python twin of :func:`overflow_counter`."""
    over = int(bool(row) and count == n_max)
    return over, count + (int(bool(row)) & (over ^ 1))


def overflow_counter_full(row: Value, count: Value, full: Value, n_max: int) -> tuple[Value, Value, Value]:
    """The counter with a registered "full" flag (``full == (count == n_max)``), as the machine uses it.

    Returns ``(over, next_count, next_full)``. Same counts as :func:`overflow_counter`, but the
    overflow is a single AND with a flag register instead of a compare in series with the
    stochastic bus, and the increment does not wait for the overflow (``row & ~over`` equals
    ``row & ~full``): the timing-critical path from the matrix is one gate shorter on both sides.
    """
    over = row & full
    next_count = (count + (row & ~full))[: len(count)]
    next_full = full | (row & (count == n_max - 1))
    return over, next_count, next_full


def overflow_counter_full_twin(row: int, count: int, full: int, n_max: int) -> tuple[int, int, int]:
    """Python twin of :func:`overflow_counter_full`."""
    r = int(bool(row))
    f = int(bool(full))
    return r & f, count + (r & (f ^ 1)), f | (r & int(count == n_max - 1))
