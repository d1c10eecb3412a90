"""The energy form of a table: integer codes of −ln of a likelihood, in fixed steps.

One definition for what sums likelihoods instead of multiplying them: the fused column (its members'
energies added per row, the smallest sum subtracted, one table back to a word) and the logarithmic
integrator (every column's codes added per row, the smallest sum is the MAP). A likelihood L is the
code ``E = round(−ln L / step)`` (round half up), :data:`ENERGY_STEP` nats per code, saturated at
``2^ENERGY_MAX_BITS − 1`` (a likelihood of 0 too: the saturated code stands for "at least that
energy"); codes are nondecreasing in the cost because the tables are nonincreasing in it. The way
back is :func:`exp_table`: ``X[e] = round(2^b · exp(−e · step))``, from ``X[0] = 2^b`` down to its
first 0, so a sum ``e`` codes above the pixel's smallest reads ``X[min(e, len(X) − 1)]``.

The step and the widths are chosen by measurement (docs/architecture.md, "The energy form").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.checks import as_int, as_real
from bayesmachine.errors import ParameterError

from .base import quantize

__all__ = ["ENERGY_STEP", "ENERGY_MAX_BITS", "INFINITE_CODE", "LOG_CODE_BITS", "EnergyTable", "energy_codes",
           "exp_table", "log_codes"]

# Nats per energy code.
ENERGY_STEP = 1.0 / 16.0
# The widest code of one table (codes saturate at 2^ENERGY_MAX_BITS - 1: 15.9 nats at 1/16 nat).
ENERGY_MAX_BITS = 8
# The logarithmic integrator's codes are one bit wider than the saturated ones, so that its all-ones code,
# infinite energy (the row is excluded), stands for a likelihood of exactly 0 only (a lane without a match
# pixel, the no-match row of a pass without one), never for a saturated one (docs/architecture.md).
LOG_CODE_BITS = ENERGY_MAX_BITS + 1
INFINITE_CODE = (1 << LOG_CODE_BITS) - 1


def energy_codes(p: np.ndarray | float, step: float = ENERGY_STEP,
                 max_bits: int = ENERGY_MAX_BITS) -> np.ndarray:
    """Likelihoods -> energy codes (uint16): ``round(−ln p / step)`` half up, saturated at
    ``2^max_bits − 1`` (p = 0 included). ``p`` outside [0, 1] or NaN is an error (a bug upstream)."""
    arr = np.asarray(p, dtype=np.float64)
    bad = ~((arr >= 0.0) & (arr <= 1.0))
    if bad.any():
        raise ValueError(f"likelihoods must be in [0, 1] to code, got {arr[bad].flat[0]!r}")
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step must be a finite number > 0, got {step!r}")
    top = (1 << as_int("max_bits", max_bits, 1, 15)) - 1
    with np.errstate(divide="ignore"):
        e = -np.log(arr) / step  # +inf at p = 0
    codes = np.floor(np.minimum(e, top) + 0.5)
    return np.minimum(codes, top).astype(np.uint16)


def log_codes(p: np.ndarray | float, step: float = ENERGY_STEP) -> np.ndarray:
    """Likelihoods -> the logarithmic integrator's codes (uint16, :data:`LOG_CODE_BITS` bits): the energy
    code of a likelihood above 0 (:func:`energy_codes`, saturated at ``2^ENERGY_MAX_BITS − 1``) and
    :data:`INFINITE_CODE` for a likelihood of 0."""
    arr = np.asarray(p, dtype=np.float64)
    return np.where(arr == 0.0, INFINITE_CODE, energy_codes(arr, step)).astype(np.uint16)


def exp_table(bits: int, step: float = ENERGY_STEP) -> np.ndarray:
    """``X[e] = round(2^bits · exp(−e · step))`` (round half up) for e = 0 up to the first e where it is
    0 (included): uint16, nonincreasing, ``X[0] = 2^bits``, its last entry 0."""
    as_int("bits", bits, 1, 15)
    if not as_real("step", step) > 0:
        raise ParameterError(f"step must be a finite number > 0, got {step!r}", "step")
    # exp(-e step) < 2^-(bits+1) from e > (bits + 1) ln 2 / step: one past it is 0.
    n = int(np.ceil((bits + 1) * np.log(2.0) / step)) + 2
    x = quantize(np.exp(-np.arange(n) * step), bits)
    return x[: int(np.flatnonzero(x == 0)[0]) + 1]


@dataclass(frozen=True, eq=False)
class EnergyTable:
    """A term's energy codes indexed by its cost (``values``, uint16, nondecreasing), its no-match row's
    constant entries (``nomatch``), the width that holds every one of them (``bits``) and ``step``."""

    values: np.ndarray
    nomatch: tuple[int, ...]
    bits: int
    step: float

    @property
    def one(self) -> int:
        """The code of a likelihood of 1: a column's no-match entry of 1 reads it, as ``Table.one``."""
        return 0

    @classmethod
    def of(cls, values: np.ndarray, nomatch: tuple[float, ...], step: float = ENERGY_STEP) -> EnergyTable:
        """The energy form of float64 likelihoods ``values`` and no-match entries ``nomatch``."""
        codes = energy_codes(values, step)
        entries = tuple(int(c) for c in energy_codes(np.asarray(nomatch, dtype=np.float64), step))
        top = max(int(codes.max(initial=0)), *entries, 1)
        return cls(codes, entries, top.bit_length(), step)
