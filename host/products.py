"""Exact products of likelihood-memory words, of any width, for the word reference's numba kernels.

A product of n words of W bits (each at most 2^W) is held, per hypothesis, in one int64 while nW <= 62
bits (:data:`TOP_BITS`), else in :func:`limbs_for` (n, W) limbs: 32-bit limbs, the least significant
first, below a top limb of up to 62 bits (never the int64's sign). A pixel's values ``v`` are then
(M,) int64 or (M, L) limbs; :func:`exact_store`, :func:`exact_times`, :func:`exact_float` and
:func:`exact_greater` are compiled for both (numba overloads on ``v``'s dimension), the one-int64 form as
plain int64 arithmetic. The float64 value of limbs is the top limb, times 2^32 plus the next, and so on:
the correctly rounded product up to two limbs (94 bits: any model of the package).
"""

from __future__ import annotations

import numba
import numpy as np
from numba.extending import overload

__all__ = ["TOP_BITS", "LIMB_BITS", "limbs_for", "exact_store", "exact_times", "exact_float", "exact_greater"]

_MASK32 = np.int64(0xFFFFFFFF)
_BASE = 4294967296.0  # 2^32: a limb's weight
# An exact product's top limb holds up to 62 bits (int64, never its sign); the lower limbs 32 each.
TOP_BITS = 62
LIMB_BITS = 32


def limbs_for(factors: int, word_bits: int) -> int:
    """Limbs of an exact product of ``factors`` words of ``word_bits`` bits (each at most 2^W): one int64
    while it fits :data:`TOP_BITS`, and a 32-bit limb below it for every 32 bits more."""
    return 1 + max(0, -(-(factors * word_bits - TOP_BITS) // LIMB_BITS))


# A pixel's exact values ``v``: (M,) int64 when a product fits one int64, else (M, L) limbs (module text).
def exact_store(v, d, value):  # pragma: no cover
    """v[d] = value (an int64 of up to 62 bits)."""
    raise NotImplementedError("compiled by numba only")


def exact_times(v, d, word):  # pragma: no cover
    """v[d] *= word, exactly."""
    raise NotImplementedError("compiled by numba only")


def exact_float(v, d):  # pragma: no cover
    """v[d] in float64: one int64, float(v); limbs, the top one first, times 2^32 plus the next..."""
    raise NotImplementedError("compiled by numba only")


def exact_greater(v, d, e):  # pragma: no cover
    """Exactly v[d] > v[e]."""
    raise NotImplementedError("compiled by numba only")


# The limbs' arithmetic, inlined into the kernels (an array passed to a call would cost a reference
# count each time); written without a scalar carried from one iteration to the next.
@numba.njit(cache=True, inline="always")
def _store_limbs(v, d, value):  # pragma: no cover
    v[d, 0] = value & _MASK32
    v[d, 1] = value >> LIMB_BITS
    for i in range(2, v.shape[1]):
        v[d, i] = 0


@numba.njit(cache=True, inline="always")
def _times_limbs(v, d, word):  # pragma: no cover
    for i in range(v.shape[1]):
        v[d, i] = v[d, i] * word
    for i in range(v.shape[1] - 1):  # each limb's bits past 32 go up into the next
        v[d, i + 1] = v[d, i + 1] + (v[d, i] >> 32)
        v[d, i] = v[d, i] & _MASK32


@numba.njit(cache=True, inline="always")
def _float_limbs(v, d):  # pragma: no cover
    f = 0.0
    for i in range(v.shape[1] - 1, -1, -1):
        f = f * _BASE + float(v[d, i])
    return f


@numba.njit(cache=True, inline="always")
def _greater_limbs(v, d, e):  # pragma: no cover
    i = v.shape[1] - 1
    while i > 0 and v[d, i] == v[e, i]:
        i -= 1
    return v[d, i] > v[e, i]


# Inlined into the kernels: the one-int64 form is a multiply, the limbs' a call.
@overload(exact_store, inline="always")
def _store_for(v, d, value):  # pragma: no cover
    if v.ndim == 1:
        def one(v, d, value):
            v[d] = value
        return one
    return lambda v, d, value: _store_limbs(v, d, value)


@overload(exact_times, inline="always")
def _times_for(v, d, word):  # pragma: no cover
    if v.ndim == 1:
        def one(v, d, word):
            v[d] = v[d] * word
        return one
    return lambda v, d, word: _times_limbs(v, d, word)


@overload(exact_float, inline="always")
def _float_for(v, d):  # pragma: no cover
    if v.ndim == 1:
        return lambda v, d: float(v[d])
    return lambda v, d: _float_limbs(v, d)


@overload(exact_greater, inline="always")
def _greater_for(v, d, e):  # pragma: no cover
    if v.ndim == 1:
        return lambda v, d, e: v[d] > v[e]
    return lambda v, d, e: _greater_limbs(v, d, e)
