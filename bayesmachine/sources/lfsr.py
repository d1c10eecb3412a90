"""Leap-forward maximal-length LFSRs: the definition shared by the RTL and the model (no Amaranth).

An LFSR is a Fibonacci LFSR of length L whose bit sequence obeys
``s[t+L] = XOR(s[t+i] for i in taps)`` (``0 in taps``; characteristic polynomial
``x^L + sum(x^i for i in taps)``, primitive, so the period is 2**L - 1). The state holds
``s[t] ... s[t+L-1]`` (bit i = s[t+i]). One clock advances the sequence by W bits at once
(leap-forward), which is cheap because every tap is at most L - W: each new bit is the XOR
of at most 6 state bits, one LUT6. The LFSR's W-bit random number is its W oldest bits,
so consecutive numbers are disjoint chunks of the m-sequence: a comparator never re-reads a
bit, unlike a register that shifts by one bit per cycle (see ``tests/sources/test_lfsr.py``, which
measures both).

The ``lfsr`` source gives every operator its own LFSR (:func:`lfsr_specs`); ``lfsr-shared``
one per operator column (:func:`column_lfsr_specs`), and the ``sobol`` source draws its
per-block random digital shifts from the same column LFSRs. This module holds the polynomial
search, the bit-serial reference sequence and the per-cycle twin :func:`lfsr_step`; the RTL
(``bayesmachine.hdl.sources``) and the model's kernels (``bayesmachine.sim.model``) build on it.
"""

from __future__ import annotations

import functools
import itertools
import math
import random
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from bayesmachine.errors import ParameterError

if TYPE_CHECKING:  # sources never import params at run time: params validates through them
    from bayesmachine.params import MachineParams

__all__ = [
    "MAX_TAPS",
    "LFSRSpec",
    "column_lfsr_specs",
    "is_primitive",
    "lfsr_bit_sequence",
    "lfsr_specs",
    "lfsr_step",
    "lfsr_numbers",
    "splitmix64",
]

_MASK64 = (1 << 64) - 1


# --- GF(2) polynomial arithmetic (polynomials as Python ints, bit i = coefficient of x^i) ---

def _poly_from_taps(length: int, taps: tuple[int, ...]) -> int:
    poly = 1 << length
    for t in taps:
        poly |= 1 << t
    return poly


def _reduce(a: int, poly: int, length: int) -> int:
    low_mask = (1 << length) - 1
    low_poly = poly & low_mask
    while a >> length:
        high = a >> length
        a &= low_mask
        # x^L == sum of the low terms, so fold the high part back in.
        p = low_poly
        while p:
            lsb = p & -p
            a ^= high << (lsb.bit_length() - 1)
            p ^= lsb
    return a


def _square(a: int) -> int:
    # Squaring over GF(2) spreads the bits: coefficient i moves to 2i.
    r = 0
    i = 0
    while a:
        if a & 1:
            r |= 1 << (2 * i)
        a >>= 1
        i += 1
    return r


def _x_pow(exponent: int, poly: int, length: int) -> int:
    r = 1
    for bit in bin(exponent)[2:]:
        r = _reduce(_square(r), poly, length)
        if bit == "1":
            r = _reduce(r << 1, poly, length)
    return r


def _is_probable_prime(n: int) -> bool:
    if n < 2:
        return False
    small = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37)
    for p in small:
        if n % p == 0:
            return n == p
    d, s = n - 1, 0
    while d % 2 == 0:
        d //= 2
        s += 1
    for a in small:  # deterministic for n < 3.3e24
        x = pow(a, d, n)
        if x in (1, n - 1):
            continue
        for _ in range(s - 1):
            x = x * x % n
            if x == n - 1:
                break
        else:
            return False
    return True


def _pollard_rho(n: int) -> int:
    if n % 2 == 0:
        return 2
    for c in itertools.count(1):
        x = y = 2
        d = 1
        while d == 1:
            x = (x * x + c) % n
            y = (y * y + c) % n
            y = (y * y + c) % n
            d = math.gcd(abs(x - y), n)
        if d != n:
            return d
    raise AssertionError("unreachable")


@functools.cache
def _prime_factors(n: int) -> tuple[int, ...]:
    if n == 1:
        return ()
    if _is_probable_prime(n):
        return (n,)
    d = _pollard_rho(n)
    return tuple(sorted(set(_prime_factors(d) + _prime_factors(n // d))))


def is_primitive(length: int, taps: tuple[int, ...]) -> bool:
    """Whether x^L + sum(x^i, i in taps) is primitive over GF(2) (the LFSR is maximal length).

    x has order exactly 2**L - 1 modulo the polynomial iff it is primitive (a ring whose unit
    group has 2**L - 1 elements is a field, so primitivity implies irreducibility).
    """
    if 0 not in taps:
        return False
    poly = _poly_from_taps(length, taps)
    order = (1 << length) - 1
    if _x_pow(order, poly, length) != 1:
        return False
    return all(_x_pow(order // q, poly, length) != 1 for q in _prime_factors(order) if q != order)


# --- Seeds ---

def splitmix64(seed: int, index: int) -> int:
    """SplitMix64 output number ``index`` of the stream seeded by ``seed``."""
    z = (seed + (index + 1) * 0x9E3779B97F4A7C15) & _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


# --- LFSR specification, reference sequence and per-cycle twin ---

MAX_TAPS = 6  # XOR inputs per new bit, the constant term included: one LUT6 (heptanomials)


@dataclass(frozen=True)
class LFSRSpec:
    """One LFSR: length L, taps (0 first, increasing), W bits per clock, start state.

    The tap set has an even size of at most :data:`MAX_TAPS`: the polynomial has odd weight (3, 5
    or 7 terms, so x + 1 never divides it), and the model's kernel XORs exactly MAX_TAPS shifted
    copies of the state, padding with pairs of 0 shifts that cancel.
    """

    length: int
    taps: tuple[int, ...]
    step: int
    init: int

    def __post_init__(self) -> None:
        if not 0 < self.step <= self.length:
            raise ParameterError(f"LFSR step {self.step} must be in [1, {self.length}]")
        taps = self.taps
        increasing = all(a < b for a, b in zip(taps, taps[1:], strict=False))
        if (not isinstance(taps, tuple) or not taps or taps[0] != 0 or not increasing
                or max(taps) > self.length - self.step):
            raise ParameterError(
                f"LFSR taps {taps!r} must be a tuple starting at 0, strictly increasing, "
                f"each <= L - W = {self.length - self.step}"
            )
        if len(taps) % 2 or len(taps) > MAX_TAPS:
            raise ParameterError(
                f"LFSR taps {taps!r}: need an even number of taps, at most {MAX_TAPS} "
                f"(a polynomial of weight 3, 5 or 7)"
            )
        if not 0 < self.init < (1 << self.length):
            raise ParameterError(f"LFSR start state must be a non-zero {self.length}-bit value")

    @property
    def period(self) -> int:
        return (1 << self.length) - 1


def lfsr_bit_sequence(spec: LFSRSpec, count: int) -> list[int]:
    """The textbook bit-serial sequence s[0], s[1], ... from the start state."""
    bits = [(spec.init >> i) & 1 for i in range(spec.length)]
    while len(bits) < count:
        t = len(bits) - spec.length
        b = 0
        for i in spec.taps:
            b ^= bits[t + i]
        bits.append(b)
    return bits[:count]


def lfsr_step(state: int, spec: LFSRSpec) -> tuple[int, int]:
    """One clock of the leap-forward LFSR: returns (this cycle's W-bit number, next state)."""
    w, length = spec.step, spec.length
    mask = (1 << w) - 1
    new = 0
    for t in spec.taps:
        new ^= state >> t
    return state & mask, (state >> w) | ((new & mask) << (length - w))


def lfsr_numbers(spec: LFSRSpec, count: int, state: int | None = None) -> Iterator[int]:
    """The W-bit numbers of ``count`` consecutive clocks."""
    s = spec.init if state is None else state
    for _ in range(count):
        n, s = lfsr_step(s, spec)
        yield n


@functools.lru_cache(maxsize=64)
def _primitive_tap_sets(length: int, max_tap: int, count: int, seed: int) -> tuple[tuple[int, ...], ...]:
    """Up to ``count`` distinct primitive tap sets with taps <= max_tap, drawn by ``seed``.

    Candidates are trinomials, pentanomials and heptanomials (odd weight, so x + 1 never
    divides them): at most 6 XOR inputs per new bit.
    """
    rnd = random.Random(seed)
    middles = range(1, max_tap + 1)
    sizes = [k for k in (1, 3, 5) if k <= max_tap]
    space = sum(math.comb(max_tap, k) for k in sizes)
    found: list[tuple[int, ...]] = []
    if space <= 40_000:
        candidates: list[tuple[int, ...]] = [c for k in sizes for c in itertools.combinations(middles, k)]
        rnd.shuffle(candidates)
        iterator: Iterator[tuple[int, ...]] = iter(candidates)
    else:
        def draw() -> Iterator[tuple[int, ...]]:
            # Heptanomials at random (without repetition), then, if they run out, the rest.
            big = sizes[-1]
            seen: set[tuple[int, ...]] = set()
            while len(seen) < math.comb(max_tap, big):
                c = tuple(sorted(rnd.sample(middles, big)))
                if c not in seen:
                    seen.add(c)
                    yield c
            for k in sizes[:-1]:
                yield from itertools.combinations(middles, k)
        iterator = draw()
    for middle in iterator:
        taps = (0, *middle)
        if is_primitive(length, taps):
            found.append(taps)
            if len(found) == count:
                break
    return tuple(found)


@functools.lru_cache(maxsize=64)
def _has_primitive(length: int, max_tap: int) -> bool:
    return bool(_primitive_tap_sets(length, max_tap, 1, 0))


def _no_polynomial(length: int, w: int) -> ParameterError:
    from bayesmachine.params import DEFAULT_LFSR_BITS  # only for the message (no import cycle)

    return ParameterError(
        f"lfsr_bits = {length}: no primitive LFSR polynomial of that length has taps <= {length - w} "
        f"(lfsr_bits - word_bits) and at most 6 XOR inputs; choose another lfsr_bits "
        f"(the default {DEFAULT_LFSR_BITS} works for every word_bits)")


def check_lfsr_params(params: MachineParams) -> None:
    """Raise ParameterError if no LFSR of ``params.lfsr_bits`` bits can step W bits per cycle."""
    if not _has_primitive(params.lfsr_bits, params.lfsr_bits - params.word_bits):
        raise _no_polynomial(params.lfsr_bits, params.word_bits)


def _specs(params: MachineParams, count: int, salt: int) -> list[LFSRSpec]:
    length, w = params.lfsr_bits, params.word_bits
    tap_sets = _primitive_tap_sets(length, length - w, count, params.seed)
    if not tap_sets:
        raise _no_polynomial(length, w)
    specs = []
    used: set[int] = set()
    for o in range(count):
        k = 0
        while True:
            init = splitmix64(params.seed ^ salt, (o << 8) + k) & ((1 << length) - 1)
            if init and init not in used:
                break
            k += 1
        used.add(init)
        specs.append(LFSRSpec(length, tap_sets[o % len(tap_sets)], w, init))
    return specs


def lfsr_specs(params: MachineParams) -> list[LFSRSpec]:
    """The LFSR of every operator of the machine (``rng = "lfsr"``), in operator order
    (r * operator_columns + c).

    Polynomials are distinct per operator wherever the polynomial space allows; start states
    are distinct non-zero values derived from the machine seed.
    """
    return _specs(params, params.operators, 0)


# Column LFSRs draw other start states than the per-operator ones of the same seed.
_COLUMN_SALT = 0x5C0_1A55


def column_lfsr_specs(params: MachineParams) -> list[LFSRSpec]:
    """One LFSR per operator column (``lfsr-shared`` numbers, ``sobol`` shifts), column order.

    The polynomials are the first ``operator_columns`` of the same draw as :func:`lfsr_specs`
    (distinct); the start states come from SplitMix64 of the seed XOR a fixed salt.
    """
    return _specs(params, params.operator_columns, _COLUMN_SALT)
