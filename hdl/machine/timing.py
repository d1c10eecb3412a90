"""The machine's timing contract: the cycles around a run, and a pixel's wall cycles from them.

``docs/architecture.md`` ("Timing") states the contract; :class:`~.top.BayesianMachine` keeps it and
``hdl.formal.control`` proves it from the ports.
"""

from __future__ import annotations

import numpy as np

from bayesmachine.params import MachineParams

__all__ = [
    "BUBBLE_CYCLES", "FEEDBACK_CYCLES", "LOAD_LATENCY", "SEARCH_CYCLES_PER_BIT", "hides_bubble",
    "pixel_wall_cycles", "search_cycles",
]

BUBBLE_CYCLES = 1  # clock cycles per run after its last compute cycle (the registered stop)
LOAD_LATENCY = 1  # a load beat is written into the shadow memory the cycle after its handshake
FEEDBACK_CYCLES = 2  # a neighbour prior's swap after the bubble: the result, then the feedback words
SEARCH_CYCLES_PER_BIT = 2  # timeout_answer "leading": the search's cycles per counter bit


def hides_bubble(params: MachineParams) -> bool:
    """Whether the machine swaps the next pixel in during its first compute cycle (no bubble).

    With ``sobol`` the next pixel's first numbers (a block's shift) are known while the previous
    pixel runs, so its first cycle's bits are compared in advance and the cycle after a run's last
    one is already the next run's first. Not with a neighbour prior (the next pixel's feedback
    words follow the result), nor with counter max below 2B (a run's second cycle could overflow:
    its prefetched overflow flags would need the first cycle's counters; B = ``samples_per_clock``),
    nor with LFSR sources (their next numbers depend on whether the previous run goes on).
    """
    return (params.rng == "sobol" and not params.feedback_columns
            and params.counter_max >= 2 * params.samples_per_clock)


def search_cycles(params: MachineParams) -> int:
    """The clock cycles a timed-out run's bubble waits for the leading row (``timeout_answer =
    "leading"``: a search over the counters, a bit per two cycles from the top; 0 otherwise)."""
    return SEARCH_CYCLES_PER_BIT * params.counter_width if params.timeout_answer == "leading" else 0


def pixel_wall_cycles(params: MachineParams, cycles: np.ndarray,
                      timeout: np.ndarray | None = None) -> np.ndarray:
    """Clock cycles per pixel in steady state (loads keep coming, results are taken at once).

    ``cycles``: the results' compute cycles (clocks: k samples take ceil(k / B)); ``timeout``: their
    timeout flags (needed with ``timeout_answer = "leading"``, whose timed-out runs wait
    :func:`search_cycles` more).

    A run of k compute cycles is followed by its bubble, in which the next pixel is swapped in if
    its ``beats_per_pixel`` load beats have been written (they start the cycle after the previous
    swap, and each is written the cycle after its handshake):
    ``max(k + search, beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES``.

    Without the bubble (:func:`hides_bubble`) the next run's first compute cycle is its swap, and the
    next pixel's beats start in it: ``max(k, beats_per_pixel + LOAD_LATENCY + 1)``, plus one bubble
    after a run whose last cycle began a Sobol block (k - 1 a nonzero multiple of 2^W / B: that cycle
    steps the shift LFSR, so the next run's first numbers were not known a cycle early), or, after a
    timed-out run, its search (the bubble's cycle included).
    """
    cycles = np.asarray(cycles, dtype=np.int64)
    search = search_cycles(params)
    if search:
        if timeout is None:
            raise ValueError("pixel_wall_cycles: a machine with timeout_answer 'leading' needs the results' "
                             "timeout flags (timeout=)")
        extra = search * np.asarray(timeout, bool).astype(np.int64)
    else:
        extra = np.zeros_like(cycles)
    if hides_bubble(params):
        block = (1 << params.word_bits) // params.samples_per_clock
        late = ((cycles > 1) & ((cycles - 1) % block == 0)).astype(np.int64)
        return np.maximum(cycles + np.maximum(late, extra), params.beats_per_pixel + LOAD_LATENCY + 1)
    # A neighbour prior's swap waits two cycles more: the bubble registers the result, the next cycle
    # the feedback column's words (see ``feedback.FeedbackPrior``).
    settle = FEEDBACK_CYCLES * params.feedback_columns
    return np.maximum(cycles + settle + extra, params.beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES

