"""The stochastic integrator, the paper's machine: per compute cycle each operator compares its word with a
random number, each row's AND of its operators' bits drives an overflow counter, and the first row to
overflow is the MAP (``docs/architecture.md``). Its RTL top is ``hdl.machine.BayesianMachine``, its model
``sim.model.MachineModel``; this module holds its kind and its timing contract (the cycles around a run
and a pixel's wall cycles from them), which the RTL keeps and ``hdl.formal.control`` proves from the
ports: ``docs/architecture.md`` ("Timing").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

from . import IntegratorKind

if TYPE_CHECKING:
    import numpy as np

    from bayesmachine.columns.base import Column, PassContext
    from bayesmachine.params import MachineParams

__all__ = [
    "BUBBLE_CYCLES", "DEFAULT_COUNTER_MAX", "DEFAULT_LFSR_BITS", "DEFAULT_MAX_CYCLES", "DEFAULT_RNG",
    "DEFAULT_SEED", "FEEDBACK_CYCLES", "LOAD_LATENCY", "SEARCH_CYCLES_PER_BIT", "STOCHASTIC",
    "STOCHASTIC_FIELDS", "StochasticKind", "hides_bubble", "pixel_wall_cycles", "search_cycles",
]

# The fields only the stochastic integrator reads (its counters, random sources, watchdog and the scaling
# of its runs): None for another kind, refused when given.
STOCHASTIC_FIELDS = ("counter_max", "rng", "lfsr_bits", "seed", "max_cycles", "timeout_answer",
                     "samples_per_clock", "normalize", "smtj_dwell", "smtj_spread", "smtj_share")
DEFAULT_COUNTER_MAX = 16  # the paper's
DEFAULT_RNG = "sobol"  # measured best on the bundled pair: README "Random sources"
DEFAULT_LFSR_BITS = 31
DEFAULT_SEED = 1
DEFAULT_MAX_CYCLES = (1 << 20) - 1

BUBBLE_CYCLES = 1  # clock cycles per run after its last compute cycle (the registered stop)
LOAD_LATENCY = 1  # a load beat is written into the shadow memory the cycle after its handshake
FEEDBACK_CYCLES = 2  # a neighbour prior's swap after the bubble: the result, then the feedback words
SEARCH_CYCLES_PER_BIT = 2  # timeout_answer "leading": the search's cycles per counter bit
_MACHINE_SEED_STEP = 0x9E3779B97F4A7C15  # odd (2**64 / golden ratio): distinct seeds for 2**64 machines


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
    import numpy as np

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
    # the feedback column's words (see ``hdl.machine.feedback.FeedbackPrior``).
    settle = FEEDBACK_CYCLES * params.feedback_columns
    return np.maximum(cycles + settle + extra, params.beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES


def _source_detail(params: MachineParams) -> str:
    from bayesmachine.sources import source_kind

    if source_kind(params.rng).on_chip:
        return f" (L = {params.lfsr_bits}, seed {params.seed})"
    if params.rng == "smtj":
        from bayesmachine.sources.smtj import smtj_device_count

        return (f"; simulated by {smtj_device_count(params)} SMTJ devices, {params.word_bits} per "
                f"{params.smtj_share}: dwell {params.smtj_dwell:g} cycles, spread {params.smtj_spread:g}, "
                f"seed {params.seed}")
    return ""


class StochasticKind(IntegratorKind):
    """The stochastic integrator's kind (module text): W-bit words loaded, counts read out."""

    name = "stochastic"
    description = "the paper's machine: AND gates and overflow counters"
    title = "stochastic"
    named = False
    loads = "words"
    fields = STOCHASTIC_FIELDS
    defaults = {"counter_max": DEFAULT_COUNTER_MAX, "rng": DEFAULT_RNG, "lfsr_bits": DEFAULT_LFSR_BITS,
                "seed": DEFAULT_SEED, "max_cycles": DEFAULT_MAX_CYCLES, "timeout_answer": "none",
                "samples_per_clock": 1, "normalize": False}
    draws_numbers = True
    top = "bayesmachine.hdl.machine:BayesianMachine"
    model = "bayesmachine.sim.model:MachineModel"
    engines = {"model": model, "pysim": "bayesmachine.sim.pysim:PysimEngine",
               "verilator": "bayesmachine.sim.verilator:VerilatorEngine"}

    def load_max(self, params: MachineParams) -> int:
        return params.word_one

    def readout_max(self, params: MachineParams) -> int:
        return params.counter_max

    def flat(self, params: MachineParams) -> int:
        return params.word_one

    def empty(self, params: MachineParams) -> int:
        return 0

    def max_clocks(self, params: MachineParams) -> int:
        """The watchdog in clocks: a run's clocks are at most ceil(max_cycles / samples_per_clock)."""
        return -(-params.max_cycles // params.samples_per_clock)

    def nth_machine(self, params: MachineParams, index: int) -> MachineParams:
        """Seed ``(seed + index * 0x9E3779B97F4A7C15) mod 2**64``: every machine draws its own LFSR
        polynomials and start states."""
        return replace(params, seed=(params.seed + index * _MACHINE_SEED_STEP) % (1 << 64))

    def load(self, factors: np.ndarray | float, params: MachineParams) -> np.ndarray:
        from bayesmachine.columns.base import quantize

        return quantize(factors, params.word_bits)

    def entries(self, values: np.ndarray | float, params: MachineParams) -> np.ndarray:
        import numpy as np

        return np.asarray(values)  # already words

    def column_entries(self, column: Column, ctx: PassContext) -> np.ndarray:
        return column.words(ctx)

    def feedback_table(self, column: object, params: MachineParams) -> tuple[tuple[int, ...], int]:
        return column.feedback(params.word_bits)  # type: ignore[attr-defined]

    def pixel_wall_cycles(self, params: MachineParams, cycles: np.ndarray,
                          timeout: np.ndarray | None = None) -> np.ndarray:
        return pixel_wall_cycles(params, cycles, timeout)

    def samples_per_pixel(self, params: MachineParams, cycles: float) -> float | None:
        return params.samples_per_clock * cycles

    def summary_lines(self, params: MachineParams) -> list[str]:
        from bayesmachine.sources import source_kind

        return [f"words: {params.word_bits}-bit comparators, {params.memory_word_width}-bit "
                f"likelihood-memory words; counter max {params.counter_max} ({params.counter_width}-bit "
                "overflow counters); "
                f"watchdog {params.max_cycles} cycles",
                f"random source: {params.rng}: {source_kind(params.rng).description}{_source_detail(params)}"]

    def brief(self, params: MachineParams) -> list[str]:
        return [f"counter max {params.counter_max}", f"W {params.word_bits}", f"rng {params.rng}"]

    def label_parts(self, values: Mapping[str, object]) -> list[str]:
        return [f"rng={values['rng']}", f"counter_max={values['counter_max']}"]

    def id_parts(self, params: MachineParams) -> list[str]:
        return [params.rng, f"cm{params.counter_max}"]


STOCHASTIC = StochasticKind()
