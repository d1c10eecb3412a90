"""The top level: ``BayesianMachine(params=params)``, the stochastic Bayesian machine of the paper.

An M x N matrix of stochastic operators (``operator.py``) fed by a random source
(``sources.py``: LFSRs, shared LFSRs or Sobol generators, or numbers on a port) and by
double-buffered likelihood memories; the AND of a row's operators is the
row's stochastic bus signal, counted by its overflow counter (``counters.py``); the first
overflow(s) stop the run and the MAP encoder (``encoder.py``) names the winner. The exact
per-cycle semantics, ports and word order are in ``docs/architecture.md``; the NumPy model
``bayesmachine.sim.model`` computes the same thing bit for bit.

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
``_result``, ``_start``, ``_enables``, ``_load``), sharing the nets of :class:`_Nets`.

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

from .counters import overflow_counter_full
from .encoder import MAPEncoder
from .operator import bus_rows, operator_bits, operator_rows, top_bit_pair
from .signatures import MachineSignature, beat_words, entropy_layout, load_layout, result_layout
from .sources import OnChipSource, random_source

__all__ = [
    "BUBBLE_CYCLES", "FEEDBACK_CYCLES", "GROUP_OPERATORS", "LOAD_LATENCY", "SOURCE_GROUPS", "BayesianMachine",
    "entropy_layout", "hides_bubble",
    "load_layout", "pixel_wall_cycles", "result_layout",
]

BUBBLE_CYCLES = 1  # clock cycles per run after its last compute cycle (the registered stop)
LOAD_LATENCY = 1  # a load beat is written into the shadow memory the cycle after its handshake
FEEDBACK_CYCLES = 2  # a neighbour prior's swap after the bubble: the result, then the feedback words
GROUP_OPERATORS = 12  # operators per registered copy of the compute and start enables
SOURCE_GROUPS = 3  # groups of rows per copy of a shared random source (its next numbers' fan-out)


def hides_bubble(params: MachineParams) -> bool:
    """Whether the machine swaps the next pixel in during its first compute cycle (no bubble).

    With ``sobol`` the next pixel's first numbers (a block's shift) are known while the previous
    pixel runs, so its first cycle's bits are compared in advance and the cycle after a run's last
    one is already the next run's first. Not with a neighbour prior (the next pixel's feedback
    words follow the result), nor with counter max 1 (a run's second cycle could overflow: its
    prefetched overflow flag would need the first cycle's counters), nor with LFSR sources (their
    next numbers depend on whether the previous run goes on).
    """
    return params.rng == "sobol" and not params.feedback_columns and params.counter_max >= 2


def pixel_wall_cycles(params: MachineParams, cycles: np.ndarray) -> np.ndarray:
    """Clock cycles per pixel in steady state (loads keep coming, results are taken at once).

    A run of k compute cycles is followed by its bubble, in which the next pixel is swapped in if
    its ``beats_per_pixel`` load beats have been written (they start the cycle after the previous
    swap, and each is written the cycle after its handshake):
    ``max(k, beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES``.

    Without the bubble (:func:`hides_bubble`) the next run's first compute cycle is its swap, and the
    next pixel's beats start in it: ``max(k, beats_per_pixel + LOAD_LATENCY + 1)``, plus one bubble
    after a run whose last cycle began a Sobol block (k - 1 a nonzero multiple of 2^W: that cycle
    steps the shift LFSR, so the next run's first numbers were not known a cycle early).
    """
    cycles = np.asarray(cycles, dtype=np.int64)
    if hides_bubble(params):
        block = 1 << params.word_bits
        late = (cycles > 1) & ((cycles - 1) % block == 0)
        return np.maximum(cycles + late, params.beats_per_pixel + LOAD_LATENCY + 1)
    # A neighbour prior's swap waits two cycles more: the bubble registers the result, the next cycle
    # the feedback column's words (see ``BayesianMachine._feedback_prior``).
    settle = FEEDBACK_CYCLES * params.feedback_columns
    return np.maximum(cycles + settle, params.beats_per_pixel + LOAD_LATENCY) + BUBBLE_CYCLES


@dataclass
class _Nets:
    """The nets the builders of ``BayesianMachine.elaborate`` share (each documented where it is driven)."""

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
    start: Signal | None = None  # the shadow is swapped in (in a bubble or when idle)
    settle: Value = field(default_factory=lambda: Const(0))  # neighbour prior: feedback words forming
    hidden: bool = False  # no bubble: a run's first compute cycle is its swap (hides_bubble)
    first_row: Value | None = None  # hidden: the next run's first stochastic bus, from registered bits


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
        With an off-chip ``rng`` ("external", "smtj") only: one random number per operator,
        sampled on compute cycles.
    entropy_ready : ``Out(1)``
        With an off-chip ``rng`` only: high on compute cycles (the numbers on ``entropy`` are
        consumed at the clock edge).

    The ports are :class:`~.signatures.MachineSignature` ``(params)``.
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"BayesianMachine takes a MachineParams, not {type(params).__name__}")
        self._params = params
        super().__init__(MachineSignature(params))

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        m = Module()
        n = self._memories()
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

    def _memories(self) -> _Nets:
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
        return _Nets(
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

    def _random_numbers(self, m: Module, n: _Nets) -> None:
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

    def _operator_matrix(self, m: Module, n: _Nets) -> None:
        """The operator matrix: each row's AND of ``number < word``, the stochastic bus."""
        p = self._params
        rows, cols, ops = p.rows, p.operator_columns, p.operators
        source = n.source
        n.row = Signal(rows, name="row")
        if source is None:
            # Numbers from a port arrive in their cycle and are compared then.
            numbers = [self.entropy[o] for o in range(ops)]
            m.d.comb += n.row.eq(operator_rows(numbers, n.active, rows, cols, list(range(ops))))
            return
        # Prefetched comparators (on-chip sources): ``bit_q[o]`` holds this compute cycle's
        # ``number < word``. It is loaded in the cycle before: in a compute cycle from the next
        # numbers and the same word, in a swap from the numbers the source gives after the
        # start (a Sobol block restarts) and the incoming (shadow) word. Same bits as comparing
        # in the cycle itself, but the matrix's path to the stop flip-flop starts at a register
        # instead of a carry chain.
        index = source.operator_numbers
        if source.shared:
            # A number shared by a column's rows would reach all its comparators from one net:
            # each group of rows gets a registered copy of the column's next numbers, loaded
            # every clock from ``following_numbers`` (so equal to ``next_numbers`` in every
            # cycle), and one of its restart numbers, loaded from ``following_restart_numbers``
            # (equal to ``restart_numbers``). The flow keeps these ``_rep`` registers apart too.
            def group_copies(name: str, attr: str) -> list[list[Signal]]:
                copies = []
                for g in range(n.groups):
                    following = list(getattr(n.sources[g // n.groups_per_source], attr))
                    copy = [Signal(len(x), name=f"{name}_rep{g}_{i}") for i, x in enumerate(following)]
                    m.d.sync += [c.eq(x) for c, x in zip(copy, following, strict=True)]
                    copies.append(copy)
                return copies

            def group_bits(copies: list[list[Signal]], words: list[Signal]) -> list[Value]:
                return [operator_bits(copies[o // cols // n.rows_per_group], [words[o]], [index[o]])[0]
                        for o in range(ops)]

            n.next_bits = group_bits(group_copies("next_number", "following_numbers"), n.active)
            restart_copies = group_copies("restart_number", "following_restart_numbers")
            start_bits = group_bits(restart_copies, n.incoming)
        else:
            n.next_bits = operator_bits(list(source.next_numbers), n.active, index)
            start_bits = operator_bits(list(source.restart_numbers), n.incoming, index)
        swap_bits = start_bits
        if n.hidden:
            # No bubble (hides_bubble, "Timing" in docs/architecture.md): the swap is the next run's
            # first compute cycle. Its bits (the restart numbers against the shadow words) are
            # registered every cycle in ``first_bit`` and drive ``first_row`` in the swap; the swap
            # loads ``bit_q`` with the run's second bits, the restart numbers XOR V_c[0] = 2^(W-1)
            # (a block's second point) against the shadow words, which the swap is still reading.
            # Both come from one comparator of the low W - 1 bits (``top_bit_pair``).
            restart = ([restart_copies[o // cols // n.rows_per_group][index[o]] for o in range(ops)]
                       if source.shared else [source.restart_numbers[index[o]] for o in range(ops)])
            assert all(d == 1 << (p.word_bits - 1) for d in source.first_directions)
            first_bits, swap_bits = [], []
            for o in range(ops):
                first, second = top_bit_pair(restart[o], n.incoming[o])
                first_bit = Signal(name=f"first_bit_{o // cols}_{o % cols}")
                m.d.sync += first_bit.eq(first)
                first_bits.append(first_bit)
                swap_bits.append(second)
            n.first_row = bus_rows(first_bits, rows, cols)
        bits = []
        for o in range(ops):
            g = o // cols // n.rows_per_group
            bit_q = Signal(name=f"bit_{o // cols}_{o % cols}")
            # A swap first: with the bubble it never coincides with a compute cycle; without, the
            # swap is also a compute cycle (the next run's first).
            with m.If(n.start_rep[g]):
                m.d.sync += bit_q.eq(swap_bits[o])
            with m.Elif(n.compute_rep[g]):
                m.d.sync += bit_q.eq(n.next_bits[o])
            bits.append(bit_q)
        m.d.comb += n.row.eq(bus_rows(bits, rows, cols))

    def _overflow_counters(self, m: Module, n: _Nets) -> None:
        """The overflow counters, with registered "full" flags (count == n_max)."""
        p = self._params
        n.full, n.over = Signal(p.rows, name="full"), Signal(p.rows, name="over")
        for r in range(p.rows):
            ov, nxt, nfull = overflow_counter_full(n.row[r], n.counts[r], n.full[r], p.counter_max)
            m.d.comb += n.over[r].eq(ov)
            n.next_counts.append(nxt)
            n.next_full.append(nfull)

    def _stop_decision(self, m: Module, n: _Nets) -> None:
        """The registered stop: a row overflows or the watchdog expires; counters advance."""
        p = self._params
        cols = p.operator_columns
        # A compute cycle: running and not yet stopped. The stop is registered (see "Timing" in
        # docs/architecture.md), so every wide enable is a function of registers only, never of
        # the matrix.
        m.d.comb += n.compute.eq(n.running & ~n.stop)
        # The stop decision needs only whether any row overflows (the encoder works in the bubble).
        # With prefetched comparators that too is known a cycle early, per group of rows: the
        # next cycle's ``row & full`` from the next bits and the next full flags, ORed over the
        # group's rows into one flip-flop (0 after a swap: the counters restart empty). The
        # stop is then an OR of one flip-flop per group.
        if n.next_bits:
            over_group = [Signal(name=f"over_group_{g}") for g in range(n.groups)]
            for g in range(n.groups):
                terms = []
                for r in range(g * n.rows_per_group, min(p.rows, (g + 1) * n.rows_per_group)):
                    row_next = bus_rows(n.next_bits[r * cols:(r + 1) * cols], 1, cols)
                    terms.append(row_next & n.next_full[r])
                # 0 after a swap: the counters restart empty (without the bubble the swap is the
                # run's first cycle, and its second cannot overflow either: counter max >= 2).
                with m.If(n.start_rep[g]):
                    m.d.sync += over_group[g].eq(0)
                with m.Elif(n.compute_rep[g]):
                    m.d.sync += over_group[g].eq(Cat(terms).any())
            n.any_over = Cat(over_group).any()
        else:
            n.any_over = n.over.any()

        # The watchdog, registered too: ``at_last`` is high in compute cycle k == max_cycles.
        n.at_last = Signal(name="at_last")
        finish = Signal()
        m.d.comb += finish.eq(n.compute & (n.any_over | n.at_last))
        n.over_q = Signal(p.rows, name="over_q")
        with m.If(n.compute):
            m.d.sync += [
                n.cycles_done.eq(n.cycles_done + 1),
                n.at_last.eq(n.cycles_done == p.max_cycles - 2),  # max_cycles >= 2: never at start
                n.stop.eq(finish),
            ]
        for r in range(p.rows):
            with m.If(n.compute_rep[r // n.rows_per_group]):
                m.d.sync += [n.counts[r].eq(n.next_counts[r]), n.full[r].eq(n.next_full[r]),
                             n.over_q[r].eq(n.over[r])]

    def _result(self, m: Module, n: _Nets) -> None:
        """The bubble hands the result over (the result register is empty: a register, no ready)."""
        p = self._params
        res = self.result.payload
        n.leave = leave = Signal()
        m.d.comb += leave.eq(n.stop & ~self.result.valid)
        with m.If(self.result.ready):
            m.d.sync += self.result.valid.eq(0)
        m.submodules.encoder = encoder = MAPEncoder(rows=p.rows, nomatch_row=p.nomatch_row,
                                                    tie_break=p.tie_break)
        m.d.comb += encoder.over.eq(n.over_q)
        valid_q, winner = encoder.valid, encoder.index
        n.valid_q, n.winner = valid_q, winner
        with m.If(leave):
            map_value = Signal(p.map_width)
            m.d.comb += map_value.eq(winner)
            m.d.sync += [
                self.result.valid.eq(1),
                res.map.eq(valid_q.replicate(p.map_width) & map_value),
                res.timeout.eq(~valid_q),
                res.cycles.eq(n.cycles_done),
                res.counts.eq(Cat(n.counts)),
                n.running.eq(0),
                n.stop.eq(0),
            ]
            if p.nomatch_row:
                m.d.sync += res.nomatch.eq(valid_q & (map_value == p.rows - 1))
            else:
                m.d.sync += res.nomatch.eq(0)

    def _feedback_prior(self, m: Module, n: _Nets) -> None:
        """A neighbour prior's feedback column 0: formed at each swap from the previous result.

        The bubble registers the winning row (``prev_row``, a copy per group of rows) and whether
        it is a hypothesis row (``prev_valid``: not the no-match row, not a timeout); the next
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
        with m.If(n.leave):
            hypothesis = n.valid_q
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

    def _start(self, m: Module, n: _Nets) -> None:
        """Start: swap in the shadow memory, in a bubble or when idle (overrides the above)."""
        p = self._params
        cols = p.operator_columns
        if n.hidden:
            # The swap is the run's first compute cycle, decided a cycle early (_enables): a register.
            # It counts that cycle (the counters take its first bus) while the result register takes
            # the previous run's counters and cycles (_result).
            n.start = start = Signal(name="start_rep_ctl")
            with m.If(start):
                m.d.sync += [n.at_last.eq(p.max_cycles == 2), n.cycles_done.eq(1), n.running.eq(1),
                             n.shadow_full.eq(0), n.stop.eq(0)]
        else:
            n.start = start = Signal()
            if p.feedback_columns:  # the swap takes the feedback words registered after the bubble
                m.d.comb += start.eq(n.shadow_full & ~n.running & ~n.settle)
            else:
                m.d.comb += start.eq(n.shadow_full & (n.leave | ~n.running))
            with m.If(start):
                m.d.sync += [n.at_last.eq(0), n.cycles_done.eq(0), n.running.eq(1), n.shadow_full.eq(0)]
        for r in range(p.rows):
            with m.If(n.start_rep[r // n.rows_per_group]):
                m.d.sync += [n.active[o].eq(n.incoming[o]) for o in range(r * cols, (r + 1) * cols)]
                # Empty, or (no bubble) after the run's first cycle: its bus (counter max >= 2: not full).
                m.d.sync += [n.counts[r].eq(n.first_row[r] if n.hidden else 0), n.full[r].eq(0)]

    def _load(self, m: Module, n: _Nets) -> None:
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
        with m.If(n.write_q[nbeats - 1]):
            m.d.sync += n.shadow_full.eq(1)
            if p.feedback_columns:
                m.d.sync += n.shadow_line_start.eq(load_q.line_start)

    def _enables(self, m: Module, n: _Nets) -> None:
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
        if n.hidden:
            # The next cycle is a swap (and the next run's first compute cycle) after a run's last
            # compute cycle, if the shadow was complete in it (the first bits were registered from
            # it), the result register will be free, and that cycle did not begin a Sobol block (it
            # steps the shift LFSR: the registered first bits used the shift before it); else the
            # bubble, then a swap from the bubble or idle once the shadow is complete.
            hold = self.result.valid & ~self.result.ready
            go_on = n.shadow_full & ~hold & ~n.source.fresh
            idle_start = n.shadow_full & ((stop_idle & ~hold) | ~(n.running & ~n.leave))
            m.d.comb += [compute_n.eq(Mux(n.compute, ~fin | go_on, n.start | idle_start)),
                         start_n.eq(Mux(n.compute, fin & go_on, ~n.start & idle_start))]
            m.d.sync += [n.start.eq(start_n)]
        else:
            m.d.comb += compute_n.eq(Mux(n.compute, ~fin, running_n & ~stop_idle))
            if self._params.feedback_columns:  # no swap in a bubble nor while settling (see _start)
                m.d.comb += start_n.eq(shadow_full_n & ~running_n & ~n.leave)
            else:
                m.d.comb += start_n.eq(Mux(n.compute, fin & shadow_full_n & ~valid_n,
                                           shadow_full_n & ((stop_idle & ~valid_n) | ~running_n)))
        m.d.sync += [c.eq(compute_n) for c in n.compute_rep + [c for c, _ in n.src_reps]]
        m.d.sync += [s.eq(start_n) for s in n.start_rep + [s for _, s in n.src_reps]]
