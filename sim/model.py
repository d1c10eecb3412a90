"""The NumPy machine model: the project's definition of what the hardware computes.

One model of the whole machine, bit for bit: given the parameters (hence every operator's
LFSR), and the likelihood-memory words of a sequence of pixels, it returns per pixel the
same counters, MAP, flags and cycle count as the RTL streams out after reset. The per-cycle
rules are in ``docs/architecture.md``; the inner loop is compiled with numba so that whole
frames run in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bayesmachine.hdl.rng import lfsr_specs
from bayesmachine.params import MachineParams

__all__ = ["MachineModel", "MachineResult", "check_words"]

_MAX_TAPS = 6  # taps per polynomial, the constant tap 0 included (heptanomials)


@dataclass
class MachineResult:
    """Per-pixel results, in load order."""

    counts: np.ndarray  # (P, rows) uint32: overflow counters at the stop (winner = n_max)
    map: np.ndarray  # (P,) int32: MAP row index (0 on timeout)
    nomatch: np.ndarray  # (P,) bool: the no-match row won
    timeout: np.ndarray  # (P,) bool: the watchdog stopped the run
    cycles: np.ndarray  # (P,) int64: compute cycles of the run

    def __len__(self) -> int:
        return len(self.map)

    @classmethod
    def concatenate(cls, parts: list[MachineResult], rows: int) -> MachineResult:
        if not parts:
            return cls.empty(rows)
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls.__dataclass_fields__))

    @classmethod
    def empty(cls, rows: int) -> MachineResult:
        return cls(
            np.zeros((0, rows), np.uint32),
            np.zeros(0, np.int32),
            np.zeros(0, bool),
            np.zeros(0, bool),
            np.zeros(0, np.int64),
        )

    def equal(self, other: MachineResult) -> bool:
        return all(np.array_equal(getattr(self, f), getattr(other, f)) for f in self.__dataclass_fields__)


def check_words(params: MachineParams, words: np.ndarray) -> np.ndarray:
    """Validate a block of pixels' likelihood-memory words; returns them as (P, operators) int32.

    Accepts shape (P, rows, operator_columns) or (P, operators); values must be integers in
    [0, 2**word_bits].
    """
    w = np.asarray(words)
    ops = params.operators
    if w.ndim == 3:
        if w.shape[1:] != (params.rows, params.operator_columns):
            raise ValueError(
                f"likelihood memories have shape {w.shape}; this machine expects "
                f"(pixels, {params.rows}, {params.operator_columns})"
            )
        w = w.reshape(w.shape[0], ops)
    elif w.ndim != 2 or w.shape[1] != ops:
        raise ValueError(
            f"likelihood memories have shape {w.shape}; this machine expects "
            f"(pixels, {params.rows}, {params.operator_columns}) or (pixels, {ops})"
        )
    if w.dtype.kind not in "iu":
        raise ValueError(f"likelihood memory words must be integers, got dtype {w.dtype}")
    if w.size and (w.min() < 0 or w.max() > params.word_one):
        raise ValueError(
            f"likelihood memory words must lie in [0, {params.word_one}] (p = q / 2**{params.word_bits}); "
            f"got [{w.min()}, {w.max()}]"
        )
    return np.ascontiguousarray(w, dtype=np.int32)


@numba.njit(cache=True, inline="always")
def _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index):
    """Stochastic bus and overflow counters for one compute cycle. Returns the MAP row or -1."""
    any_over = 0
    for r in range(rows):  # branch-free so that it vectorizes; the overflow path is rare
        b = bits[r * opcols]
        for c in range(1, opcols):
            b &= bits[r * opcols + c]
        ov = b & (counts[r] == n_max)
        over[r] = ov
        any_over |= ov
        counts[r] += b & (ov ^ 1)  # an overflowing counter stays at n_max
    if not any_over:
        return -1
    if nm_index >= 0 and over[nm_index]:
        return nm_index  # nomatch-first: the no-match row wins every tie it is part of
    for r in range(rows):
        if over[r]:
            return r
    return -1


@numba.njit(cache=True, inline="always")
def _store(p, counts, k, winner, out_counts, out_map, out_timeout, out_cycles):
    """Pixel p's result: counters at the stop, MAP (0 on timeout), timeout flag, cycles."""
    out_counts[p, :] = counts
    out_cycles[p] = k
    out_timeout[p] = winner < 0
    out_map[p] = max(winner, 0)


@numba.njit(cache=True)
def _run_lfsr(q, states, shifts, rows, opcols, word_bits, lfsr_bits, n_max, max_cycles, nm_index,
              out_counts, out_map, out_timeout, out_cycles):
    pixels, ops = q.shape
    mask = np.uint64((1 << word_bits) - 1)
    w = np.uint64(word_bits)
    top = np.uint64(lfsr_bits - word_bits)
    # Tap shifts as separate contiguous vectors so the operator loop vectorizes (SIMD).
    t1 = shifts[1].copy()
    t2 = shifts[2].copy()
    t3 = shifts[3].copy()
    t4 = shifts[4].copy()
    t5 = shifts[5].copy()
    bits = np.zeros(ops, np.uint8)
    counts = np.zeros(rows, np.uint32)
    over = np.zeros(rows, np.uint8)
    for p in range(pixels):
        qp = q[p]
        counts[:] = 0
        k = 0
        winner = -1
        while True:
            k += 1
            for o in range(ops):
                s = states[o]
                new = s ^ (s >> t1[o]) ^ (s >> t2[o]) ^ (s >> t3[o]) ^ (s >> t4[o]) ^ (s >> t5[o])
                states[o] = (s >> w) | ((new & mask) << top)
                bits[o] = (s & mask) < qp[o]
            winner = _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index)
            if winner >= 0 or k == max_cycles:
                break
        _store(p, counts, k, winner, out_counts, out_map, out_timeout, out_cycles)


@numba.njit(cache=True)
def _run_external(q, numbers, start, rows, opcols, n_max, max_cycles, nm_index,
                  out_counts, out_map, out_timeout, out_cycles):
    """Same machine, random numbers taken from ``numbers[t, o]``; returns cycles used, or -1 if
    the supply ran out (the pixel being run is then not reported)."""
    pixels, ops = q.shape
    t = start
    bits = np.zeros(ops, np.uint8)
    counts = np.zeros(rows, np.uint32)
    over = np.zeros(rows, np.uint8)
    for p in range(pixels):
        qp = q[p]
        counts[:] = 0
        k = 0
        winner = -1
        while True:
            if t >= numbers.shape[0]:
                return -1
            k += 1
            for o in range(ops):
                bits[o] = np.int64(numbers[t, o]) < qp[o]
            t += 1
            winner = _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index)
            if winner >= 0 or k == max_cycles:
                break
        _store(p, counts, k, winner, out_counts, out_map, out_timeout, out_cycles)
    return t - start


class MachineModel:
    """The whole machine, cycle-accurate and bit-exact with the RTL.

    The model keeps the LFSR states between calls, so running pixels in several chunks
    gives the same results as one call (as the hardware runs a stream of pixels).
    """

    def __init__(self, params: MachineParams) -> None:
        self._params = params
        self._nm_index = (
            params.rows - 1 if params.nomatch_row and params.tie_break == "nomatch-first" else -1
        )
        if params.rng == "lfsr":
            specs = lfsr_specs(params)
            self._init_states = np.array([s.init for s in specs], dtype=np.uint64)
            shifts = np.zeros((_MAX_TAPS, params.operators), dtype=np.uint64)
            for o, spec in enumerate(specs):
                taps = list(spec.taps) + [0] * (_MAX_TAPS - len(spec.taps))  # pairs of 0 cancel
                shifts[:, o] = taps
            self._shifts = shifts
        self.reset()

    @property
    def params(self) -> MachineParams:
        return self._params

    def reset(self) -> None:
        """Back to the state after a hardware reset."""
        if self._params.rng == "lfsr":
            self._states = self._init_states.copy()

    @property
    def lfsr_states(self) -> np.ndarray:
        """The current LFSR state of every operator (a copy)."""
        if self._params.rng != "lfsr":
            raise ValueError("this machine has no LFSRs (rng = 'external')")
        return self._states.copy()

    def run(self, words: np.ndarray, numbers: np.ndarray | None = None) -> MachineResult:
        """Run the machine on a sequence of pixels.

        ``words``: (P, rows, operator_columns) or (P, operators) integers in [0, 2**W].
        ``numbers``: only with ``rng = "external"``: (T, operators) W-bit random numbers, one
        row per compute cycle, consumed in order from the first; it must cover the whole run.
        """
        p = self._params
        q = check_words(p, words)
        n = q.shape[0]
        out = MachineResult(
            np.zeros((n, p.rows), np.uint32),
            np.zeros(n, np.int32),
            np.zeros(n, bool),
            np.zeros(n, bool),
            np.zeros(n, np.int64),
        )
        if p.rng == "lfsr":
            if numbers is not None:
                raise ValueError("random numbers are only taken with rng = 'external'")
            _run_lfsr(q.astype(np.uint64), self._states, self._shifts, p.rows, p.operator_columns,
                      p.word_bits, p.lfsr_bits, p.counter_max, p.max_cycles, self._nm_index,
                      out.counts, out.map, out.timeout, out.cycles)
        else:
            if numbers is None:
                raise ValueError("rng = 'external': pass the random numbers of every compute cycle")
            nums = np.asarray(numbers)
            if nums.ndim != 2 or nums.shape[1] != p.operators:
                raise ValueError(f"random numbers must have shape (cycles, {p.operators}), got {nums.shape}")
            if nums.size and (nums.min() < 0 or nums.max() >= (1 << p.word_bits)):
                raise ValueError(f"random numbers must be {p.word_bits}-bit unsigned integers")
            used = _run_external(q, np.ascontiguousarray(nums, dtype=np.int32), 0, p.rows,
                                 p.operator_columns, p.counter_max, p.max_cycles, self._nm_index,
                                 out.counts, out.map, out.timeout, out.cycles)
            if used < 0:
                raise ValueError(f"the {nums.shape[0]} cycles of random numbers ran out before the run ended")
        if p.nomatch_row:
            out.nomatch[:] = (~out.timeout) & (out.map == p.rows - 1)
        return out
