"""The nets the machine's builders share, and the small helpers they build with.

:class:`MachineNets` is what ``BayesianMachine.build``'s builders (``top.py``, ``matrix.py``, ``stop.py``)
hand each other, and what a proof reads (``build`` returns them beside the module); :func:`row_groups` says
how the rows are grouped for the registered copies of the wide enables.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from amaranth.hdl import Const, Module, Signal, Value

from bayesmachine.params import MachineParams

if TYPE_CHECKING:  # the components import the helpers below
    from bayesmachine.hdl.sources import OnChipSource

    from .encoder import MAPEncoder
    from .feedback import FeedbackPrior
    from .normalize import ColumnScales

__all__ = ["GROUP_OPERATORS", "SOURCE_GROUPS", "MachineNets", "net", "or_all", "register_copy", "row_groups"]

GROUP_OPERATORS = 12  # operators per registered copy of the compute and start enables
SOURCE_GROUPS = 3  # groups of rows per copy of a shared random source (its next numbers' fan-out)


def row_groups(params: MachineParams) -> tuple[int, int]:
    """``(rows_per_group, groups)``: the matrix's enables reach thousands of flip-flops, so each group
    of rows (about :data:`GROUP_OPERATORS` operators) gets its own registered copy of them."""
    rows_per_group = max(1, GROUP_OPERATORS // params.operator_columns)
    return rows_per_group, -(-params.rows // rows_per_group)


def or_all(values: list[Value]) -> Value:
    """The bitwise OR of equal-width values."""
    out = values[0]
    for v in values[1:]:
        out = out | v
    return out


def net(m: Module, name: str, value: Value) -> Signal:
    """``value`` as a net of its own (a value read in several places would be built again in each)."""
    out = Signal(len(value), name=name)
    m.d.comb += out.eq(value)
    return out


def register_copy(m: Module, name: str, value: Value | list[Value]) -> Value | list[Value]:
    """A register loaded every clock with ``value`` (each of a list's values: ``<name>_<j>``)."""
    if isinstance(value, list):
        return [register_copy(m, f"{name}_{j}", x) for j, x in enumerate(value)]
    reg = Signal(len(value), name=name)
    m.d.sync += reg.eq(value)
    return reg


@dataclass
class MachineNets:
    """The nets the builders of ``BayesianMachine.build`` share (each documented where it is driven), and
    the registers a proof of the machine relates to its reference (``build`` returns them: the formal
    wrappers of ``hdl.formal`` and their mutants read them, never Amaranth's internals; a
    mutant may drive only those the machine's own module drives, not its submodules')."""

    shadow: list[Signal]  # the shadow likelihood memory, one word per loaded word of a pixel
    incoming: list[Value]  # per operator, the word a swap puts into the active memory
    active: list[Signal]  # the active likelihood memory
    shadow_full: Signal  # the shadow holds a complete pixel not yet started
    shadow_line_start: Signal  # neighbour prior: the shadow's pixel starts a line
    write_q: Signal  # one-hot: the beat written into the shadow this cycle
    running: Signal
    stop: Signal  # the registered end-of-run decision: high in the bubble
    compute: Signal  # a compute cycle: running and not stopped
    cycles_done: Signal  # compute cycles of this run so far
    counts: list[Signal]  # the overflow counters
    groups: int  # groups of rows, each with its own registered copy of the enables
    rows_per_group: int
    compute_rep: list[Signal]  # per group, a registered copy of the compute enable
    start_rep: list[Signal]  # per group, a registered copy of the start (swap) enable
    # A shared source's own copies of the compute and start enables, one pair per copy of the
    # source (see _random_numbers).
    src_reps: list[tuple[Signal, Signal]] = field(default_factory=list)
    source: OnChipSource | None = None
    sources: list[OnChipSource] = field(default_factory=list)  # a shared source's copies (source first)
    groups_per_source: int = SOURCE_GROUPS  # groups of rows fed by one copy of a shared source
    next_bits: list[Value] = field(default_factory=list)  # see matrix.operator_matrix
    row: Signal | None = None  # this compute cycle's stochastic bus, one bit per row
    full: Signal | None = None  # registered: count == counter max, per row
    over: Signal | None = None  # this cycle's overflows, per row
    next_counts: list[Value] = field(default_factory=list)
    next_full: list[Value] = field(default_factory=list)
    any_over: Value | None = None  # some row overflows in this compute cycle
    at_last: Signal | None = None  # compute cycle k == max_cycles (the watchdog)
    over_q: Signal | None = None  # the overflow flags of the last compute cycle, for the encoder
    leave: Signal | None = None  # the bubble hands its result over
    valid_q: Value | None = None  # the encoder: some row overflowed (not a timeout)
    winner: Value | None = None  # the encoder: the winning row
    encoder: MAPEncoder | None = None  # the MAP encoder (submodule ``encoder``), on over_q
    start: Signal | None = None  # the shadow is swapped in (in a bubble or when idle)
    settle: Value = field(default_factory=lambda: Const(0))  # neighbour prior: feedback words forming
    hidden: bool = False  # no bubble: a run's first compute cycle is its swap (hides_bubble)
    first_row: Value | None = None  # hidden: the next run's first stochastic bus, from registered bits
    swap_bits: list[Value] = field(default_factory=list)  # per operator, the bits a swap loads into bit_q
    hit: Value | None = None  # some row overflows in this compute cycle (by the watchdog's sample)
    timeout_now: Value | None = None  # this compute cycle is the watchdog's and no row overflows
    # B samples per clock (samples_per_clock > 1): per row its room (n_max - count, capped at 2B) and
    # its cumulative overflow flags; the cycle's stop samples over the rows (cumulative).
    room: list[Signal] = field(default_factory=list)
    flags: list[Value] = field(default_factory=list)
    G: Signal | None = None
    # timeout_answer "leading": the run timed out; the search for the leading row is on (and its next value).
    timed_out: Signal | None = None
    search: Signal | None = None
    search_n: Value = field(default_factory=lambda: Const(0))
    search_phase: Signal | None = None  # the search's second cycle of a bit
    search_bit: Signal | None = None  # one-hot: the counter bit the search looks at
    search_any: list[Signal] = field(default_factory=list)  # per group: a candidate has that bit set
    # The load's registers (_load).
    beat: Signal | None = None
    load_q: Signal | None = None
    # A neighbour prior (submodule ``feedback_prior``): its previous result and feedback words.
    feedback: FeedbackPrior | None = None
    prev_rows: list[Signal] = field(default_factory=list)
    prev_valids: list[Signal] = field(default_factory=list)
    feedback_q: list[Signal] = field(default_factory=list)
    # normalize (submodule ``column_scales``): per loaded column the largest of the shadow's words so
    # far; per operator column the number scale m of the shadow's pixel (that maximum) and of the
    # active one (registered at the swap).
    scales: ColumnScales | None = None
    norm_max: list[Signal] = field(default_factory=list)
    scale_shadow: list[Value] = field(default_factory=list)
    scale_active: list[Value] = field(default_factory=list)
    scale_active_n: list[Value] = field(default_factory=list)  # its next value
