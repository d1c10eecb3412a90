"""Overflow counters: one per row of the matrix, counting the 1s of the row's bus signal.

Per compute cycle (``docs/architecture.md``)::

    over  = row & (count == n_max)      # overflow on the (n_max + 1)-th 1
    count = count + (row & ~over)       # an overflowing counter stays at n_max

so a counter is ``bit_length(n_max)`` bits and never wraps: at the stop the winner holds
n_max and the others their counts, the estimate p_j ~ count_j / n_max.

With B samples per clock (``samples_per_clock``) a counter takes its row's B bits at once, in
sample order: :func:`overflow_flags` says by which sample it has overflowed (its 1s up to sample i
exceed its ``room``, n_max - count, kept capped at 2B in a register), the machine picks the first
sample at which any row has, and :func:`sample_counter` adds the 1s up to that sample (all B when
no row overflows), capped at n_max: the counts of the one-sample counter at that sample.
"""

from __future__ import annotations

from collections.abc import Sequence

from amaranth.hdl import Cat, Const, Mux, Value

__all__ = ["count_ones", "overflow_counter", "overflow_counter_full", "overflow_counter_full_twin",
           "overflow_counter_twin", "overflow_flags", "overflow_flags_twin", "room_width", "sample_counter",
           "sample_counter_twin"]


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


def room_width(samples: int) -> int:
    """Bits of a row's ``room`` register: n_max - count capped at 2B (the prefetch adds two clocks' 1s)."""
    return (2 * samples).bit_length()


def count_ones(bits: Sequence[Value] | Value) -> Value:
    """The number of 1s of ``bits`` (an adder tree: Amaranth's sum is a chain, this halves it)."""
    parts: list[Value] = [Value.cast(b) for b in bits]
    if not parts:
        return Const(0, 1)
    while len(parts) > 1:
        parts = [parts[i] + parts[i + 1] if i + 1 < len(parts) else parts[i] for i in range(0, len(parts), 2)]
    return parts[0]


def overflow_flags(bits: Value, room: Value, earlier: Value | int = 0) -> Value:
    """``Cat(F_0, ..., F_(B-1))``, F_i: the row has overflowed by sample i, its 1s in samples 0 ... i
    (``bits``, sample i at bit i), plus ``earlier`` 1s counted before them, exceed ``room``. The flags
    are cumulative (once set, set for every later sample)."""
    return Cat(*((count_ones(bits[: i + 1]) + earlier) > room for i in range(len(bits))))


def overflow_flags_twin(bits: Sequence[int], room: int, earlier: int = 0) -> list[int]:
    """Python twin of :func:`overflow_flags` (``bits`` in sample order)."""
    return [int(sum(bits[: i + 1]) + earlier > room) for i in range(len(bits))]


def sample_counter(bits: Value, count: Value, counted: Value, n_max: int) -> tuple[Value, Value]:
    """One counter over a clock of B samples: returns ``(next_count, next_room)``.

    ``counted``: the samples that count (those up to the run's stop, every one when it goes on).
    ``next_count`` = min(n_max, count + the counted 1s): an overflowing row stops at n_max, the
    others hold their counts at the stop. ``next_room`` = min(n_max - next_count, 2B)."""
    samples = len(bits)
    total = count + count_ones(bits & counted)
    next_count = Mux(total > n_max, n_max, total)[: len(count)]
    left = n_max - next_count
    next_room = Mux(left > 2 * samples, 2 * samples, left)[: room_width(samples)]
    return next_count, next_room


def sample_counter_twin(bits: Sequence[int], count: int, counted: Sequence[int],
                        n_max: int) -> tuple[int, int]:
    """Python twin of :func:`sample_counter`."""
    nxt = min(n_max, count + sum(b & c for b, c in zip(bits, counted, strict=True)))
    return nxt, min(n_max - nxt, 2 * len(bits))
