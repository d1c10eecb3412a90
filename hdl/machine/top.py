"""The top level: ``BayesianMachine(params=params)``, the stochastic Bayesian machine of the paper.

An M x N matrix of stochastic operators (``operator.py``, built by ``matrix.py``) fed by a random
source (``hdl/sources.py``: LFSRs, shared LFSRs or Sobol generators, or numbers on a port) and by
double-buffered likelihood memories; the AND of a row's operators is the row's stochastic bus
signal, counted by its overflow counter (``counters.py``, ``stop.py``); the first overflow(s) stop
the run and the MAP encoder (``encoder.py``) names the winner. With B samples per clock
(``samples_per_clock``) every operator compares B numbers per clock, the bus carries B bits per row
and the run stops at the sample of its first overflow; with ``timeout_answer = "leading"`` a
timed-out run's bubble searches the leading row first. The exact per-sample semantics, ports and
word order are in ``docs/architecture.md``; the NumPy model ``bayesmachine.sim.model`` computes the
same thing bit for bit.

Timing (``bayesmachine.integrators.stochastic``; ``docs/architecture.md``, "Timing"):

- ``load`` takes one beat per handshake and writes it into the *shadow* likelihood memory the
  cycle after; ``load.ready`` is low while the shadow holds a complete pixel not yet started
  (or its last beat is being written).
- A run's compute cycles advance the random source, counters and cycle count. The cycle after
  the last one is the run's *bubble* (the stop decision is registered): the result register
  takes the result, and a complete shadow is swapped into the *active* memory, so runs go back
  to back with one bubble between them. Back-pressure on ``result`` holds the bubble, never a
  compute cycle, so it changes no result.

:meth:`~BayesianMachine.build` (what ``elaborate`` builds, with the nets a proof reads) is a sequence of
named builders, one per part of the design (``_memories``,
``_column_scales``, ``_random_numbers``, ``matrix.operator_matrix``, ``stop.overflow_counters``,
``stop.stop_decision``, ``_result``, ``_feedback_prior``, ``_start``, ``_enables``, ``_load``),
sharing the nets of :class:`~.nets.MachineNets`.

The random source, the MAP encoder (``encoder.MAPEncoder``), a neighbour prior's feedback column
(``feedback.FeedbackPrior``) and per-pixel normalization's column scales
(``normalize.ColumnScales``) are direct submodules (depth 1), the very components their unit tests
drive. The operator matrix and the counters are built into this module (``matrix.py``: a
submodule's port copies of every word and number would slow Amaranth's Python simulator).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import wiring

from bayesmachine.hdl.signatures import MachineSignature, beat_words
from bayesmachine.hdl.sources import random_source
from bayesmachine.integrators.stochastic import hides_bubble
from bayesmachine.params import MachineParams

from .counters import count_ones
from .encoder import MAPEncoder
from .feedback import FeedbackPrior
from .matrix import operator_matrix
from .nets import SOURCE_GROUPS, MachineNets, row_groups
from .normalize import ColumnScales
from .stop import overflow_counters, stop_decision

__all__ = ["BayesianMachine"]


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
    The ports are :class:`bayesmachine.hdl.signatures.MachineSignature` ``(params)``.
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
        return self.build(platform)[0]

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        """The machine's module (what :meth:`elaborate` gives) and its :class:`MachineNets`: the internal
        nets and registers a proof relates to its reference (``hdl.formal``; a mutant changes them)."""
        m = Module()
        n = self._memories()
        self._column_scales(m, n)
        self._random_numbers(m, n)
        operator_matrix(m, n, self._params, self.entropy if n.source is None else None)
        overflow_counters(m, n, self._params)
        stop_decision(m, n, self._params)
        self._result(m, n)
        self._feedback_prior(m, n)
        self._start(m, n)
        self._enables(m, n)
        self._load(m, n)
        return m, n

    def _memories(self) -> MachineNets:
        """The likelihood memories, the run state and the registered enables' copies."""
        p = self._params
        rows, cols, ops = p.rows, p.operator_columns, p.operators
        # Likelihood memories (registers: every operator reads its word every cycle). No reset: a
        # run always starts by copying a complete shadow into the active memory.
        # The shadow holds the loaded words (a neighbour prior's feedback column 0 is formed at the
        # swap instead, by the FeedbackPrior: the result it follows comes later).
        fb, loaded = p.feedback_columns, p.loaded_columns
        shadow = [Signal(p.memory_word_width, name=f"shadow_{w // loaded}_{fb + w % loaded}", reset_less=True)
                  for w in range(p.words_per_pixel)]
        feedback = FeedbackPrior(params=p) if fb else None
        incoming: list[Value] = []
        for o in range(ops):
            r, c = divmod(o, cols)
            incoming.append(feedback.words[r] if c < fb else shadow[r * loaded + c - fb])
        active = [Signal(p.memory_word_width, name=f"word_{o // cols}_{o % cols}", reset_less=True)
                  for o in range(ops)]
        # The matrix's enables (compute: random source, counters; start: the shadow-to-active copy)
        # reach thousands of flip-flops: each group of rows gets its own registered copy, loaded
        # with the enable's next value (``compute_n``/``start_n``, see _enables), so no net fans
        # out further than a group (row_groups). The flow keeps these ``_rep`` registers apart
        # (docs/fpga.md).
        rows_per_group, groups = row_groups(p)
        return MachineNets(
            hidden=hides_bubble(p), feedback=feedback,
            # A neighbour prior's machine keeps one source: copies of it routed no faster, for many
            # more LUTs (measured: docs/fpga.md, "The census model's machine").
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
        """Per-pixel column normalization (``normalize``): the ColumnScales keeps each loaded column's
        scale m, of the shadow's pixel (its words taken with each beat's handshake, _load) and of the
        active one (taken at the swap, _start). The operators of the column compare their words with
        ``(number * m) >> W`` (matrix.py). A feedback column is not scaled (m = 2^W)."""
        p = self._params
        if not p.normalize:
            return
        m.submodules.column_scales = n.scales = scales = ColumnScales(params=p)
        n.norm_max = list(scales.shadow)
        one = Const(p.word_one, p.memory_word_width)
        for c in range(p.operator_columns):
            loaded = c - p.feedback_columns
            n.scale_shadow.append(scales.shadow[loaded] if loaded >= 0 else one)
            n.scale_active.append(scales.active[loaded] if loaded >= 0 else one)
            n.scale_active_n.append(scales.active_next[loaded] if loaded >= 0 else one)

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
            # numbers (matrix.py), so the next-number logic's nets stay within a few groups
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
        """A neighbour prior's feedback column 0 (the FeedbackPrior, whose words are the column's
        incoming words, _memories): formed at each swap from the result the bubble hands over."""
        feedback = n.feedback
        if feedback is None:
            return
        m.submodules.feedback_prior = feedback
        m.d.comb += [feedback.leave.eq(n.leave), feedback.map.eq(n.winner), feedback.valid.eq(n.valid_q),
                     feedback.line_start.eq(n.shadow_line_start)]
        if n.timed_out is not None:
            m.d.comb += feedback.timed_out.eq(n.timed_out)
        n.prev_rows, n.prev_valids = feedback.previous_rows, feedback.previous_valid
        n.feedback_q, n.settle = feedback.registered_words, feedback.settle

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
        if n.scales is not None:  # normalize: the active pixel's scales, taken at the swap
            m.d.comb += n.scales.start.eq(start)
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
        if n.scales is not None:  # normalize: each column's maximum, taken with the handshake
            m.d.comb += [n.scales.accept.eq(accept), n.scales.beat.eq(beat)]
            offered = beat_words(p, self.load.payload)
            m.d.comb += [n.scales.words[lane].eq(offered[lane]) for lane in range(p.words_per_beat)]
        with m.If(n.write_q[nbeats - 1]):
            m.d.sync += n.shadow_full.eq(1)
            if p.feedback_columns:
                m.d.sync += n.shadow_line_start.eq(load_q.line_start)

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

