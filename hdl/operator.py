"""The stochastic operator: a comparator against a random number, ANDed into the row's bus.

Operator (r, c) turns its likelihood-memory word q (a probability q / 2**W) into a
stochastic bitstream by comparing a fresh W-bit random number with q each cycle
(``number < q`` is 1 with probability exactly q / 2**W for uniform numbers; q = 0 is never
1 and q = 2**W always is), and multiplies it into the stochastic bus signal of its row by an
AND gate. :func:`stochastic_operator` is that logic; the machine instantiates it for every
operator, so it exists once. :class:`StochasticOperator` wraps it with its LFSR for unit tests
against :func:`stochastic_operator_twin`.
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal, Value, ValueCastable, unsigned
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .rng import LFSRSpec, lfsr_next_state_expr, lfsr_step

__all__ = ["StochasticOperator", "stochastic_operator", "stochastic_operator_twin", "operator_stream"]


def stochastic_operator(bus_in: Value | ValueCastable | int, number: Value, word: Value) -> Value:
    """One operator's output bit: ``bus_in & (number < word)``.

    ``number`` is W bits, ``word`` W + 1 bits, so the comparator covers p = 0 and p = 1 exactly.
    """
    # Amaranth compares unsigned values of different widths by zero-extension: exact.
    return Value.cast(bus_in) & (number < word)


def stochastic_operator_twin(bus_in: int, number: int, word: int) -> int:
    """Python twin of :func:`stochastic_operator`."""
    return int(bool(bus_in) and number < word)


def operator_stream(spec: LFSRSpec, word: int, cycles: int, state: int | None = None) -> list[int]:
    """The output bits of one operator with ``bus_in = 1`` over ``cycles`` compute cycles."""
    s = spec.init if state is None else state
    out = []
    for _ in range(cycles):
        number, s = lfsr_step(s, spec)
        out.append(stochastic_operator_twin(1, number, word))
    return out


class StochasticOperator(wiring.Component):
    """A single operator with its own leap-forward LFSR (for unit tests; the machine inlines it).

    Ports: ``word`` (W + 1 bits, the likelihood-memory word), ``bus_in`` (the stochastic bus
    from the left), ``enable`` (a compute cycle: the LFSR advances), ``number`` (this cycle's
    random number), ``bus_out`` (``bus_in & (number < word)``).
    """

    def __init__(self, spec: LFSRSpec) -> None:
        self._spec = spec
        w = spec.step
        super().__init__({
            "word": In(unsigned(w + 1)),
            "bus_in": In(1),
            "enable": In(1),
            "number": Out(unsigned(w)),
            "bus_out": Out(1),
        })

    @property
    def spec(self) -> LFSRSpec:
        return self._spec

    def elaborate(self, platform: object) -> Module:
        m = Module()
        spec = self._spec
        state = Signal(spec.length, init=spec.init)
        m.d.comb += [
            self.number.eq(state[: spec.step]),
            self.bus_out.eq(stochastic_operator(self.bus_in, self.number, self.word)),
        ]
        with m.If(self.enable):
            m.d.sync += state.eq(lfsr_next_state_expr(state, spec))
        return m
