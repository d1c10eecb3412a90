"""The logarithmic integrator (Turck et al. 2025): a pixel's energy codes summed per row, the MAP the row of
the lowest sum, each row's weight from an exp table (``docs/integrators.md``). This module is its
definition but for the rule's kernels: its kind, the rule's parameters (:class:`LogParams`, what
:func:`log_params` makes of a machine's), its pipeline setting and its pixel clocks and wall cycles
(:func:`pixel_clocks`, :func:`pixel_wall_cycles`). The rule itself (NumPy, numba) is in
``sim.log_model``, beside the stochastic rule in ``sim.model``; its RTL is ``hdl.log`` (``LogMachine``
its top).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from bayesmachine.checks import as_bool, as_int, type_name
from bayesmachine.errors import ParameterError

from . import IntegratorKind

if TYPE_CHECKING:
    import numpy as np

    from bayesmachine.columns.base import Column, PassContext
    from bayesmachine.params import MachineParams

__all__ = ["ADDER_LEVELS_PER_STAGE", "ARGMIN_LEVELS_PER_STAGE", "LOG", "MAX_CODE_BITS", "MAX_WEIGHT_BITS",
           "LogKind", "LogParams", "check_params", "log_params", "pixel_clocks", "pixel_wall_cycles",
           "tree_levels"]

MAX_CODE_BITS = 16
MAX_WEIGHT_BITS = 16
# The log machine's pipeline setting: tree levels between two registers, of the row adders (before the
# issue point, outside the loop) and of the argmin tree (the loop: the feedback codes' adders, the tree).
ADDER_LEVELS_PER_STAGE = 1
ARGMIN_LEVELS_PER_STAGE = 4
# A code travels in the low bits of a W + 1-bit load word: W >= 8 holds the 9-bit codes.
MIN_WORD_BITS = 8


def tree_levels(leaves: int) -> int:
    """Levels of a balanced binary tree over ``leaves`` leaves: ceil(log2 leaves)."""
    return (leaves - 1).bit_length()


def _table(weights: object) -> tuple[int, ...]:
    """The exp table as a tuple of ints, checked: nonincreasing, at least 2 entries, the first
    positive and below ``2**(MAX_WEIGHT_BITS + 1)``, the last 0."""
    if isinstance(weights, (str, bytes)) or not hasattr(weights, "__iter__"):
        raise TypeError(f"weights must be a sequence of integers, not {type(weights).__name__}")
    table = tuple(as_int("weights", w, 0, 1 << MAX_WEIGHT_BITS) for w in weights)  # type: ignore[union-attr]
    if len(table) < 2 or table[0] == 0 or table[-1] != 0:
        raise ParameterError(f"weights must have at least 2 entries, the first positive and the last 0, "
                             f"got {table[:4]}...{table[-2:]}", "weights")
    if any(b > a for a, b in zip(table, table[1:], strict=False)):
        raise ParameterError("weights must be nonincreasing", "weights")
    return table


@dataclass(frozen=True)
class LogParams:
    """Parameters of one logarithmic integrator (the rule, the blocks and the top share them).

    Parameters
    ----------
    rows : int
        M, the rows (hypotheses) of a pixel, 1 ... 4096 (>= 2 with a no-match row); Dmax + 2 in
        disparity use.
    codes : int
        N, the energy codes per row, 1 ... 64.
    code_bits : int
        Bits of a code, 1 ... 16; the all-ones code is infinite energy.
    weights : sequence of int
        The exp table X: nonincreasing, at least 2 entries, the first positive, the last 0
        (``bayesmachine.columns.energy.exp_table`` builds one).
    nomatch_row : bool
        Whether the last row is the no-match row.
    tie_break : str or None
        ``"nomatch-first"`` or ``"lowest-index"`` (``bayesmachine.params.TIE_BREAKS``); None: the
        machine's default, ``bayesmachine.params.DEFAULT_TIE_BREAK``.

    Attributes
    ----------
    sum_bits : int
        Bits of a row's sum: ``code_bits + ceil(log2 codes)``.
    map_width : int
        Bits of a row index: ``max(1, bit_length(rows - 1))``.
    weight_bits : int
        Bits of a weight: ``bit_length(weights[0])``.
    infinite : int
        The infinite code, ``2**code_bits - 1``.
    """

    rows: int
    codes: int
    code_bits: int
    weights: tuple[int, ...]
    nomatch_row: bool = True
    tie_break: str | None = None

    def __post_init__(self) -> None:
        from bayesmachine.params import DEFAULT_TIE_BREAK, TIE_BREAKS  # params imports this package

        object.__setattr__(self, "rows", as_int("rows", self.rows, 1, 4096))
        object.__setattr__(self, "codes", as_int("codes", self.codes, 1, 64))
        object.__setattr__(self, "code_bits", as_int("code_bits", self.code_bits, 1, MAX_CODE_BITS))
        object.__setattr__(self, "weights", _table(self.weights))
        object.__setattr__(self, "nomatch_row", as_bool("nomatch_row", self.nomatch_row))
        if self.nomatch_row and self.rows < 2:
            raise ParameterError("rows: an integrator with a no-match row needs at least 2 rows", "rows")
        if self.tie_break is None:
            object.__setattr__(self, "tie_break", DEFAULT_TIE_BREAK)
        if not isinstance(self.tie_break, str):
            raise TypeError(f"tie_break must be a str, not {type_name(self.tie_break)}")
        if self.tie_break not in TIE_BREAKS:
            raise ParameterError(f"tie_break must be one of {TIE_BREAKS}, got {self.tie_break!r}",
                                 "tie_break")

    @property
    def sum_bits(self) -> int:
        return self.code_bits + (self.codes - 1).bit_length()

    @property
    def map_width(self) -> int:
        return max(1, (self.rows - 1).bit_length())

    @property
    def weight_bits(self) -> int:
        return self.weights[0].bit_length()

    @property
    def infinite(self) -> int:
        return (1 << self.code_bits) - 1

    @property
    def nomatch_first(self) -> bool:
        """The no-match row wins the ties it is part of."""
        return self.nomatch_row and self.tie_break == "nomatch-first"

    @property
    def none_index(self) -> int:
        """The ``map`` of a pixel whose rows are all excluded: the no-match row, else row 0."""
        return self.rows - 1 if self.nomatch_row else 0


def check_params(params: object) -> LogParams:
    """``params`` if it is a :class:`LogParams`, else a TypeError."""
    if not isinstance(params, LogParams):
        raise TypeError(f"params must be a LogParams, not {type(params).__name__}")
    return params


def log_params(params: MachineParams) -> LogParams:
    """The integrator of a log machine's ``params``: a row per hypothesis, a code per operator column,
    ``LOG_CODE_BITS``-bit codes, the exp table ``exp_table(word_bits)``, its no-match row and tie rule."""
    from bayesmachine.columns.energy import ENERGY_STEP, LOG_CODE_BITS, exp_table

    return LogParams(rows=params.rows, codes=params.operator_columns, code_bits=LOG_CODE_BITS,
                     weights=exp_table(params.word_bits, ENERGY_STEP), nomatch_row=params.nomatch_row,
                     tie_break=params.tie_break)


def pixel_clocks(params: MachineParams) -> tuple[int, int]:
    """(clocks per pixel where no feedback column binds, clocks per pixel where one does): 1, and with a
    neighbour prior the loop's ``ArgminTree.latency`` at this machine's setting (the feedback codes'
    adders and the tree's levels at ``ARGMIN_LEVELS_PER_STAGE``; the next pixel issues the clock its
    predecessor's MAP is registered as the tree's latest result)."""
    levels = tree_levels(params.rows) + 1
    loop = max(1, -(-levels // ARGMIN_LEVELS_PER_STAGE))
    return 1, loop if params.feedback_columns else 1


def pixel_wall_cycles(params: MachineParams, cycles: np.ndarray) -> np.ndarray:
    """Clock cycles per pixel in steady state (loads keep coming, results are taken at once), from the
    results' ``cycles`` (each pixel's issue interval by the rule): a pixel takes ``beats_per_pixel``
    beats to load and issues ``cycles`` after the one before, ``max(cycles, beats_per_pixel)``. Exact
    where ``beats_per_pixel`` is 1 or at least the loop's clocks (the models' load streams) or every
    pixel has the loop's clocks; between them an upper bound: the row adders take a pixel every
    clock, so a line's first pixel may load during the loops before it and issue sooner."""
    import numpy as np

    return np.maximum(np.asarray(cycles), params.beats_per_pixel)


class LogKind(IntegratorKind):
    """The logarithmic integrator's kind (module text): energy codes loaded, weights read out, no random
    numbers (none of the stochastic machine's fields)."""

    name = "log"
    description = ("the logarithmic machine: each row's energy codes summed, the MAP the lowest sum, the "
                   "rows' weights from an exp table: fed words or pixels, or on the board; "
                   "docs/integrators.md")
    title = "logarithmic"
    named = True
    loads = "codes"
    fields = ()
    defaults = {}
    draws_numbers = False
    top = "bayesmachine.hdl.log.machine:LogMachine"
    model = "bayesmachine.sim.log_model:LogMachineModel"
    engines = {"model": model, "pysim": "bayesmachine.sim.pysim:PysimEngine",
               "verilator": "bayesmachine.sim.verilator:VerilatorEngine"}

    def check(self, params: MachineParams) -> None:
        if params.word_bits < MIN_WORD_BITS:
            raise ParameterError(f"word_bits ({params.word_bits}) must be at least {MIN_WORD_BITS} with "
                                 "integrator 'log': its 9-bit energy codes travel in the load stream's "
                                 "W + 1-bit words", "word_bits")

    def load_max(self, params: MachineParams) -> int:
        from bayesmachine.columns.energy import INFINITE_CODE  # NumPy's: not at import

        return INFINITE_CODE

    def readout_max(self, params: MachineParams) -> int:
        return params.word_one  # the MAP's weight, X[0] = 2^W

    def flat(self, params: MachineParams) -> int:
        return 0

    def empty(self, params: MachineParams) -> int:
        return self.load_max(params)

    def max_clocks(self, params: MachineParams) -> int:
        """A pixel's issue interval at most: the loop's clocks (:func:`pixel_clocks`)."""
        return pixel_clocks(params)[1]

    def nth_machine(self, params: MachineParams, index: int) -> MachineParams:
        return params  # no seed: K log machines are one machine K times

    def load(self, factors: np.ndarray | float, params: MachineParams) -> np.ndarray:
        from bayesmachine.columns.energy import log_codes

        return log_codes(factors)

    def entries(self, values: np.ndarray | float, params: MachineParams) -> np.ndarray:
        from bayesmachine.columns.energy import log_codes

        return log_codes(values)  # float64 factors (table_bits None)

    def column_entries(self, column: Column, ctx: PassContext) -> np.ndarray:
        return column.codes(ctx)

    def feedback_table(self, column: object, params: MachineParams) -> tuple[tuple[int, ...], int]:
        return column.feedback_codes()  # type: ignore[attr-defined]

    def pixel_wall_cycles(self, params: MachineParams, cycles: np.ndarray,
                          timeout: np.ndarray | None = None) -> np.ndarray:
        return pixel_wall_cycles(params, cycles)

    def summary_lines(self, params: MachineParams) -> list[str]:
        lp = log_params(params)
        return [f"integrator: log (docs/integrators.md): {lp.code_bits}-bit energy codes in "
                f"{params.memory_word_width}-bit words, {lp.sum_bits}-bit row sums, {lp.weight_bits}-bit "
                f"weights ({len(lp.weights)}-entry exp table); {pixel_clocks(params)[1]} clock(s) per pixel "
                "where a feedback column binds, else 1"]

    def brief(self, params: MachineParams) -> list[str]:
        return ["log integrator", f"W {params.word_bits}"]  # no counters, no random source

    def label_parts(self, values: Mapping[str, object]) -> list[str]:
        return []  # no source, no counters

    def id_parts(self, params: MachineParams) -> list[str]:
        return []


LOG = LogKind()
