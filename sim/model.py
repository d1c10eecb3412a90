"""The NumPy machine model: the project's definition of what the hardware computes.

One model of the whole machine, bit for bit: given the parameters (hence the random source),
and the likelihood-memory words of a sequence of pixels, it returns per pixel the
same counters, MAP, flags and cycle count as the RTL streams out after reset. The per-cycle
rules are in ``docs/architecture.md``; the inner loop is compiled with numba so that whole
frames run in seconds. Two compiled kernels share the per-cycle bus/counter/encoder helpers:
``_run_on_chip`` runs every on-chip random source (``lfsr``, ``lfsr-shared``, ``sobol``: their
twins, from the definitions of ``bayesmachine.sources``, no Amaranth) and ``_run_numbers`` takes
an off-chip source's numbers (``external``, ``smtj``).
"""

from __future__ import annotations

import numba
import numpy as np

from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import EngineBase
from bayesmachine.sim.results import MachineResult, NumberFeed, answered, check_words, ran_out_error
from bayesmachine.sources.lfsr import MAX_TAPS, LFSRSpec, column_lfsr_specs, lfsr_specs
from bayesmachine.sources.sobol import sobol_points

__all__ = ["MachineModel", "MachineResult", "check_words", "column_scales", "feedback_result",
           "fill_feedback"]

_BLOCK = 4096  # clocks of random numbers fetched at a time from an off-chip source


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
def _leading_row(counts, nm_index):
    """The row with the largest count: the no-match row if it is among them under nomatch-first
    (``nm_index`` >= 0), else the lowest index (the MAP encoder's tie rule)."""
    best = counts.max()
    if nm_index >= 0 and counts[nm_index] == best:
        return nm_index
    for r in range(counts.shape[0]):
        if counts[r] == best:
            return r
    return 0


@numba.njit(cache=True, inline="always")
def _store(p, counts, k, winner, samples, leading, nm_index, out_counts, out_map, out_timeout, out_cycles):
    """Pixel p's result: counters at the stop, MAP, timeout flag, clocks (``k`` samples in clocks of
    ``samples``). A timeout's MAP is 0, or with ``leading`` the leading row. Returns the MAP (-1 for
    a timeout without an answer)."""
    out_counts[p, :] = counts
    out_cycles[p] = (k + samples - 1) // samples
    out_timeout[p] = winner < 0
    if winner < 0 and leading:
        winner = _leading_row(counts, nm_index)
    out_map[p] = max(winner, 0)
    return winner


@numba.njit(cache=True, inline="always")
def fill_feedback(qp, prev, start, fb, fb_nm, rows, opcols, nm_row, one):
    """A neighbour prior's feedback column (operator column 0) of a pixel from the previous result
    ``prev`` (a hypothesis row, or -1: no match, timeout, none yet): flat (every word 1.0) when the
    pixel starts a line or there is no previous hypothesis. With :func:`feedback_result`, the twin of
    ``hdl.machine.feedback.FeedbackPrior``."""
    last = fb.shape[0] - 1
    for r in range(rows):
        if start or prev < 0:
            qp[r * opcols] = one
        elif r == nm_row:
            qp[r * opcols] = fb_nm
        else:
            qp[r * opcols] = fb[min(abs(r - prev), last)]


@numba.njit(cache=True, inline="always")
def feedback_result(winner, timeout, nm_row):
    """The result a next pixel's feedback prior follows: the winning hypothesis row, else -1 (no
    match; a timeout, even one answered by its leading row: no information)."""
    return winner if winner >= 0 and not timeout and winner != nm_row else -1


@numba.njit(cache=True, inline="always")
def _step_lfsrs(states, t1, t2, t3, t4, t5, mask, w, top, nums):
    """Leap-forward step of every LFSR of ``states``; ``nums`` gets their numbers before the step."""
    for i in range(states.shape[0]):
        s = states[i]
        new = s ^ (s >> t1[i]) ^ (s >> t2[i]) ^ (s >> t3[i]) ^ (s >> t4[i]) ^ (s >> t5[i])
        states[i] = (s >> w) | ((new & mask) << top)
        nums[i] = s & mask


@numba.njit(cache=True)
def _run_on_chip(q, norm, states, shifts, points, per_operator, rows, opcols, word_bits, lfsr_bits, n_max,
                 max_cycles, nm_index, samples, leading, out_counts, out_map, out_timeout, out_cycles,
                 line_start, fb, fb_nm, nm_row, prev):
    """The on-chip sources, cycle by cycle.

    ``lfsr`` (``per_operator``): operator o reads its own LFSR, which steps every compute cycle.
    ``lfsr-shared`` (``points`` empty): one LFSR per operator column, stepping every compute cycle,
    read by every row of that column. ``sobol``: cycle k of a pixel gives column c
    ``points[j, c] ^ shift[c]``, j = (k - 1) mod 2^W; the column LFSRs step once per block (j = 0)
    to give the block's shifts (every pixel starts a block). With a neighbour prior (``line_start``
    not empty) each pixel's feedback column is formed first from ``prev[0]``, which carries the
    previous result over calls. ``norm[p, c]``: column c's number scale m for pixel p (normalize): its
    operators compare their words with ``(number * m) >> W`` (m = 2^W: the number itself).

    Sample by sample: with ``samples`` (B) per clock only ``sobol`` runs, whose pixels start blocks
    (a multiple of B) and whose blocks are whole clocks, so a clock's samples after the stop draw no
    shift the next pixel would have used: the numbers, hence the results, are B = 1's."""
    pixels, ops = q.shape
    mask = np.uint64((1 << word_bits) - 1)
    w = np.uint64(word_bits)
    top = np.uint64(lfsr_bits - word_bits)
    sobol = points.shape[0] > 0
    block = 1 << word_bits
    # Tap shifts as separate contiguous vectors so the LFSR loop vectorizes (SIMD).
    t1, t2, t3 = shifts[1].copy(), shifts[2].copy(), shifts[3].copy()
    t4, t5 = shifts[4].copy(), shifts[5].copy()
    shift = np.zeros(opcols, np.uint64)
    nums = np.zeros(states.shape[0], np.uint64)
    col_nums = np.zeros(opcols, np.uint64)
    bits = np.zeros(ops, np.uint8)
    counts = np.zeros(rows, np.uint32)
    over = np.zeros(rows, np.uint8)
    feedback = line_start.shape[0] > 0
    for p in range(pixels):
        qp = q[p]
        sh = norm[p]
        if feedback:
            fill_feedback(qp, prev[0], line_start[p], fb, fb_nm, rows, opcols, nm_row, 1 << word_bits)
        counts[:] = 0
        k = 0
        winner = -1
        while True:
            j = k % block
            k += 1
            if per_operator:
                _step_lfsrs(states, t1, t2, t3, t4, t5, mask, w, top, nums)
                for o in range(ops):
                    bits[o] = ((nums[o] * sh[o % opcols]) >> word_bits) < qp[o]
            else:
                if not sobol:
                    _step_lfsrs(states, t1, t2, t3, t4, t5, mask, w, top, nums)
                else:
                    if j == 0:  # a block starts: fresh shifts
                        _step_lfsrs(states, t1, t2, t3, t4, t5, mask, w, top, shift)
                    for c in range(opcols):
                        nums[c] = points[j, c] ^ shift[c]
                for c in range(opcols):
                    col_nums[c] = (nums[c] * sh[c]) >> word_bits
                for r in range(rows):
                    for c in range(opcols):
                        bits[r * opcols + c] = col_nums[c] < qp[r * opcols + c]
            winner = _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index)
            if winner >= 0 or k == max_cycles:
                break
        winner = _store(p, counts, k, winner, samples, leading, nm_index, out_counts, out_map, out_timeout,
                        out_cycles)
        prev[0] = feedback_result(winner, out_timeout[p], nm_row)


def _lfsr_arrays(specs: list[LFSRSpec]) -> tuple[np.ndarray, np.ndarray]:
    """Start states and the kernels' tap shifts (MAX_TAPS rows; padding pairs of 0 cancel)."""
    init = np.array([s.init for s in specs], dtype=np.uint64)
    shifts = np.zeros((MAX_TAPS, len(specs)), dtype=np.uint64)
    for i, spec in enumerate(specs):
        shifts[: len(spec.taps), i] = spec.taps
    return init, shifts


class _OnChipSource:
    """Model state of an on-chip source: its LFSRs (per operator for ``lfsr``, per column for
    ``lfsr-shared``, the per-column shift LFSRs of ``sobol``) and, for ``sobol``, its points."""

    def __init__(self, params: MachineParams) -> None:
        self._params = params
        specs = lfsr_specs(params) if params.rng == "lfsr" else column_lfsr_specs(params)
        self._init, self._shifts = _lfsr_arrays(specs)
        self._points = np.zeros((0, params.operator_columns), np.uint64)  # lfsr-shared: none
        if params.rng == "sobol":
            points = [sobol_points(c, params.word_bits) for c in range(params.operator_columns)]
            self._points = np.ascontiguousarray(np.array(points, dtype=np.uint64).T)
        self.reset()

    def reset(self) -> None:
        self.states = self._init.copy()

    def run(self, q: np.ndarray, norm: np.ndarray, out: MachineResult, feedback: _Feedback) -> None:
        p = self._params
        args = (p.rows, p.operator_columns, p.word_bits, p.lfsr_bits, p.counter_max, p.max_cycles,
                _nm_index(p), p.samples_per_clock, p.timeout_answer == "leading", out.counts, out.map,
                out.timeout, out.cycles)
        _run_on_chip(q.astype(np.uint64), norm.astype(np.uint64), self.states, self._shifts, self._points,
                     p.rng == "lfsr", *args, *feedback.args())


# The model twin of every on-chip source kind (bayesmachine.sources.SOURCE_KINDS).
_ON_CHIP_SOURCES = {"lfsr": _OnChipSource, "lfsr-shared": _OnChipSource, "sobol": _OnChipSource}


def _nm_index(params: MachineParams) -> int:
    return params.rows - 1 if params.nomatch_row and params.tie_break == "nomatch-first" else -1


class _Feedback:
    """A neighbour prior's state (the previous result's hypothesis row, -1 for none) and table; with
    another prior, empty arrays that the kernels skip."""

    def __init__(self, params: MachineParams) -> None:
        self._table = np.array(params.feedback_words or (0,), np.int64)
        self._nomatch = int(params.feedback_nomatch_word or 0)
        self._nm_row = params.rows - 1 if params.nomatch_row else -1
        self.line_start = np.zeros(0, np.uint8)
        self.prev = np.full(1, -1, np.int64)

    def reset(self) -> None:
        self.prev[0] = -1

    def args(self) -> tuple:
        return self.line_start, self._table, self._nomatch, self._nm_row, self.prev


def column_scales(params: MachineParams, q: np.ndarray) -> np.ndarray:
    """Per pixel and operator column, the scale m of that column's random numbers
    (``MachineParams.normalize``): m = the column's largest word (0 .. 2^W; 0 only for a column of
    zeros); 2^W (the numbers unchanged) for a neighbour prior's feedback column and without
    ``normalize``. ``q``: operator words (P, operators). A word w fires when w > floor(r * m / 2^W),
    that is when w * 2^W > r * m (w an integer): with probability w / m, the run on the real words
    w * 2^W / m (each column rescaled so its largest word is 2^W)."""
    scales = np.full((q.shape[0], params.operator_columns), params.word_one, np.int64)
    if params.normalize:
        top = q.reshape(q.shape[0], params.rows, params.operator_columns).astype(np.int64).max(axis=1)
        scales[:, params.feedback_columns:] = top[:, params.feedback_columns:]
    return scales


def _expand(params: MachineParams, q: np.ndarray) -> np.ndarray:
    """Loaded words (P, words_per_pixel) -> operator words (P, operators), the feedback column 0 (to
    be formed by the kernel) zero."""
    if not params.feedback_columns:
        return q
    full = np.zeros((q.shape[0], params.rows, params.operator_columns), q.dtype)
    full[:, :, params.feedback_columns:] = q.reshape(q.shape[0], params.rows, params.loaded_columns)
    return full.reshape(q.shape[0], params.operators)


@numba.njit(cache=True)
def _run_numbers(q, norm, numbers, first, counts, done, rows, opcols, word_bits, n_max, max_cycles, nm_index,
                 samples, leading, out_counts, out_map, out_timeout, out_cycles, line_start, fb, fb_nm,
                 nm_row, prev):
    """Same machine, random numbers from ``numbers[t, i * operators + o]`` (clock t, sample i: B =
    ``samples`` per clock), resumable: pixel ``first`` has run ``done[0]`` samples, whole clocks (its
    counters in ``counts``). A clock takes its B samples' numbers whole: those after the run's stop
    are used by no one. Stops at the end of the pixels or of the numbers, saving the pixel in
    progress; returns (next pixel, clocks of numbers used). ``norm``: as for :func:`_run_on_chip`."""
    pixels, ops = q.shape
    t = 0
    k = done[0]
    bits = np.zeros(ops, np.uint8)
    over = np.zeros(rows, np.uint8)
    feedback = line_start.shape[0] > 0
    for p in range(first, pixels):
        qp = q[p]
        if feedback and k == 0:  # a pixel's start (not a resumed one)
            fill_feedback(qp, prev[0], line_start[p], fb, fb_nm, rows, opcols, nm_row, 1 << word_bits)
        winner = -1
        while True:
            if t >= numbers.shape[0]:
                done[0] = k
                return p, t
            for i in range(samples):
                k += 1
                for o in range(ops):
                    bits[o] = ((np.int64(numbers[t, i * ops + o]) * norm[p, o % opcols]) >> word_bits) < qp[o]
                winner = _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index)
                if winner >= 0 or k == max_cycles:
                    break
            t += 1
            if winner >= 0 or k == max_cycles:
                break
        winner = _store(p, counts, k, winner, samples, leading, nm_index, out_counts, out_map, out_timeout,
                        out_cycles)
        prev[0] = feedback_result(winner, out_timeout[p], nm_row)
        counts[:] = 0
        k = 0
    done[0] = 0
    return pixels, t


class MachineModel(EngineBase):
    """The whole machine, cycle-accurate and bit-exact with the RTL: the ``model`` engine.

    The model keeps its random source's state between calls, so running pixels in several
    chunks gives the same results as one call (as the hardware runs a stream of pixels). It has
    the engines' contract (:mod:`bayesmachine.sim.engines`): ``run``, ``reset``, ``close`` and
    ``wall_cycles`` (None: the model does not time loading).
    """

    name = "model"
    FEEDBACK = True

    def __init__(self, params: MachineParams) -> None:
        super().__init__(params)
        self._nm_index = _nm_index(params)
        self._twin = _ON_CHIP_SOURCES[params.rng](params) if self._kind.on_chip else None
        self._feedback = _Feedback(params)
        self._reset()

    def _reset(self) -> None:
        if self._twin is not None:
            self._twin.reset()
        self._feedback.reset()

    def _run_feedback(self, q: np.ndarray, feed: NumberFeed | None, line_start: np.ndarray) -> MachineResult:
        self._feedback.line_start = line_start
        try:
            return self._run(q, feed)
        finally:
            self._feedback.line_start = np.zeros(0, np.uint8)

    def _run(self, q: np.ndarray, feed: NumberFeed | None) -> MachineResult:
        """``q``: checked (P, words_per_pixel) words; ``feed``: the random numbers of an off-chip source."""
        p = self._params
        q = _expand(p, q)
        n = q.shape[0]
        out = MachineResult.zeros(n, p.rows)
        norm = column_scales(p, q)
        if feed is None:
            self._twin.run(q, norm, out, self._feedback)
        else:
            counts = np.zeros(p.rows, np.uint32)
            done = np.zeros(1, np.int64)
            first = 0
            while first < n:
                clocks = feed.take_clocks(_BLOCK)
                if not len(clocks):
                    raise ran_out_error(feed.source)
                first, used = _run_numbers(q, norm, clocks, first, counts, done, p.rows, p.operator_columns,
                                           p.word_bits, p.counter_max, p.max_cycles, self._nm_index,
                                           p.samples_per_clock, p.timeout_answer == "leading",
                                           out.counts, out.map, out.timeout, out.cycles,
                                           *self._feedback.args())
                feed.unread_clocks(clocks[used:])
        if p.nomatch_row:
            out.nomatch[:] = answered(p, out.timeout) & (out.map == p.rows - 1)
        return out
