"""The top level: ``BayesianMachine(params=params)``, the stochastic Bayesian machine of the paper.

An M x N matrix of stochastic operators (``operator.py``) fed by a random source
(``sources.py``: LFSRs, shared LFSRs or Sobol generators, or numbers on a port) and by
double-buffered likelihood memories; the AND of a row's operators is the
row's stochastic bus signal, counted by its overflow counter (``counters.py``); the first
overflow(s) stop the run and the MAP encoder (``encoder.py``) names the winner. With B samples per
clock (``samples_per_clock``) every operator compares B numbers per clock, the bus carries B bits
per row and the run stops at the sample of its first overflow; with ``timeout_answer = "leading"``
a timed-out run's bubble searches the leading row first. The exact per-sample semantics, ports and
word order are in ``docs/architecture.md``; the NumPy model ``bayesmachine.sim.model`` computes the
same thing bit for bit.

Timing (``docs/architecture.md``, "Timing"):

- ``load`` takes one beat per handshake and writes it into the *shadow* likelihood memory the
  cycle after; ``load.ready`` is low while the shadow holds a complete pixel not yet started
  (or its last beat is being written).
- A run's compute cycles advance the random source, counters and cycle count. The cycle after
  the last one is the run's *bubble* (the stop decision is registered): the result register
  takes the result, and a complete shadow is swapped into the *active* memory, so runs go back
  to back with one bubble between them. Back-pressure on ``result`` holds the bubble, never a
  compute cycle, so it changes no result.

``elaborate`` is a sequence of named builders, one per part of the design (``_memories``,
``_random_numbers``, ``_operator_matrix``, ``_overflow_counters``, ``_stop_decision``,
``_result``, ``_start``, ``_enables``, ``_load``), sharing the nets of :class:`MachineNets`.

The random source and the MAP encoder are direct submodules (depth 1), the very components
their unit tests drive; the operator matrix is built by ``operator.operator_bits`` and
``operator.bus_rows`` (``operator_rows`` is their composition, the function the operator test's
component wraps; as a submodule its port copies of 246 words and numbers would slow Amaranth's
Python simulator, which also slows with hierarchy depth).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import wiring

from bayesmachine.params import MachineParams

from .counters import count_ones, overflow_counter_full, overflow_flags, room_width, sample_counter
from .encoder import MAPEncoder
from .operator import bus_rows, operator_bits, sample_bits, sample_low, scaled_numbers
from .signatures import MachineSignature, beat_words, entropy_layout, load_layout, result_layout
from .sources import OnChipSource, random_source

__all__ = [
    "BUBBLE_CYCLES", "FEEDBACK_CYCLES", "GROUP_OPERATORS", "LOAD_LATENCY", "SEARCH_CYCLES_PER_BIT",
    "SOURCE_GROUPS", "BayesianMachine", "entropy_layout", "hides_bubble", "load_layout", "pixel_wall_cycles",
    "result_layout", "search_cycles",
]

BUBBLE_CYCLES = 1  # clock cycles per run after its last compute cycle (the registered stop)
LOAD_LATENCY = 1  # a load beat is written into the shadow memory the cycle after its handshake
FEEDBACK_CYCLES = 2  # a neighbour prior's swap after the bubble: the result, then the feedback words
GROUP_OPERATORS = 12  # operators per registered copy of the compute and start enables
SOURCE_GROUPS = 3  # groups of rows per copy of a shared random source (its next numbers' fan-out)


def _or_all(values: list[Value]) -> Value:
    """The bitwise OR of equal-width values."""
    out = values[0]
    for v in values[1:]:
        out = out | v
    return out


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


SEARCH_CYCLES_PER_BIT = 2  # timeout_answer "leading": the search's cycles per counter bit


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
    # the feedback column's words (see ``BayesianMachine._feedback_prior``).
    settle = FEEDBACK_CYCLES * params.feedback_columns
    return np.maximum(cycles + settle + extra, params.beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES


@dataclass
class MachineNets:
    """The nets the builders of ``BayesianMachine.elaborate`` share (each documented where it is driven),
    and the registers a proof of the machine relates to its reference (``BayesianMachine.nets``: the
    formal wrappers of ``hdl.formal`` and their mutants read them, never Amaranth's internals)."""

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
    next_bits: list[Value] = field(default_factory=list)  # see _operator_matrix
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
    # The load's registers (_load) and a neighbour prior's previous result and feedback words.
    beat: Signal | None = None
    load_q: Signal | None = None
    prev_rows: list[Signal] = field(default_factory=list)
    prev_valids: list[Signal] = field(default_factory=list)
    feedback_q: list[Signal] = field(default_factory=list)
    # normalize: per loaded column the largest of the shadow's words so far (taken with each beat's
    # handshake); per operator column the number scale m of the shadow's pixel (that maximum) and of
    # the active one (registered at the swap).
    norm_max: list[Signal] = field(default_factory=list)
    scale_shadow: list[Value] = field(default_factory=list)
    scale_active: list[Value] = field(default_factory=list)
    scale_active_n: list[Value] = field(default_factory=list)  # its next value


class BayesianMachine(wiring.Component):
    """The stochastic Bayesian machine.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (checked against the random source before anything is built).

    Attributes
    ----------
    load : ``In(stream.Signature(load_layout(params)))``
        A pixel's words in operator order, ``words_per_beat`` per beat, ``beats_per_pixel`` beats per pixel.
    result : ``Out(stream.Signature(result_layout(params)))``
        One result per pixel, in order.
    entropy : ``In(entropy_layout(params))``
        With an off-chip ``rng`` ("external", "smtj") only: one random number per operator and
        sample (B per operator), sampled on compute cycles.
    entropy_ready : ``Out(1)``
        With an off-chip ``rng`` only: high on compute cycles (the numbers on ``entropy`` are
        consumed at the clock edge).
    nets : MachineNets
        After elaboration: the internal nets a proof relates to its reference (read-only).

    The ports are :class:`~.signatures.MachineSignature` ``(params)``.
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"BayesianMachine takes a MachineParams, not {type(params).__name__}")
        self._params = params
        self._nets: MachineNets | None = None
        super().__init__(MachineSignature(params))

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def nets(self) -> MachineNets:
        """The :class:`MachineNets` of the last :meth:`elaborate`: the internal nets and registers a
        proof relates to its reference (``hdl.formal``); elaborate first."""
        if self._nets is None:
            raise RuntimeError("BayesianMachine.nets: elaborate the machine first (Fragment.get)")
        return self._nets

    def elaborate(self, platform: object) -> Module:
        m = Module()
        n = self._nets = self._memories()
        self._column_scales(m, n)
        self._random_numbers(m, n)
        self._operator_matrix(m, n)
        self._overflow_counters(m, n)
        self._stop_decision(m, n)
        self._result(m, n)
        self._feedback_prior(m, n)
        self._start(m, n)
        self._enables(m, n)
        self._load(m, n)
        return m

    def _memories(self) -> MachineNets:
        """The likelihood memories, the run state and the registered enables' copies."""
        p = self._params
        rows, cols, ops = p.rows, p.operator_columns, p.operators
        # Likelihood memories (registers: every operator reads its word every cycle). No reset: a
        # run always starts by copying a complete shadow into the active memory.
        # The shadow holds the loaded words (a neighbour prior's feedback column 0 is formed at the
        # swap instead, by _feedback_prior).
        fb, loaded = p.feedback_columns, p.loaded_columns
        shadow = [Signal(p.memory_word_width, name=f"shadow_{w // loaded}_{fb + w % loaded}", reset_less=True)
                  for w in range(p.words_per_pixel)]
        # A feedback word is driven by _feedback_prior (the result it follows comes later).
        incoming: list[Value] = []
        for o in range(ops):
            r, c = divmod(o, cols)
            incoming.append(Signal(p.memory_word_width, name=f"feedback_{r}") if c < fb
                            else shadow[r * loaded + c - fb])
        active = [Signal(p.memory_word_width, name=f"word_{o // cols}_{o % cols}", reset_less=True)
                  for o in range(ops)]
        # The matrix's enables (compute: random source, counters; start: the shadow-to-active copy)
        # reach thousands of flip-flops: each group of rows gets its own registered copy, loaded
        # with the enable's next value (``compute_n``/``start_n``, see _enables), so no net fans
        # out further than a group. The flow keeps these ``_rep`` registers apart (docs/fpga.md).
        rows_per_group = max(1, GROUP_OPERATORS // cols)
        groups = -(-rows // rows_per_group)
        return MachineNets(
            hidden=hides_bubble(p),
            # The census model's machine (a neighbour prior, 6 columns) keeps one source: with a copy
            # per 3 groups (14 copies of 6 columns) it routed at 63.9 MHz against 64.4 MHz with one,
            # for 30,763 LUT4 sites against 19,713 (docs/fpga.md).
            groups_per_source=groups if p.feedback_columns else SOURCE_GROUPS,
            shadow=shadow, incoming=incoming, active=active, shadow_full=Signal(name="shadow_full"),
            shadow_line_start=Signal(name="shadow_line_start"),
            write_q=Signal(p.beats_per_pixel, name="write_q"), running=Signal(name="running"),
            stop=Signal(name="stop"), compute=Signal(name="compute"),
            cycles_done=Signal(p.cycle_width, name="cycles_done"),
            counts=[Signal(p.counter_width, name=f"count_{r}") for r in range(rows)],
            groups=groups, rows_per_group=rows_per_group,
            compute_rep=[Signal(name=f"compute_rep{g}") for g in range(groups)],
            start_rep=[Signal(name=f"start_rep{g}") for g in range(groups)],
        )

    def _column_scales(self, m: Module, n: MachineNets) -> None:
        """Per-pixel column normalization (``normalize``): per loaded column a register keeps the
        largest of the shadow's words, taken with each beat's handshake (_load; cleared at the swap):
        the shadow's scale m, registered at the swap as the active pixel's. The operators of the
        column compare their words with ``(number * m) >> W`` (_operator_matrix): a word w fires when
        w * 2^W > r * m, the run on the words w * 2^W / m. A feedback column is not scaled (m = 2^W)."""
        p = self._params
        cols, fb = p.operator_columns, p.feedback_columns
        if not p.normalize:
            return
        width = p.memory_word_width
        n.norm_max = [Signal(width, name=f"norm_max_{c}") for c in range(p.loaded_columns)]  # _column_max
        for c in range(cols):
            if c < fb:
                for scales in (n.scale_shadow, n.scale_active, n.scale_active_n):
                    scales.append(Const(p.word_one, width))
                continue
            n.scale_shadow.append(n.norm_max[c - fb])
            n.scale_active.append(Signal(width, name=f"norm_scale_{c}"))
            n.scale_active_n.append(Signal(width, name=f"norm_scale_n_{c}"))  # driven by _start

    def _random_numbers(self, m: Module, n: MachineNets) -> None:
        """The random source: advances on compute cycles only, restarts with each pixel's run."""
        p = self._params
        cols = p.operator_columns
        source = random_source(p, [o // cols // n.rows_per_group for o in range(p.operators)])
        n.source = source
        if source is None:  # off chip: the numbers arrive on the entropy port
            m.d.comb += self.entropy_ready.eq(n.compute)
            return
        m.submodules.source = source
        n.sources.append(source)
        if source.shared:
            # A second level of copies: the source itself is replicated, one identical copy per
            # SOURCE_GROUPS groups of rows, each feeding only its groups' registered copies of the
            # numbers (_operator_matrix), so the next-number logic's nets stay within a few groups
            # instead of spanning the matrix (docs/fpga.md). Copy k's flip-flops are named
            # ``source_rep<k>.*`` after flattening, which the flow keeps apart.
            for k in range(1, -(-n.groups // n.groups_per_source)):
                copy = random_source(p, [o // cols // n.rows_per_group for o in range(p.operators)])
                m.submodules[f"source_rep{k}"] = copy
                n.sources.append(copy)
            # One registered copy each of the compute and start enables per source copy: its
            # next-number logic feeds the groups' copies of the numbers, so its inputs come straight
            # from flip-flops. Amaranth aliases these registers with the source's ports, so the
            # flow's keep selection goes two steps back from the ``_rep`` wires to reach them
            # (``KEEP_REGISTER_COPIES`` in fpga/flow.py, docs/fpga.md).
            for k, src in enumerate(n.sources):
                suffix = "" if k == 0 else str(k)
                n.src_reps.append((Signal(name=f"compute_rep_src{suffix}"),
                                   Signal(name=f"start_rep_src{suffix}")))
                m.d.comb += [src.enable.eq(n.src_reps[k][0]), src.restart.eq(n.src_reps[k][1])]
        else:  # a number per operator: one enable (and restart) bit per group of rows
            m.d.comb += [source.enable.eq(Cat(n.compute_rep)), source.restart.eq(Cat(n.start_rep))]

    def _operator_matrix(self, m: Module, n: MachineNets) -> None:
        """The operator matrix: each row's AND of ``number < word``, the stochastic bus (B bits per row,
        one per sample: operator o's sample i compares its word with number ``sample_points[i]`` XOR
        its source's number)."""
        p = self._params
        rows, cols, ops, samples = p.rows, p.operator_columns, p.operators, p.samples_per_clock
        source = n.source
        n.row = Signal(rows * samples, name="row")
        if source is None:
            # Numbers from a port arrive in their cycle and are compared then (sample i's at i * ops).
            numbers = [self.entropy[i * ops + o] for i in range(samples) for o in range(ops)]
            scaled = [scaled_numbers(x, n.scale_active[j % ops % cols], (0,))[0] if p.normalize else x
                      for j, x in enumerate(numbers)]
            bits = [Cat(scaled[i * ops + o] < n.active[o] for i in range(samples)) for o in range(ops)]
            m.d.comb += n.row.eq(bus_rows(bits, rows, cols, samples))
            return
        # Prefetched comparators (on-chip sources): ``bit_q[o]`` holds this compute cycle's
        # ``number < word``. It is loaded in the cycle before: in a compute cycle from the next
        # numbers and the same word, in a swap from the numbers the source gives after the
        # start (a Sobol block restarts) and the incoming (shadow) word. Same bits as comparing
        # in the cycle itself, but the matrix's path to the stop flip-flop starts at a register
        # instead of a carry chain.
        index, points = source.operator_numbers, source.sample_points

        def compare(numbers: list, words: list[Value], kind: str,
                    at: list[tuple[int, ...]] | None = None) -> list[Value]:
            """Per operator, its B bits (``at``: other points per number entry) from its number, or
            from its list of normalized numbers, one per point (compared as they are); with B
            samples nets of their own (``<kind>_bits_<r>_<c>``, read in several places)."""
            at = points if at is None else at
            if samples == 1 and not any(isinstance(x, list) for x in numbers):
                if not any(a != (0,) for a in at):
                    return operator_bits(numbers, words, range(ops))
                return [sample_bits(numbers[o], words[o], at[index[o]]) for o in range(ops)]
            out = []
            for o in range(ops):
                name = f"{o // cols}_{o % cols}"
                if isinstance(numbers[o], list):
                    bits = Cat(*(x < words[o] for x in numbers[o]))
                else:
                    low = self._net(m, f"{kind}_low_{name}", sample_low(numbers[o], words[o], at[index[o]]))
                    bits = sample_bits(numbers[o], words[o], at[index[o]], low=low)
                out.append(self._net(m, f"{kind}_bits_{name}", bits) if samples > 1 else bits)
            return out

        swap_at = list(source.swap_points) if n.hidden else points
        if source.shared:
            # A number shared by a column's rows would reach all its comparators from one net:
            # each group of rows gets a registered copy of the column's next numbers, loaded
            # every clock from ``following_numbers`` (so equal to ``next_numbers`` in every
            # cycle), and one of its restart numbers, loaded from ``following_restart_numbers``
            # (equal to ``restart_numbers``). The flow keeps these ``_rep`` registers apart too.
            # Normalized columns copy their scaled numbers (one per point), formed once per source
            # copy: the next numbers from the next cycle's scales (the active pixel's, or the shadow's
            # at a swap), the restart numbers from the shadow's maxima registers, final from the cycle
            # the pixel's last beat is written on (taken with its handshake), so before any swap.
            def group_copies(name: str, attr: str, scales: list[Value], at: list[tuple[int, ...]]) -> list:
                copies, per_source = [], {}
                for g in range(n.groups):
                    k = g // n.groups_per_source
                    if k not in per_source:
                        following = list(getattr(n.sources[k], attr))
                        per_source[k] = self._normalized(m, f"{name}_norm{k}", following, scales, at)
                    copies.append([self._copy(m, f"{name}_rep{g}_{i}", x)
                                   for i, x in enumerate(per_source[k])])
                return [copies[o // cols // n.rows_per_group][index[o]] for o in range(ops)]

            next_numbers = group_copies("next_number", "following_numbers", n.scale_active_n, points)
            restart = group_copies("restart_number", "following_restart_numbers", n.scale_shadow, swap_at)
        else:
            def spread(values: list) -> list:  # per number entry -> per operator
                return [values[index[o]] for o in range(ops)]

            def by_column(scales: list[Value]) -> list[Value]:
                return [scales[o % cols] for o in range(ops)] if scales else []

            next_numbers = self._normalized(m, "next_number_norm", spread(list(source.next_numbers)),
                                            by_column(n.scale_active), spread(list(points)))
            restart = self._normalized(m, "restart_number_norm", spread(list(source.restart_numbers)),
                                       by_column(n.scale_shadow), spread(list(swap_at)))
        n.next_bits = compare(next_numbers, n.active, "next")
        if n.hidden:
            # No bubble (hides_bubble, "Timing" in docs/architecture.md): the swap is the next run's
            # first compute cycle. Its bits (the restart numbers against the shadow words) are
            # registered every cycle in ``first_bit`` and drive ``first_row`` in the swap; the swap
            # loads ``bit_q`` with the run's second bits, the restart numbers XOR a block's second
            # cycle's points against the shadow words, which the swap is still reading. Both come
            # from one comparator of the low bits (``sample_bits``: for B = 1 the points 0 and V_0 =
            # 2^(W-1), a comparator of the low W - 1 bits).
            pair = compare(restart, n.incoming, "swap", swap_at)
            first_bits, swap_bits = [], []
            for o in range(ops):
                first_bit = Signal(samples, name=f"first_bit_{o // cols}_{o % cols}")
                m.d.sync += first_bit.eq(pair[o][:samples])
                first_bits.append(first_bit)
                swap_bits.append(pair[o][samples:])
            n.first_row = bus_rows(first_bits, rows, cols, samples)
        else:
            swap_bits = compare(restart, n.incoming, "swap")
        n.swap_bits = swap_bits
        bits = []
        for o in range(ops):
            g = o // cols // n.rows_per_group
            bit_q = Signal(samples, name=f"bit_{o // cols}_{o % cols}")
            # A swap first: with the bubble it never coincides with a compute cycle; without, the
            # swap is also a compute cycle (the next run's first).
            with m.If(n.start_rep[g]):
                m.d.sync += bit_q.eq(swap_bits[o])
            with m.Elif(n.compute_rep[g]):
                m.d.sync += bit_q.eq(n.next_bits[o])
            bits.append(bit_q)
        m.d.comb += n.row.eq(bus_rows(bits, rows, cols, samples))

    def _overflow_counters(self, m: Module, n: MachineNets) -> None:
        """The overflow counters: with registered "full" flags (count == n_max) for one sample per
        clock, with registered ``room`` (n_max - count, capped at 2B) for B samples."""
        p = self._params
        n.over = Signal(p.rows, name="over")
        if p.samples_per_clock > 1:
            # B samples: each row's flags F_i (overflowed by sample i) from its bits and room.
            b = p.samples_per_clock
            n.room = [Signal(room_width(b), name=f"room_{r}", init=min(p.counter_max, 2 * b))
                      for r in range(p.rows)]
            n.flags = [self._net(m, f"flags_{r}", overflow_flags(n.row[r * b:(r + 1) * b], n.room[r]))
                       for r in range(p.rows)]
            return
        n.full = Signal(p.rows, name="full")
        for r in range(p.rows):
            ov, nxt, nfull = overflow_counter_full(n.row[r], n.counts[r], n.full[r], p.counter_max)
            m.d.comb += n.over[r].eq(ov)
            n.next_counts.append(nxt)
            n.next_full.append(nfull)

    def _normalized(self, m: Module, name: str, numbers: list[Value], scales: list[Value],
                    at: list[tuple[int, ...]]) -> list:
        """``numbers`` (one per column, or per operator for a source of its own) as they are, or,
        where ``scales`` gives a scale m below 2^W or a signal (a normalized column: ``normalize``), as
        the list of ``((number ^ point) * m) >> W`` per point of ``at`` (:func:`scaled_numbers`, nets
        named ``<name>_<i>_<j>``). A feedback column's scale is the constant 2^W: kept as it is."""
        out: list = []
        for i, number in enumerate(numbers):
            scale = scales[i] if scales else None
            if scale is None or (isinstance(scale, Const) and scale.value == self._params.word_one):
                out.append(number)
                continue
            def net(part: str, value: Value, i: int = i) -> Value:
                return self._net(m, f"{name}_{i}_{part}", value)

            out.append([net(str(j), x) for j, x in enumerate(scaled_numbers(number, scale, at[i], net))])
        return out

    @staticmethod
    def _copy(m: Module, name: str, value: Value | list[Value]) -> Value | list[Value]:
        """A register loaded every clock with ``value`` (each of a list's values: ``<name>_<j>``)."""
        if isinstance(value, list):
            return [BayesianMachine._copy(m, f"{name}_{j}", x) for j, x in enumerate(value)]
        reg = Signal(len(value), name=name)
        m.d.sync += reg.eq(value)
        return reg

    @staticmethod
    def _net(m: Module, name: str, value: Value) -> Signal:
        """``value`` as a net of its own (a value read in several places would be built again in each)."""
        net = Signal(len(value), name=name)
        m.d.comb += net.eq(value)
        return net

    def _group_flags(self, m: Module, n: MachineNets, terms: list[list[Value]], start: list[Value],
                     name: str) -> Value:
        """Per group of rows, a register holding the OR of its rows' ``terms`` (the next cycle's
        overflows, prefetched: loaded in a compute cycle) or ``start`` (its value after a swap, which
        takes priority); returns the OR over the groups, a function of registers only."""
        width = len(Cat(terms[0]))
        regs = [Signal(width, name=f"{name}_{g}") for g in range(n.groups)]
        for g in range(n.groups):
            group = range(g * n.rows_per_group, min(self._params.rows, (g + 1) * n.rows_per_group))
            with m.If(n.start_rep[g]):
                m.d.sync += regs[g].eq(start[g])
            with m.Elif(n.compute_rep[g]):
                m.d.sync += regs[g].eq(_or_all([Cat(terms[r]) for r in group]))
        return _or_all(regs)

    def _overflow_detect(self, m: Module, n: MachineNets) -> None:
        """Whether some row overflows in this compute cycle (``any_over``) and, with B samples, the
        first sample at which one does (``G``, cumulative flags over the rows).

        With prefetched comparators that is known a cycle early, per group of rows: the next cycle's
        overflows from the next bits and the counters' next state, ORed over the group's rows into
        registers (their value after a swap: none can overflow in a run's first cycle, nor, without
        the bubble, in its second: counter max >= 2B). The stop is then an OR of registers."""
        p = self._params
        cols, b = p.operator_columns, p.samples_per_clock
        if b == 1:
            if n.next_bits:
                terms = [[bus_rows(n.next_bits[r * cols:(r + 1) * cols], 1, cols) & n.next_full[r]]
                         for r in range(p.rows)]
                n.any_over = self._group_flags(m, n, terms, [Const(0)] * n.groups, "over_group")
            else:
                n.any_over = n.over.any()
            n.hit = n.any_over  # an overflow within the watchdog's limit
            return
        if n.next_bits:
            # The next cycle's 1s of row r follow this cycle's (all counted: a cycle that stops is
            # followed by a swap, whose value takes priority). The buses are nets of their own: each
            # sample's flag reads them.
            def bus(name: str, bits: list[Value], r: int) -> Value:
                return self._net(m, f"{name}_{r}", bus_rows(bits[r * cols:(r + 1) * cols], 1, cols, b))

            terms = [[overflow_flags(bus("next_row", n.next_bits, r), n.room[r],
                                     count_ones(n.row[r * b:(r + 1) * b]))] for r in range(p.rows)]
            start = [Const(0, b)] * n.groups
            if not n.hidden and p.counter_max < b:  # a run's first cycle can overflow: its flags
                first = [overflow_flags(bus("swap_row", n.swap_bits, r), Const(p.counter_max))
                         for r in range(p.rows)]
                per = n.rows_per_group
                start = [_or_all(first[g * per:(g + 1) * per]) for g in range(n.groups)]
            flags = self._group_flags(m, n, terms, start, "over_group")
        else:
            flags = _or_all(n.flags)
        # The watchdog stops at sample max_cycles: sample ``limit`` of the last cycle.
        limit = p.max_cycles - (p.max_clocks - 1) * b
        watchdog = Const(((1 << b) - 1) >> (limit - 1) << (limit - 1), b)
        n.G = Signal(b, name="stop_samples")
        m.d.comb += n.G.eq(flags | Mux(n.at_last, watchdog, 0))
        n.any_over = flags[b - 1]
        n.hit = flags[limit - 1] | ~n.at_last

    def _stop_decision(self, m: Module, n: MachineNets) -> None:
        """The registered stop: a row overflows or the watchdog expires; counters advance."""
        p = self._params
        # A compute cycle: running and not yet stopped. The stop is registered (see "Timing" in
        # docs/architecture.md), so every wide enable is a function of registers only, never of
        # the matrix.
        m.d.comb += n.compute.eq(n.running & ~n.stop)
        # The watchdog, registered too: ``at_last`` is high in compute cycle k == max_clocks.
        n.at_last = Signal(name="at_last")
        self._overflow_detect(m, n)
        finish = Signal()
        m.d.comb += finish.eq(n.compute & (n.any_over | n.at_last))
        n.over_q = Signal(p.rows, name="over_q")
        with m.If(n.compute):
            m.d.sync += [
                n.cycles_done.eq(n.cycles_done + 1),
                n.at_last.eq(n.cycles_done == p.max_clocks - 2),  # max_clocks >= 2: never at start
                n.stop.eq(finish),
            ]
        b = p.samples_per_clock
        if b > 1:
            # The first stop sample (one-hot, 0 if none) and the samples up to it, which count.
            first = self._net(m, "stop_sample", n.G & ~(n.G << 1)[:b])
            counted = self._net(m, "counted_samples", ~(n.G << 1)[:b])
            for r in range(p.rows):
                nxt, room = sample_counter(n.row[r * b:(r + 1) * b], n.counts[r], counted, p.counter_max)
                n.next_counts.append(nxt)
                m.d.comb += n.over[r].eq((n.flags[r] & first).any())
                with m.If(n.compute_rep[r // n.rows_per_group]):
                    m.d.sync += [n.counts[r].eq(nxt), n.room[r].eq(room)]
        else:
            for r in range(p.rows):
                with m.If(n.compute_rep[r // n.rows_per_group]):
                    m.d.sync += [n.counts[r].eq(n.next_counts[r]), n.full[r].eq(n.next_full[r])]
        self._over_flags(m, n)

    def _over_flags(self, m: Module, n: MachineNets) -> None:
        """``over_q``: the rows that overflowed at the stop, for the MAP encoder in the bubble. With
        ``timeout_answer = "leading"`` a timeout sets every row and a search keeps the rows with the
        largest count, a bit per two cycles from the top (``search``: the bubble waits for it)."""
        p = self._params
        leading = p.timeout_answer == "leading"
        n.timeout_now = timeout_now = n.at_last & ~n.hit  # this compute cycle ends without an overflow
        if leading:
            n.timed_out = Signal(name="timed_out")
            n.search = Signal(name="search")
            phase = Signal(name="search_phase")
            bit = Signal(p.counter_width, name="search_bit", init=1 << (p.counter_width - 1))  # one-hot
            any_g = [Signal(name=f"search_any_{g}") for g in range(n.groups)]
            n.search_phase, n.search_bit, n.search_any = phase, bit, any_g
            last = Signal()
            m.d.comb += last.eq(n.search & phase & bit[0])
            n.search_n = Mux(n.compute, timeout_now, n.search & ~last)
            with m.If(n.compute):
                m.d.sync += [n.timed_out.eq(timeout_now), n.search.eq(timeout_now), phase.eq(0),
                             bit.eq(1 << (p.counter_width - 1))]
            with m.Elif(n.search):
                m.d.sync += [phase.eq(~phase), n.search.eq(~last)]
                with m.If(phase):
                    m.d.sync += bit.eq(bit >> 1)
            step = n.search & phase
            any_set = _or_all(any_g)
        for r in range(p.rows):
            g = r // n.rows_per_group
            with m.If(n.compute_rep[g]):
                over = n.over[r] | timeout_now if leading else n.over[r]
                m.d.sync += n.over_q[r].eq(over)
            if leading:
                set_bit = (n.counts[r] & bit).any()
                with m.Elif(step):
                    m.d.sync += n.over_q[r].eq(n.over_q[r] & (set_bit | ~any_set))
        if leading:
            for g in range(n.groups):
                group = range(g * n.rows_per_group, min(p.rows, (g + 1) * n.rows_per_group))
                m.d.sync += any_g[g].eq(_or_all([n.over_q[r] & (n.counts[r] & bit).any() for r in group]))

    def _result(self, m: Module, n: MachineNets) -> None:
        """The bubble hands the result over (the result register is empty: a register, no ready)."""
        p = self._params
        res = self.result.payload
        n.leave = leave = Signal()
        searching = n.search if n.search is not None else Const(0)
        m.d.comb += leave.eq(n.stop & ~self.result.valid & ~searching)
        with m.If(self.result.ready):
            m.d.sync += self.result.valid.eq(0)
        m.submodules.encoder = encoder = MAPEncoder(rows=p.rows, nomatch_row=p.nomatch_row,
                                                    tie_break=p.tie_break)
        m.d.comb += encoder.over.eq(n.over_q)
        valid_q, winner = encoder.valid, encoder.index
        n.valid_q, n.winner, n.encoder = valid_q, winner, encoder
        with m.If(leave):
            map_value = Signal(p.map_width)
            m.d.comb += map_value.eq(winner)
            m.d.sync += [
                self.result.valid.eq(1),
                res.map.eq(valid_q.replicate(p.map_width) & map_value),
                # A leading answer's encoder is valid (the leading rows): the flag says it timed out.
                res.timeout.eq(n.timed_out if n.timed_out is not None else ~valid_q),
                res.cycles.eq(n.cycles_done),
                res.counts.eq(Cat(n.counts)),
                n.running.eq(0),
                n.stop.eq(0),
            ]
            if p.nomatch_row:
                m.d.sync += res.nomatch.eq(valid_q & (map_value == p.rows - 1))
            else:
                m.d.sync += res.nomatch.eq(0)

    def _feedback_prior(self, m: Module, n: MachineNets) -> None:
        """A neighbour prior's feedback column 0: formed at each swap from the previous result.

        The bubble registers the winning row (``prev_row``, a copy per group of rows) and whether
        it is a hypothesis row (``prev_valid``: not the no-match row, not a timeout, answered or
        not); the next
        cycle (``settle``) registers each row's word, ``feedback_words[min(|r - prev_row|, last)]``
        (the no-match row ``feedback_nomatch_word``; 1.0 everywhere without a previous
        hypothesis, after reset too); the swap, a cycle later still, takes them, or 1.0
        everywhere when the pixel starts a line. So the swap's path is the same as a loaded
        word's (a register, a comparator), and the subtraction, clamp and table per row have a
        cycle of their own.
        """
        p = self._params
        if not p.feedback_columns:
            return
        # One registered copy of the previous result per group of rows, as for the enables: a single
        # register would fan out to every row's distance logic (the flow keeps the _rep copies apart).
        prev_rows = [Signal(p.map_width, name=f"prev_row_rep{g}") for g in range(n.groups)]
        prev_valids = [Signal(name=f"prev_valid_rep{g}") for g in range(n.groups)]
        n.prev_rows, n.prev_valids = prev_rows, prev_valids
        with m.If(n.leave):
            hypothesis = n.valid_q
            if n.timed_out is not None:  # a timeout's leading row is its answer, not information
                hypothesis = hypothesis & ~n.timed_out
            if p.nomatch_row:
                hypothesis = hypothesis & (n.winner != p.rows - 1)
            m.d.sync += [c.eq(n.winner) for c in prev_rows] + [c.eq(hypothesis) for c in prev_valids]
        settle = Signal(name="feedback_settle")
        m.d.sync += settle.eq(n.leave)
        n.settle = settle
        one = Const(p.word_one, p.memory_word_width)
        table = p.feedback_words
        last = len(table) - 1
        cols = p.operator_columns
        for r in range(p.rows):
            prev_row, prev_valid = prev_rows[r // n.rows_per_group], prev_valids[r // n.rows_per_group]
            word_q = Signal(p.memory_word_width, name=f"feedback_q_{r}", init=p.word_one)
            n.feedback_q.append(word_q)
            if p.nomatch_row and r == p.rows - 1:
                m.d.sync += word_q.eq(Mux(prev_valid, p.feedback_nomatch_word, one))
            else:
                dist = Signal(p.map_width, name=f"feedback_dist_{r}")
                m.d.comb += dist.eq(Mux(prev_row > r, prev_row - r, r - prev_row))
                # The table clamped by padding it with its last word to every distance the index can
                # take: the same words as min(dist, last), and a complete case (verilator -Wall).
                entries = Array(Const(table[min(i, last)], p.memory_word_width)
                                for i in range(1 << p.map_width))
                m.d.sync += word_q.eq(Mux(prev_valid, entries[dist], one))
            m.d.comb += n.incoming[r * cols].eq(Mux(n.shadow_line_start, one, word_q))

    def _start(self, m: Module, n: MachineNets) -> None:
        """Start: swap in the shadow memory, in a bubble or when idle (overrides the above)."""
        p = self._params
        cols = p.operator_columns
        if n.hidden:
            # The swap is the run's first compute cycle, decided a cycle early (_enables): a register.
            # It counts that cycle (the counters take its first bus) while the result register takes
            # the previous run's counters and cycles (_result).
            n.start = start = Signal(name="start_rep_ctl")
            with m.If(start):
                m.d.sync += [n.at_last.eq(p.max_clocks == 2), n.cycles_done.eq(1), n.running.eq(1),
                             n.shadow_full.eq(0), n.stop.eq(0)]
        else:
            n.start = start = Signal()
            if p.feedback_columns:  # the swap takes the feedback words registered after the bubble
                m.d.comb += start.eq(n.shadow_full & ~n.running & ~n.settle)
            else:
                m.d.comb += start.eq(n.shadow_full & (n.leave | ~n.running))
            with m.If(start):
                m.d.sync += [n.at_last.eq(0), n.cycles_done.eq(0), n.running.eq(1), n.shadow_full.eq(0)]
        for a, a_n, s in zip(n.scale_active, n.scale_active_n, n.scale_shadow, strict=True):
            if isinstance(a, Signal):  # normalize: the active pixel's scales, taken at the swap
                m.d.comb += a_n.eq(Mux(start, s, a))
                m.d.sync += a.eq(a_n)
        b = p.samples_per_clock
        for r in range(p.rows):
            with m.If(n.start_rep[r // n.rows_per_group]):
                m.d.sync += [n.active[o].eq(n.incoming[o]) for o in range(r * cols, (r + 1) * cols)]
                # Empty, or (no bubble) after the run's first cycle: its bus's 1s (counter max >= 2B:
                # not full, and the second cycle cannot overflow either).
                first = count_ones(n.first_row[r * b:(r + 1) * b]) if n.hidden else Const(0)
                if b == 1:
                    m.d.sync += [n.counts[r].eq(first), n.full[r].eq(0)]
                else:
                    room = p.counter_max - first
                    m.d.sync += [n.counts[r].eq(first), n.room[r].eq(Mux(room > 2 * b, 2 * b, room))]

    def _load(self, m: Module, n: MachineNets) -> None:
        """The load stream: one beat per handshake into the shadow memory, written a cycle later."""
        p = self._params
        nbeats = p.beats_per_pixel
        # Not ready while the shadow is full or its last beat is being written.
        # Without the bubble the swap cycle already takes a beat (written after the swap).
        held = n.shadow_full & ~n.start if n.hidden else n.shadow_full
        m.d.comb += self.load.ready.eq(~held & ~n.write_q[nbeats - 1])
        accept = self.load.valid & self.load.ready
        # Registered load: a beat is taken into ``load_q`` and written into the shadow memory the
        # cycle after, under a registered one-hot enable (no logic between a flip-flop and the
        # enables of a beat's words, which are spread over the whole matrix).
        beat = Signal(nbeats, init=1)  # one-hot: the beat the next handshake carries
        load_q = Signal.like(self.load.payload)
        n.beat, n.load_q = beat, load_q
        m.d.sync += n.write_q.eq(Mux(accept, beat, 0))
        with m.If(accept):
            m.d.sync += [load_q.eq(self.load.payload), beat.eq(beat.rotate_left(1))]
        words = beat_words(p, load_q)
        for b in range(nbeats):
            with m.If(n.write_q[b]):
                for lane in range(p.words_per_beat):
                    w = b * p.words_per_beat + lane
                    if w < p.words_per_pixel:  # unused lanes of the last beat are ignored
                        m.d.sync += n.shadow[w].eq(words[lane])
        if p.normalize:
            self._column_max(m, n, beat_words(p, self.load.payload), accept)
        with m.If(n.write_q[nbeats - 1]):
            m.d.sync += n.shadow_full.eq(1)
            if p.feedback_columns:
                m.d.sync += n.shadow_line_start.eq(load_q.line_start)

    def _column_max(self, m: Module, n: MachineNets, words: list[Value], accept: Value) -> None:
        """normalize: each loaded column's running maximum over the shadow's words, taken with each
        beat's handshake from the handshake's ``words`` and cleared at the swap (a beat taken in the
        swap, without the bubble, is the next pixel's first). The new maximum is the largest of the
        column's lanes in the beat (a lane that is not the column's in this beat reads 0) and the
        maximum so far, by one level of compares (:meth:`_largest`). So the maxima are final from the
        cycle the pixel's last beat is written on, a cycle before the earliest swap: the restart
        numbers' scale is a register (_operator_matrix) and no load cycle is added."""
        p = self._params
        loaded, per_beat = p.loaded_columns, p.words_per_beat
        for c in range(loaded):
            # Per lane, the beats in which it carries a word of column c.
            beats: dict[int, list[int]] = {}
            for b in range(p.beats_per_pixel):
                for lane in range(per_beat):
                    w = b * per_beat + lane
                    if w < p.words_per_pixel and w % loaded == c:
                        beats.setdefault(lane, []).append(b)
            lanes = [words[lane] if len(bs) == p.beats_per_pixel
                     else Mux(_or_all([n.beat[b] for b in bs]), words[lane], 0) for lane, bs in beats.items()]
            # Without the bubble a swap may take a beat (the next pixel's first): ``start`` is a register.
            so_far = Mux(n.start, 0, n.norm_max[c]) if n.hidden else n.norm_max[c]
            best = self._largest(m, f"norm_beat_{c}", [*lanes, so_far])
            m.d.sync += n.norm_max[c].eq(Mux(accept, best, Mux(n.start, 0, n.norm_max[c])))

    def _largest(self, m: Module, name: str, values: list[Value]) -> Value:
        """The largest of ``values`` by one level of compares: every pair compared at once, the first
        of the largest picked by the AND of its compares (nets ``<name>_<i>``, ``<name>_gt_<i>_<j>``)."""
        values = [self._net(m, f"{name}_{i}", v) for i, v in enumerate(values)]
        gt = {(i, j): self._net(m, f"{name}_gt_{i}_{j}", values[i] > values[j])
              for i in range(len(values)) for j in range(i)}
        picked = []
        for i, v in enumerate(values):
            # v_i is picked if it exceeds every earlier value and is at least every later one.
            wins = Cat(*(gt[i, j] for j in range(i)), *(~gt[j, i] for j in range(i + 1, len(values))))
            picked.append(Mux(wins.all(), v, 0))
        return self._net(m, name, _or_all(picked))

    def _enables(self, m: Module, n: MachineNets) -> None:
        """The next values of the replicated enables: the registers' updates, one cycle early."""
        nbeats = self._params.beats_per_pixel
        # Written as a last 2:1 choice on ``compute`` so that the OR over the rows (``fin``), the
        # late signal, enters the last gate only: in a compute cycle there is no start or leave,
        # running stays 1 and stop becomes ``fin``.
        fin = n.any_over | n.at_last
        shadow_full_n = ~n.start & (n.shadow_full | n.write_q[nbeats - 1])
        valid_n = n.leave | (self.result.valid & ~self.result.ready)
        stop_idle = n.stop & ~n.leave  # stop's next value outside compute cycles
        running_n = n.start | (n.running & ~n.leave)
        compute_n, start_n = Signal(), Signal()
        # timeout_answer "leading": a timed-out run's bubble waits for the search (no swap before it).
        searched = n.timeout_now if n.search is not None else Const(0)  # in a compute cycle
        search_n = n.search_n
        if n.hidden:
            # The next cycle is a swap (and the next run's first compute cycle) after a run's last
            # compute cycle, if the shadow was complete in it (the first bits were registered from
            # it), the result register will be free, and that cycle did not begin a Sobol block (it
            # steps the shift LFSR: the registered first bits used the shift before it); else the
            # bubble, then a swap from the bubble or idle once the shadow is complete.
            hold = self.result.valid & ~self.result.ready
            go_on = n.shadow_full & ~hold & ~n.source.fresh & ~searched
            idle_start = n.shadow_full & ((stop_idle & ~hold & ~search_n) | ~(n.running & ~n.leave))
            m.d.comb += [compute_n.eq(Mux(n.compute, ~fin | go_on, n.start | idle_start)),
                         start_n.eq(Mux(n.compute, fin & go_on, ~n.start & idle_start))]
            m.d.sync += [n.start.eq(start_n)]
        else:
            m.d.comb += compute_n.eq(Mux(n.compute, ~fin, running_n & ~stop_idle))
            if self._params.feedback_columns:  # no swap in a bubble nor while settling (see _start)
                m.d.comb += start_n.eq(shadow_full_n & ~running_n & ~n.leave)
            else:
                m.d.comb += start_n.eq(Mux(n.compute, fin & shadow_full_n & ~valid_n & ~searched,
                                           shadow_full_n & ((stop_idle & ~valid_n & ~search_n) | ~running_n)))
        m.d.sync += [c.eq(compute_n) for c in n.compute_rep + [c for c, _ in n.src_reps]]
        m.d.sync += [s.eq(start_n) for s in n.start_rep + [s for _, s in n.src_reps]]
