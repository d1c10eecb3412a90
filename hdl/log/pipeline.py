"""The stall pipeline every log block is: stages of logic between registers, one pixel per clock.

A block is a list of *stage functions*; each builds one stage's logic from the previous stage's
registers (the first from the input stream's payload, the last returns the output payload as one
flat value). After each stage a register bank and its ``valid`` bit; the last bank is the output
(the *head*), and beside it one more bank, the *skid*. The pipeline moves on ``go``, a register
(with a copy per stage: no logic between ``out.ready`` and the thousands of register enables):

    go           = ~skid.valid                       # a register: the skid is empty
    in.ready     = go
    valid[i]    <= valid[i - 1]                      # on go (valid[-1] = in.valid), i < L - 1
    bank[i]     <= stage_i(bank[i - 1])              # on go and valid[i - 1] (a bubble loads nothing)
    arriving     = go & valid[L - 2]                 # a pixel reaches the last stage
    free         = ~head.valid | out.ready           # the head is empty or taken
    head        <= skid if skid.valid else stage_L-1(bank[L - 2])    # when free (and one of them is there)
    skid        <= stage_L-1(bank[L - 2])            # when arriving and (not free, or the skid moves up)

So a pixel taken at clock t is offered at t + ``latency`` (the number of stages) if the output is
not held; a held output keeps its pixel, the next pixel to arrive waits in the skid and the
pipeline stops the clock after (``go`` falls), and resumes the clock after the skid moves up:
nothing is dropped or taken twice, and with ``out.ready`` high one pixel passes per clock. The
data registers have no reset (the ``valid`` bits do).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import reduce
from typing import Any

from amaranth.hdl import Cat, Const, Module, Mux, Shape, Signal, Value
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .rule import LogParams, check_params

__all__ = ["Bank", "LogBlock", "PipelineNets", "Stage", "StallPipeline", "Wire", "fit", "pack",
           "stage_functions", "wires"]

Bank = Any  # a Value, or a list, tuple or dict (str keys) of banks
# ``wire(value, name)`` returns a net equal to ``value`` (a comb-driven Signal in the module that
# builds the stage): a stage names what it reuses, so the netlist and the simulator's code share
# it rather than repeat its expression at each use.
Wire = Callable[[Value, str], Value]
Stage = Callable[[Bank, Wire], Bank]


def wires(m: Module) -> Wire:
    """The ``wire`` of stages built in ``m``."""
    def wire(value: Value, name: str) -> Value:
        value = Value.cast(value)
        net = Signal(value.shape(), name=name)
        m.d.comb += net.eq(value)
        return net
    return wire


def _register(bank: Bank, name: str, out: list) -> Bank:
    """Registers shaped like ``bank``; their loads are appended to ``out``."""
    if isinstance(bank, (list, tuple)):
        return type(bank)(_register(b, f"{name}_{i}", out) for i, b in enumerate(bank))
    if isinstance(bank, dict):  # named registers: ``<stage>_<key>``
        return {k: _register(b, f"{name}_{k}", out) for k, b in bank.items()}
    if isinstance(bank, Const):  # a constant needs no register
        return bank
    value = Value.cast(bank)
    if len(value) == 0:
        return value
    reg = Signal(value.shape(), name=name, reset_less=True)
    out.append(reg.eq(value))
    return reg


def fit(value: Value, width: int) -> Value:
    """``value``'s bits cut or zero-extended to ``width``."""
    value = Value.cast(value)
    return value[:width] if len(value) >= width else Cat(value, Const(0, width - len(value)))


def pack(layout: data.StructLayout, **fields: Value) -> Value:
    """One flat value of ``layout`` from its fields (each zero-extended or cut to its width)."""
    parts, offset = [], 0
    for name, field in layout:
        assert field.offset == offset, "a struct layout's fields follow each other"
        width = Shape.cast(field.shape).width
        parts.append(fit(fields.pop(name), width))
        offset += width
    assert not fields, f"fields not in the layout: {sorted(fields)}"
    return Cat(*parts)


def stage_functions(first: Stage, levels: Sequence[Stage], last: Stage, per_stage: int) -> tuple[Stage, ...]:
    """Stages of ``per_stage`` levels each (the last may have fewer; one stage if there are no
    levels), ``first`` before the first level and ``last`` after the last."""
    groups = [list(levels[i:i + per_stage]) for i in range(0, len(levels), per_stage)] or [[]]
    stages = []
    for j, group in enumerate(groups):
        fns = ([first] if j == 0 else []) + group + ([last] if j == len(groups) - 1 else [])
        stages.append(_compose(fns))
    return tuple(stages)


def _compose(fns: Sequence[Stage]) -> Stage:
    return lambda bank, wire: reduce(lambda b, f: f(b, wire), fns, bank)


@dataclass(frozen=True)
class PipelineNets:
    """A pipeline's registers (``StallPipeline.nets``): per stage i its ``valid[i]`` and register bank
    ``banks[i]`` (the last: the head, the output payload), the skid (``skid_valid``, ``skid``) and
    ``go`` (the copies of one register, one per stage: stage i moves on ``go[i]``)."""

    valid: tuple[Signal, ...]
    banks: tuple[Bank, ...]
    skid_valid: Signal
    skid: Signal
    go: tuple[Signal, ...]


class StallPipeline(wiring.Component):
    """A stream in, a stream out, the stages between (module docstring).

    Parameters
    ----------
    sink, source : str
        The names of the input and the output stream members.
    in_layout, out_layout : data.Layout
        Their payloads.
    stages : sequence of Stage
        The stage functions: the first takes the input payload (a view), the last returns a value
        as wide as ``out_layout``. Each call builds fresh logic (a proof calls them again).

    Attributes
    ----------
    stream_names : tuple of str
        ``(sink, source)``.
    latency : int
        Clocks from a pixel taken to its result offered (the number of stages).
    nets : PipelineNets
        After elaboration: the stage registers, the skid and ``go`` (read-only).
    """

    def __init__(self, *, sink: str, source: str, in_layout: data.Layout, out_layout: data.Layout,
                 stages: Sequence[Stage]) -> None:
        self._sink, self._source = sink, source
        self._stages = tuple(stages)
        self._nets: PipelineNets | None = None
        super().__init__({sink: In(stream.Signature(in_layout)), source: Out(stream.Signature(out_layout))})

    @property
    def stream_names(self) -> tuple[str, str]:
        """The names of the input and the output stream members."""
        return self._sink, self._source

    @property
    def latency(self) -> int:
        return len(self._stages)

    @property
    def nets(self) -> PipelineNets:
        if self._nets is None:
            raise RuntimeError(f"{type(self).__name__}.nets: elaborate it first (Fragment.get)")
        return self._nets

    def remaining(self, m: Module, stage: int, bank: Bank) -> Value:
        """The output payload (flat) the stages after ``stage`` make of its register ``bank``:
        logic built anew in ``m``, for a proof's invariants."""
        wire = wires(m)
        return Value.cast(reduce(lambda b, f: f(b, wire), self._stages[stage + 1:], bank))

    def elaborate(self, platform: object) -> Module:
        m = Module()
        sink, source = getattr(self, self._sink), getattr(self, self._source)
        last = self.latency - 1
        # go, and its copies (init 1: the skid is empty); named *_rep*: the FPGA flow keeps them apart.
        go = tuple(Signal(name=f"go_rep{i}", init=1) for i in range(self.latency))
        m.d.comb += sink.ready.eq(go[0])
        bank, valid = sink.payload, sink.valid
        valids, banks = [], []
        wire = wires(m)
        for i, stage in enumerate(self._stages[:last]):
            loads: list = []
            bank = _register(stage(bank, wire), f"stage{i}", loads)
            with m.If(go[i] & valid):
                m.d.sync += loads
            v = Signal(name=f"stage{i}_valid")
            with m.If(go[i]):
                m.d.sync += v.eq(valid)
            valid = v
            valids.append(v)
            banks.append(bank)
        head, skid_valid, skid = self._head_and_skid(m, self._stages[last](bank, wire), go[last] & valid, go)
        valids.append(source.valid)
        banks.append(head)
        m.d.comb += source.payload.eq(head)
        self._nets = PipelineNets(valid=tuple(valids), banks=tuple(banks), skid_valid=skid_valid, skid=skid,
                                  go=go)
        return m

    def _head_and_skid(self, m: Module, value: Value, arriving: Value, go: tuple[Signal, ...]
                       ) -> tuple[Signal, Signal, Signal]:
        """The last stage: its value arriving into the head or the skid (module docstring)."""
        source = getattr(self, self._source)
        value = Value.cast(value)
        head = Signal(len(value), name=f"stage{self.latency - 1}", reset_less=True)
        skid = Signal(len(value), name="skid", reset_less=True)
        skid_valid = Signal(name="skid_valid")
        free = ~source.valid | source.ready
        with m.If(free):
            m.d.sync += [source.valid.eq(skid_valid | arriving), skid_valid.eq(skid_valid & arriving)]
            with m.If(skid_valid):
                m.d.sync += head.eq(skid)
            with m.Elif(arriving):
                m.d.sync += head.eq(value)
        with m.Else():
            m.d.sync += skid_valid.eq(skid_valid | arriving)
        with m.If(arriving & (skid_valid | ~free)):
            m.d.sync += skid.eq(value)
        skid_next = Mux(free, skid_valid & arriving, skid_valid | arriving)
        m.d.sync += [g.eq(~skid_next) for g in go]
        return head, skid_valid, skid


class LogBlock(StallPipeline):
    """A stall pipeline of the log integrator, built from a :class:`~.rule.LogParams` (``params``,
    checked first, read-only); the other arguments are :class:`StallPipeline`'s."""

    def __init__(self, *, params: LogParams, **pipeline: object) -> None:
        self._params = check_params(params)
        super().__init__(**pipeline)  # type: ignore[arg-type]

    @property
    def params(self) -> LogParams:
        return self._params
