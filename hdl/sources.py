"""RTL of the on-chip random sources: one generator component per kind, the machine's submodule.

Each on-chip kind of ``bayesmachine.sources.SOURCE_KINDS`` has one component here, built from
the pure-Python definitions in ``bayesmachine.sources`` (the same ones the model's kernels use):

- ``lfsr``: :class:`LFSRBank` of one leap-forward LFSR per operator;
- ``lfsr-shared``: :class:`LFSRBank` of one LFSR per operator column, every row of a column
  reading its column's number;
- ``sobol``: :class:`SobolGenerators`, one Sobol generator per operator column sharing a block
  index counter, each with a shift LFSR.

Every generator has ``enable`` (a compute cycle: the source advances) and ``numbers``, a
list of this cycle's W-bit numbers (separate signals: Amaranth's simulator updates them far
faster than slices of one wide signal). ``LFSRBank`` exposes its LFSR registers themselves as
ports ``state_<i>`` (``numbers[i]`` is the W low bits of ``state_<i>``): a copy of 246 numbers
into an output port would cost the full machine's simulation a quarter of its speed.
``SobolGenerators`` also has ``restart`` (a pixel's run starts). :func:`random_source` builds
the component of a machine and says which number each operator reads. The unit tests (``tests/test_rng.py``,
``tests/test_sobol.py``) drive the very components the machine instantiates.
"""

from __future__ import annotations

from collections.abc import Sequence

from amaranth.hdl import Cat, Module, Mux, Signal, Value, unsigned
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources import source_kind
from bayesmachine.sources.lfsr import LFSRSpec, column_lfsr_specs, lfsr_specs
from bayesmachine.sources.sobol import check_params, direction_numbers

__all__ = ["LFSRBank", "SobolGenerators", "lfsr_next_state_expr", "random_source"]


def lfsr_next_state_expr(state: Value, spec: LFSRSpec) -> Value:
    """The leap-forward next-state expression (the RTL form of ``sources.lfsr.lfsr_step``)."""
    w, length = spec.step, spec.length
    new = state[0:w]
    for t in spec.taps:
        if t:
            new = new ^ state[t : t + w]
    return Cat(state[w:length], new)


class LFSRBank(wiring.Component):
    """Leap-forward LFSRs, one per spec: port ``state_<i>`` is LFSR i's register (L bits, reset to
    the spec's start state) and ``numbers[i]`` its W oldest bits, this cycle's number.

    All LFSRs advance W bits on each clock where ``enable`` is high (compute cycles only).
    """

    def __init__(self, specs: Sequence[LFSRSpec]) -> None:
        specs = tuple(specs)
        if not specs or any(not isinstance(s, LFSRSpec) for s in specs):
            raise ParameterError("specs must be a non-empty sequence of LFSRSpec")
        if len({s.step for s in specs}) != 1:
            raise ParameterError("specs must all deliver the same number of bits per clock (step)")
        self._specs = specs
        members = {"enable": In(1)}
        for i, spec in enumerate(specs):
            members[f"state_{i}"] = Out(unsigned(spec.length), init=spec.init)
        super().__init__(members)

    @property
    def numbers(self) -> list[Value]:
        return [getattr(self, f"state_{i}")[: s.step] for i, s in enumerate(self._specs)]

    @property
    def specs(self) -> tuple[LFSRSpec, ...]:
        return self._specs

    def elaborate(self, platform: object) -> Module:
        m = Module()
        for i, spec in enumerate(self._specs):
            state = getattr(self, f"state_{i}")
            with m.If(self.enable):
                m.d.sync += state.eq(lfsr_next_state_expr(state, spec))
        return m


class SobolGenerators(wiring.Component):
    """One randomized W-bit Sobol generator per operator column (twin: ``sources.sobol.SobolTwin``).

    Shared: the block index ``i`` (W bits) and ``fresh`` (the next compute cycle starts a block,
    1 after reset). Per column c: a register ``y`` and a shift LFSR. Per cycle::

        numbers[c] = fresh ? lfsr_c.number : y_c
        on enable: lfsr_c advances if fresh; y_c = numbers[c] ^ V_c[lowest 0 bit of i];
                   i, fresh = (0, 1) if i == 2^W - 1 else (i + 1, 0)
        on restart (wins over enable for i and fresh): i, fresh = 0, 1
    """

    def __init__(self, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"SobolGenerators takes a MachineParams, not {type(params).__name__}")
        check_params(params)
        self._params = params
        self._specs = tuple(column_lfsr_specs(params))
        super().__init__({
            "enable": In(1),
            "restart": In(1),
            "numbers": Out(unsigned(params.word_bits)).array(params.operator_columns),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def specs(self) -> tuple[LFSRSpec, ...]:
        return self._specs

    def elaborate(self, platform: object) -> Module:
        m = Module()
        w = self._params.word_bits
        index = Signal(w)
        fresh = Signal(init=1)
        # One-hot of the index's lowest 0 bit (all zeros when i = 2^W - 1, the block's last cycle).
        lowest_zero = Signal(w)
        m.d.comb += lowest_zero.eq(~index & (index + 1)[:w])
        for c, spec in enumerate(self._specs):
            state = Signal(spec.length, init=spec.init, name=f"shift_lfsr_{c}")
            y = Signal(w, name=f"sobol_{c}")
            number = Mux(fresh, state[:w], y)
            m.d.comb += self.numbers[c].eq(number)
            direction = 0
            for k, v in enumerate(direction_numbers(c, w)):
                direction = direction | Mux(lowest_zero[k], v, 0)
            with m.If(self.enable):
                m.d.sync += y.eq(self.numbers[c] ^ direction)
                with m.If(fresh):
                    m.d.sync += state.eq(lfsr_next_state_expr(state, spec))
        with m.If(self.enable):
            with m.If(index == (1 << w) - 1):
                m.d.sync += [index.eq(0), fresh.eq(1)]
            with m.Else():
                m.d.sync += [index.eq(index + 1), fresh.eq(0)]
        with m.If(self.restart):
            m.d.sync += [index.eq(0), fresh.eq(1)]
        return m


def random_source(params: MachineParams) -> tuple[wiring.Component | None, list[int]]:
    """The generator component of a machine's on-chip source (None for an off-chip kind) and,
    per operator, the index of the ``numbers`` entry it compares against."""
    kind = source_kind(params.rng)
    ops, cols = params.operators, params.operator_columns
    if not kind.on_chip:
        return None, list(range(ops))
    if params.rng == "lfsr":
        return LFSRBank(lfsr_specs(params)), list(range(ops))
    if params.rng == "lfsr-shared":
        return LFSRBank(column_lfsr_specs(params)), [o % cols for o in range(ops)]
    if params.rng == "sobol":
        return SobolGenerators(params), [o % cols for o in range(ops)]
    raise ParameterError(f"no RTL generator for the on-chip random source {params.rng!r}")
