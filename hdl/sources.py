"""RTL of the on-chip random sources: one generator component per kind, the machine's submodule.

Each on-chip kind of ``bayesmachine.sources.SOURCE_KINDS`` has one component here, built from
the pure-Python definitions in ``bayesmachine.sources`` (the same ones the model's kernels use):

- ``lfsr``: :class:`LFSRBank` of one leap-forward LFSR per operator;
- ``lfsr-shared``: :class:`LFSRBank` of one LFSR per operator column, every row of a column
  reading its column's number;
- ``sobol``: :class:`SobolGenerators`, one Sobol generator per operator column sharing a block
  index counter, each with a shift LFSR.

Both implement one interface, :class:`OnChipSource`, the only thing the machine knows of them:
``enable`` and ``restart`` ports (a compute cycle: the source advances; a pixel's run starts),
the numbers of this cycle and, for the machine's prefetched comparators, of the next one
(``numbers``, ``next_numbers``, ``restart_numbers``, ``following_numbers``,
``following_restart_numbers``: lists of W-bit values, separate signals, since Amaranth's
simulator updates them far faster than slices of one wide signal), and ``operator_numbers``,
the entry each operator compares against. ``LFSRBank`` exposes its LFSR registers themselves as
ports ``state_<i>`` (``numbers[i]`` is the W low bits of ``state_<i>``): a copy of every number
into an output port would slow the full machine's simulation.
:func:`random_source` builds the component of a machine. The unit tests (``tests/sources/test_lfsr.py``,
``tests/sources/test_sobol.py``) drive the very components the machine instantiates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from amaranth.hdl import Cat, Module, Mux, Signal, Value, unsigned
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources import source_kind
from bayesmachine.sources.lfsr import LFSRSpec, column_lfsr_specs, lfsr_specs
from bayesmachine.sources.sobol import check_params, clock_directions, sample_points

__all__ = ["SOURCE_NUMBERS", "LFSRBank", "OnChipSource", "SobolGenerators", "lfsr_next_state_expr",
           "random_source"]

# The per-cycle number lists every on-chip source gives (see OnChipSource).
SOURCE_NUMBERS = ("numbers", "next_numbers", "restart_numbers", "following_numbers",
                  "following_restart_numbers")


def lfsr_next_state_expr(state: Value, spec: LFSRSpec) -> Value:
    """The leap-forward next-state expression (the RTL form of ``sources.lfsr.lfsr_step``)."""
    w, length = spec.step, spec.length
    new = state[0:w]
    for t in spec.taps:
        if t:
            new = new ^ state[t : t + w]
    return Cat(state[w:length], new)


class OnChipSource(wiring.Component):
    """The interface of an on-chip random source, as the machine uses it.

    A subclass declares the ports ``enable`` and ``restart`` (``In(enable_groups)`` each) in its
    signature and gives the lists :data:`SOURCE_NUMBERS` (checked when it is built).

    Attributes
    ----------
    enable : ``In(enable_groups)``
        A compute cycle: the numbers of bit g's group advance at the clock edge.
    restart : ``In(enable_groups)``
        A pixel's run starts (the machine's swap): a source with per-pixel state (a Sobol block)
        begins anew; a no-op for LFSRs, which have nothing to restart.
    numbers : list of Value
        This cycle's W-bit numbers.
    next_numbers : list of Value
        The next compute cycle's numbers when this cycle is a compute cycle (``enable``).
    restart_numbers : list of Value
        The next compute cycle's numbers when this cycle restarts without computing.
    following_numbers, following_restart_numbers : list of Value
        ``next_numbers`` / ``restart_numbers`` of the next cycle, from this cycle's state and
        inputs: a register loaded with one every clock equals the other in every cycle (the
        machine keeps such copies per group of rows for numbers shared by many comparators).
    operator_numbers : tuple of int
        Per operator, the index of the entry of ``numbers`` it compares against.
    shared : bool
        Whether an entry is read by several operators (a column's rows): the machine then keeps
        registered per-group copies of the numbers, and the source has one enable group.
    sample_points : tuple of tuple of int
        Per entry, the B constants (B = ``samples_per_clock``) a compute cycle's B numbers are the
        entry's number XOR, sample by sample: ``(0,)`` for a source of one number per clock.
    """

    def __init__(self, signature: dict[str, wiring.Member], *, operator_numbers: Sequence[int]) -> None:
        self._operator_numbers = tuple(int(i) for i in operator_numbers)
        super().__init__(signature)
        for name in ("enable", "restart"):
            if name not in self.signature.members:
                raise TypeError(f"{type(self).__name__} must declare the port {name!r} of an on-chip source")
        count = len(self.numbers)
        if any(len(getattr(self, name)) != count for name in SOURCE_NUMBERS):
            raise TypeError(f"{type(self).__name__} must give {count} entries in each of {SOURCE_NUMBERS}")
        if not self._operator_numbers or not all(0 <= i < count for i in self._operator_numbers):
            raise ParameterError(f"operator_numbers must index the {count} numbers, one entry per operator")
        if self.shared and len(self.enable) != 1:
            raise ParameterError("a source whose numbers are shared by several operators has one enable")

    @property
    def operator_numbers(self) -> tuple[int, ...]:
        return self._operator_numbers

    @property
    def shared(self) -> bool:
        return len(set(self._operator_numbers)) < len(self._operator_numbers)

    @property
    def sample_points(self) -> tuple[tuple[int, ...], ...]:
        return ((0,),) * len(self.numbers)


class LFSRBank(OnChipSource):
    """Leap-forward LFSRs, one per spec: an :class:`OnChipSource` (the interface's lists are Python
    properties over the LFSR registers).

    All LFSRs advance W bits on each clock where ``enable`` is high (compute cycles only).
    With ``enable_groups`` (one group index per LFSR), ``enable`` has one bit per group and
    LFSR i advances on ``enable[enable_groups[i]]``: the machine drives the groups from
    registered copies of its compute enable, so no enable net reaches every LFSR.

    ``next_numbers[i]`` is the number LFSR i gives in the next compute cycle if this cycle is a
    compute cycle (the low W bits of its next state: wires when L >= 2W); outside a compute
    cycle the next compute cycle's number is ``numbers[i]`` (``restart_numbers``, the same
    list: an LFSR has nothing to restart, ``restart`` is ignored).

    Parameters
    ----------
    specs : sequence of LFSRSpec
        One per LFSR, all with the same ``step`` (W).
    enable_groups : sequence of int, optional
        The enable bit of each LFSR (default: one enable for all).
    operator_numbers : sequence of int, optional
        Per operator, the LFSR it reads (default: operator i reads LFSR i).

    Attributes
    ----------
    enable, restart : ``In(max(enable_groups) + 1)``
        See :class:`OnChipSource` (``restart`` is a no-op).
    state_<i> : ``Out(unsigned(specs[i].length))``
        LFSR i's register, reset to the spec's start state; ``numbers[i]`` is its W oldest bits.
    """

    def __init__(self, *, specs: Sequence[LFSRSpec], enable_groups: Sequence[int] | None = None,
                 operator_numbers: Sequence[int] | None = None) -> None:
        if isinstance(specs, LFSRSpec) or not isinstance(specs, Sequence):
            raise TypeError(f"specs must be a sequence of LFSRSpec, not {type(specs).__name__}")
        specs = tuple(specs)
        if any(not isinstance(s, LFSRSpec) for s in specs):
            raise TypeError("specs must be a sequence of LFSRSpec")
        if not specs:
            raise ParameterError("specs must be a non-empty sequence of LFSRSpec")
        if len({s.step for s in specs}) != 1:
            raise ParameterError("specs must all deliver the same number of bits per clock (step)")
        self._specs = specs
        if enable_groups is None:
            self._groups = (0,) * len(specs)
        else:
            self._groups = tuple(int(g) for g in enable_groups)
            if len(self._groups) != len(specs) or min(self._groups) < 0:
                raise ParameterError("enable_groups must give one group index (>= 0) per LFSR")
        width = max(self._groups) + 1
        members = {"enable": In(width), "restart": In(width)}
        for i, spec in enumerate(specs):
            members[f"state_{i}"] = Out(unsigned(spec.length), init=spec.init)
        super().__init__(members, operator_numbers=range(len(specs)) if operator_numbers is None
                         else operator_numbers)

    @property
    def enable_groups(self) -> tuple[int, ...]:
        return self._groups

    @property
    def numbers(self) -> list[Value]:
        return [getattr(self, f"state_{i}")[: s.step] for i, s in enumerate(self._specs)]

    @property
    def next_numbers(self) -> list[Value]:
        """The next compute cycle's numbers when this cycle is a compute cycle."""
        return [lfsr_next_state_expr(getattr(self, f"state_{i}"), s)[: s.step]
                for i, s in enumerate(self._specs)]

    @property
    def restart_numbers(self) -> list[Value]:
        """The next compute cycle's numbers when this cycle is not a compute cycle."""
        return self.numbers

    @property
    def following_numbers(self) -> list[Value]:
        """``next_numbers`` of the next cycle, from this cycle's state and ``enable``: a register
        loaded with it every clock equals ``next_numbers`` in every cycle (the machine keeps such
        copies per group of rows for numbers shared by many comparators)."""
        out = []
        for i, s in enumerate(self._specs):
            state = getattr(self, f"state_{i}")
            step1 = lfsr_next_state_expr(state, s)
            step2 = lfsr_next_state_expr(step1, s)
            out.append(Mux(self.enable[self._groups[i]], step2[: s.step], step1[: s.step]))
        return out

    @property
    def following_restart_numbers(self) -> list[Value]:
        """``restart_numbers`` of the next cycle, from this cycle's state and ``enable``: a register
        loaded with it every clock equals ``restart_numbers`` in every cycle (the machine keeps
        such copies per group of rows for numbers shared by many start comparators). An LFSR's
        restart number is its number: the next state's low bits if enabled, else this one's."""
        return [Mux(self.enable[self._groups[i]], n, r)
                for i, (n, r) in enumerate(zip(self.next_numbers, self.numbers, strict=True))]

    @property
    def specs(self) -> tuple[LFSRSpec, ...]:
        return self._specs

    def elaborate(self, platform: object) -> Module:
        m = Module()
        for i, spec in enumerate(self._specs):
            state = getattr(self, f"state_{i}")
            with m.If(self.enable[self._groups[i]]):
                m.d.sync += state.eq(lfsr_next_state_expr(state, spec))
        return m


@dataclass(frozen=True)
class _BlockIndex:
    """A Sobol generator's index in the block, as its columns read it (``SobolGenerators._block_index``):
    ``top`` (the block's last index), ``last`` (registered: i == top), its value with a restart
    (``_e``) and its next value (``_n``), ``fresh`` likewise, and the one-hot lowest 0 bit of i + 3."""

    top: int
    last: Signal
    last_e: Value
    last_n: Signal
    fresh_e: Value
    fresh_n: Signal
    lowest_zero_3: Signal


class SobolGenerators(OnChipSource):
    """One randomized W-bit Sobol generator per operator column (twin: ``sources.sobol.SobolTwin``).

    B = ``samples_per_clock`` points per compute cycle: ``numbers[c]`` is the cycle's first, the
    others that XOR :attr:`sample_points` (constants). Shared: the block index ``i`` (counting
    cycles: W - log2(B) bits, a block's 2^W points are 2^W / B cycles) and ``fresh`` (the next
    compute cycle starts a block, 1 after reset). Per column c: a register ``y`` and a shift LFSR.
    With D_c the per-cycle directions (``sources.sobol.clock_directions``, V_c when B = 1)::

        on restart, first: i, fresh = 0, 1       (this cycle is a block's start)
        numbers[c] = fresh ? lfsr_c.number : y_c
        on enable: lfsr_c advances if fresh; y_c = numbers[c] ^ D_c[lowest 0 bit of i];
                   i, fresh = (0, 1) if i == 2^W / B - 1 else (i + 1, 0)

    A restart alone (no compute) makes the next compute cycle a block's first; a restart with
    ``enable`` is itself a block's first compute cycle (the machine's swap when it has no bubble:
    ``BayesianMachine``). The twin's ``clock(False, True)`` then ``clock(True, False)`` is the latter.

    ``last`` (i == 2^W / B - 1), ``penult`` (i == 2^W / B - 2) and each column's direction numbers
    D_c[lowest 0 bit of i], of i + 1 and of i + 2 are registers loaded with the next index's values
    (the same numbers, a shorter path to them: a step shifts the directions down and loads the
    third from i + 3's lowest 0 bit, computed from the index register alone).

    For the machine's prefetched comparators it also gives the next compute cycle's numbers:
    ``next_numbers[c]`` if this cycle is a compute cycle without restart (the block's last cycle
    hands over to the shift LFSR's number, which has not stepped since the block began:
    ``i == 2^W / B - 1 ? lfsr_c.number : numbers[c] ^ D_c[...]``) and ``restart_numbers[c]`` if
    this cycle restarts without computing (a new block: ``lfsr_c.number``);
    ``following_numbers[c]`` is ``next_numbers[c]`` of the next cycle, from this cycle's state,
    ``enable`` and ``restart`` (a register loaded with it every clock equals ``next_numbers``),
    and ``following_restart_numbers[c]`` likewise ``restart_numbers[c]`` of the next cycle (the
    low W bits of the shift LFSR's next state: it steps on ``enable`` when ``fresh``; a register
    loaded with it every clock equals ``restart_numbers``). The machine keeps such registered
    copies per group of rows, since each column's number reaches all the column's comparators.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (``rng = "sobol"``; W, the operator columns, the seed).

    Attributes
    ----------
    enable, restart : ``In(1)``
        See :class:`OnChipSource` and above (``restart`` takes effect before ``enable``'s step).
    fresh : ``Out(1)``
        The register ``fresh``: a compute cycle now (without restart) would start a block (the
        shift LFSR steps at its end).
    numbers, next_numbers, restart_numbers, following_numbers, following_restart_numbers :
        ``Out(unsigned(W)).array(operator_columns)``, see above; operator o reads column o % columns.
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"SobolGenerators takes a MachineParams, not {type(params).__name__}")
        check_params(params)
        self._params = params
        self._specs = tuple(column_lfsr_specs(params))
        cols = params.operator_columns
        super().__init__({
            "enable": In(1),
            "restart": In(1),
            "numbers": Out(unsigned(params.word_bits)).array(params.operator_columns),
            "next_numbers": Out(unsigned(params.word_bits)).array(params.operator_columns),
            "restart_numbers": Out(unsigned(params.word_bits)).array(params.operator_columns),
            "following_numbers": Out(unsigned(params.word_bits)).array(params.operator_columns),
            "following_restart_numbers": Out(unsigned(params.word_bits)).array(params.operator_columns),
            "fresh": Out(1, init=1),
        }, operator_numbers=[o % cols for o in range(params.operators)])

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def specs(self) -> tuple[LFSRSpec, ...]:
        return self._specs

    @property
    def sample_points(self) -> tuple[tuple[int, ...], ...]:
        """Per column, the B points a cycle's numbers are its first (``numbers[c]``) XOR
        (``sources.sobol.sample_points``: the unrandomized Sobol points 0 ... B - 1)."""
        p = self._params
        return tuple(sample_points(c, p.word_bits, p.samples_per_clock) for c in range(p.operator_columns))

    @property
    def swap_points(self) -> tuple[tuple[int, ...], ...]:
        """Per column, the 2B points of a block's first two compute cycles relative to its first
        number (the shift): a run's first and second cycles' numbers are ``restart_numbers[c] ^``
        these (the machine without a bubble compares both in the swap)."""
        p = self._params
        return tuple(sample_points(c, p.word_bits, 2 * p.samples_per_clock)
                     for c in range(p.operator_columns))

    def elaborate(self, platform: object) -> Module:
        m = Module()
        block = self._block_index(m)
        for c, spec in enumerate(self._specs):
            self._column(m, c, spec, block)
        return m

    def _block_index(self, m: Module) -> _BlockIndex:
        """The index in the block (cycles: 2^W / B per block) and its registered functions, loaded
        with their next values, so that the numbers of the next cycle, and of the one after
        (``following_numbers``), are a few LUTs from flip-flops: ``last`` (i == 2^W - 1), ``penult``
        (i == 2^W - 2), ``fresh`` (a block's first cycle) and the one-hot lowest 0 bit of i + 3."""
        samples = self._params.samples_per_clock
        iw = self._params.word_bits - (samples.bit_length() - 1)  # the index counts cycles: 2^W / B per block
        top = (1 << iw) - 1
        index = Signal(iw)
        fresh = self.fresh
        last, penult = Signal(), Signal(init=int(top == 1))
        # A restart takes effect before the cycle's compute step: the cycle's state is that of a
        # block's start (i = 0, fresh), on which ``enable`` then acts as on any other state.
        last_e, penult_e = ~self.restart & last, Mux(self.restart, int(top == 1), penult)
        fresh_e = self.restart | fresh
        # The next index and ``penult`` with the enable and restart entering last: the increment
        # and the compare are made on the index register alone.
        index_n = Signal(iw)
        m.d.comb += index_n.eq(Mux(self.enable, Mux(last_e, 0, Mux(self.restart, 1, index + 1)),
                                   Mux(self.restart, 0, index)))
        penult_n = Mux(self.enable, Mux(last_e, top == 1, Mux(self.restart, top == 2, index == top - 2)),
                       penult_e)
        # The lowest 0 bit of i + 3 (one-hot), for the direction register two steps ahead.
        plus3, plus4 = (index + 3)[:iw], (index + 4)[:iw]
        lowest_zero_3 = Signal(iw)
        m.d.comb += lowest_zero_3.eq(~plus3 & plus4)
        last_n, fresh_n = Signal(), Signal()
        m.d.comb += [
            last_n.eq(Mux(self.enable, ~last_e & penult_e, last_e)),
            fresh_n.eq(Mux(self.enable, last_e, fresh_e)),
        ]
        m.d.sync += [index.eq(index_n), last.eq(last_n), penult.eq(penult_n), fresh.eq(fresh_n)]
        return _BlockIndex(top=top, last=last, last_e=last_e, last_n=last_n, fresh_e=fresh_e, fresh_n=fresh_n,
                           lowest_zero_3=lowest_zero_3)

    def _column(self, m: Module, c: int, spec: LFSRSpec, block: _BlockIndex) -> None:
        """Column c's numbers: its shift LFSR (stepped at a block's start) XOR the Sobol point, the
        point kept in ``y`` and stepped by the direction number of the index's lowest 0 bit. The
        direction numbers of i's, i + 1's and i + 2's lowest 0 bit are registers (0 for 2^W - 1, a
        block's last): a step shifts them down, the third from i + 3's one-hot (off the numbers'
        path); a block's start loads those of 0, 1, 2."""
        w, top, fresh = self._params.word_bits, block.top, self.fresh
        last_e = block.last_e
        state = Signal(spec.length, init=spec.init, name=f"shift_lfsr_{c}")
        y = Signal(w, name=f"sobol_{c}")
        vs = clock_directions(c, w, self._params.samples_per_clock)

        def at(j: int) -> int:  # D of j's lowest 0 bit (0 from the block's end)
            return vs[((~j & (j + 1)).bit_length() - 1)] if j < top else 0

        direction = Signal(w, init=at(0), name=f"direction_{c}")
        direction_succ = Signal(w, init=at(1), name=f"direction_succ_{c}")
        direction_succ2 = Signal(w, init=at(2), name=f"direction_succ2_{c}")
        direction_3 = 0
        for k, v in enumerate(vs):
            direction_3 = direction_3 | Mux(block.lowest_zero_3[k], v, 0)
        direction_e = Mux(self.restart, at(0), direction)
        direction_succ_e = Mux(self.restart, at(1), direction_succ)
        direction_succ2_e = Mux(self.restart, at(2), direction_succ2)
        direction_3_e = Mux(self.restart, at(3), direction_3)
        # The direction of index_n: of 0 after a block's end, of i + 1 after a step.
        direction_n = Signal(w, name=f"direction_n_{c}")
        m.d.comb += direction_n.eq(Mux(self.enable, Mux(last_e, at(0), direction_succ_e), direction_e))
        m.d.sync += [
            direction.eq(direction_n),
            direction_succ.eq(Mux(self.enable, Mux(last_e, at(1), direction_succ2_e), direction_succ_e)),
            direction_succ2.eq(Mux(self.enable, Mux(last_e, at(2), direction_3_e), direction_succ2_e)),
        ]
        m.d.comb += self.numbers[c].eq(Mux(block.fresh_e, state[:w], y))
        # i == 2^W - 1 implies fresh == 0 (fresh is set with i = 0): the LFSR keeps its state.
        m.d.comb += [
            self.next_numbers[c].eq(Mux(block.last, state[:w], Mux(fresh, state[:w], y) ^ direction)),
            self.restart_numbers[c].eq(state[:w]),
        ]
        # The same rules on the next cycle's registers (y, the LFSR, fresh, last, direction).
        y_n = Mux(self.enable, self.numbers[c] ^ direction_e, y)
        state_n = Mux(self.enable & block.fresh_e, lfsr_next_state_expr(state, spec), state)
        m.d.sync += [y.eq(y_n), state.eq(state_n)]
        number_n = Mux(block.fresh_n, state_n[:w], y_n)
        m.d.comb += [
            self.following_numbers[c].eq(Mux(block.last_n, state_n[:w], number_n ^ direction_n)),
            self.following_restart_numbers[c].eq(state_n[:w]),
        ]


def random_source(params: MachineParams, operator_groups: Sequence[int] | None = None) -> OnChipSource | None:
    """The generator component of a machine's on-chip source (None for an off-chip kind).

    ``operator_groups`` (one group index per operator) splits the enable of a source with a
    number per operator (``rng = "lfsr"``) into one bit per group; a shared source keeps one enable."""
    kind = source_kind(params.rng)
    ops, cols = params.operators, params.operator_columns
    if not kind.on_chip:
        return None
    if params.rng == "lfsr":
        return LFSRBank(specs=lfsr_specs(params), enable_groups=operator_groups)
    if params.rng == "lfsr-shared":
        return LFSRBank(specs=column_lfsr_specs(params), operator_numbers=[o % cols for o in range(ops)])
    if params.rng == "sobol":
        return SobolGenerators(params=params)
    raise ParameterError(f"no RTL generator for the on-chip random source {params.rng!r}")
