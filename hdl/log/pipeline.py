"""The stall pipeline every log block is: stages of logic between registers, one pixel per clock.

A block is a list of *stage functions*; each builds one stage's logic from the previous stage's
registers (the first from the input stream's payload, the last returns the output payload as one
flat value). After each stage but the last a register bank and its ``valid`` bit; the last stage
writes a two-entry output buffer, in turn, and the output reads it in turn (the entry offered is
the *head*, the other the *skid*). The pipeline moves on ``go``, a register saying an entry is
free, so ``out.ready`` reaches only a few registers (the read pointer, the entries' valid bits,
``go``), never the thousands of data-register enables; and ``go`` and the read pointer are copied,
one copy per ``ENABLE_GROUP`` register bits (``go_rep*``, ``out_read_rep*``: the FPGA flow keeps
such copies apart), so no enable or select net fans out to more than a group:

    in.ready     = go                                # a register: an entry is (will be) free
    valid[i]    <= valid[i - 1]                      # on go (valid[-1] = in.valid), i < L - 1
    bank[i]     <= stage_i(bank[i - 1])              # on go and valid[i - 1] (a bubble loads nothing)
    arriving     = go & valid[L - 2]                 # a pixel reaches the last stage
    entry[write] <= stage_L-1(bank[L - 2]), write flips      # when arriving
    out.valid, out.payload = entry_valid[read], entry[read]; read flips when taken
    go          <= not both entries valid (after this clock's write and read)

So a pixel taken at clock t is offered at t + ``latency`` (the number of stages) if the output is
not held; a held output keeps its pixel, the next pixel to arrive waits in the other entry and the
pipeline stops the clock after (``go`` falls) until the head is taken: nothing is dropped or taken
twice, and with ``out.ready`` high one pixel passes per clock. The data registers have no reset
(the ``valid`` bits do).

A pipeline may also keep its *latest* result: some fields of the last stage's output, registered
(``latest_copies`` copies, ``latest_rep*``) as each pixel reaches the output buffer, whether or not
it is taken, with ``arriving`` high in that clock. A loop through the pipeline's result (the log
machine's feedback) reads them: in order, the latest is the last pixel's, the clock after it arrived.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import reduce
from typing import Any

from amaranth.hdl import Array, Cat, Const, Module, Mux, Shape, Signal, Value, unsigned
from amaranth.lib import data, memory, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.integrators.log import LogParams, check_params

__all__ = ["ENABLE_GROUP", "LOOKUP_PORTS", "Bank", "LogBlock", "Lookup", "OutputBuffer", "PipelineNets",
           "Stage", "StallPipeline", "Wire", "fit", "latest_layout", "pack", "stage_functions", "wires"]

ENABLE_GROUP = 64  # register bits per copy of the pipeline's enable (and of the read pointer)
LOOKUP_PORTS = 2  # read ports per memory of a Lookup: a block RAM's two
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


@dataclass(frozen=True)
class Lookup:
    """Table reads a stage hands its register bank: the words of ``table`` at each of ``indices`` (each
    index's bits reach no entry past the table), registered as a block RAM's reads (``LOOKUP_PORTS``
    read ports per memory, loaded with the bank's registers), so that a wide table costs no logic.
    The next stage sees the words (a list); only a stage followed by a register bank may return one."""

    table: tuple[int, ...]
    indices: tuple[Value, ...]

    @property
    def bits(self) -> int:
        return max(1, max(self.table).bit_length())

    def words(self) -> list[Value]:
        """The words read in logic (a proof's ``remaining``)."""
        table = Array(Const(w, self.bits) for w in self.table)
        return [table[i] for i in self.indices]


def _resolved(bank: Bank) -> Bank:
    """``bank`` with each :class:`Lookup` read in logic."""
    if isinstance(bank, Lookup):
        return bank.words()
    if isinstance(bank, (list, tuple)):
        return type(bank)(_resolved(b) for b in bank)
    if isinstance(bank, dict):
        return {k: _resolved(b) for k, b in bank.items()}
    return bank


def _register(bank: Bank, name: str, out: list, lookups: list) -> Bank:
    """Registers shaped like ``bank``; ``(register, value)`` of each is appended to ``out``, and
    ``(lookup, words)`` of each :class:`Lookup` to ``lookups`` (``words``: the signals its reads drive)."""
    if isinstance(bank, Lookup):
        words = [Signal(bank.bits, name=f"{name}_{k}") for k in range(len(bank.indices))]
        lookups.append((bank, words))
        return words
    if isinstance(bank, (list, tuple)):
        return type(bank)(_register(b, f"{name}_{i}", out, lookups) for i, b in enumerate(bank))
    if isinstance(bank, dict):  # named registers: ``<stage>_<key>``
        return {k: _register(b, f"{name}_{k}", out, lookups) for k, b in bank.items()}
    if isinstance(bank, Const):  # a constant needs no register
        return bank
    value = Value.cast(bank)
    if len(value) == 0:
        return value
    reg = Signal(value.shape(), name=name, reset_less=True)
    out.append((reg, value))
    return reg


def _read(m: Module, lookup: Lookup, words: list[Signal], en: Value, name: str) -> None:
    """``lookup``'s reads into ``words``, loaded on ``en``: a read-only memory (block RAM) per
    ``LOOKUP_PORTS`` indices."""
    for k, index in enumerate(lookup.indices):
        if k % LOOKUP_PORTS == 0:
            mem = memory.Memory(shape=unsigned(lookup.bits), depth=len(lookup.table), init=lookup.table,
                                attrs={"rom_style": "block"})
            m.submodules[f"{name}_{k // LOOKUP_PORTS}"] = mem
        port = mem.read_port()
        m.d.comb += [port.en.eq(en), port.addr.eq(index), words[k].eq(port.data)]


def _groups(pairs: Sequence[tuple[Value, Value]], bits: int) -> list[list[tuple[Value, Value]]]:
    """``(register, value)`` pairs cut into slices and grouped, at most ``bits`` register bits a
    group: each group's enable is a register copy of its own (no enable net fans out further)."""
    groups: list[list[tuple[Value, Value]]] = [[]]
    used = 0
    for reg, value in pairs:
        value = Value.cast(value)
        for lo in range(0, len(reg), bits):
            width = min(bits, len(reg) - lo)
            if used + width > bits:
                groups.append([])
                used = 0
            groups[-1].append((reg[lo:lo + width], fit(value.as_unsigned(), len(reg))[lo:lo + width]))
            used += width
    return [g for g in groups if g]


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
class OutputBuffer:
    """The last stage's two entries (``entries``, ``entry_valid``) and pointers: ``reads`` (copies of
    one register, the first for the control) the entry offered, ``write`` the entry the next
    arriving pixel goes to; ``head`` and ``skid`` the entry offered and the other, ``skid_valid``
    the other's valid bit."""

    entries: tuple[Signal, Signal]
    entry_valid: tuple[Signal, Signal]
    reads: tuple[Signal, ...]
    write: Signal
    head: Value
    skid: Value
    skid_valid: Value


@dataclass(frozen=True)
class PipelineNets:
    """A pipeline's registers (what ``StallPipeline.build`` returns beside its module): per stage i its
    ``valid[i]`` and register bank ``banks[i]`` (the last: the head, the entry offered), the skid
    (``skid_valid``, ``skid``: the other entry), ``go`` (the copies of one register, one per stage: stage i
    moves on ``go[i]``) and
    the ``output`` buffer's registers."""

    valid: tuple[Value, ...]
    banks: tuple[Bank, ...]
    skid_valid: Value
    skid: Value
    go: tuple[Signal, ...]
    output: OutputBuffer


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
    latest_fields : sequence of str
        Fields of ``out_layout`` (a struct layout) the latest result keeps (none: no latest result).
    latest_copies : int
        Register copies of the latest result (1 ... 64; with ``latest_fields``).

    Attributes
    ----------
    stream_names : tuple of str
        ``(sink, source)``.
    latency : int
        Clocks from a pixel taken to its result offered (the number of stages).
    latest : ``Out(ArrayLayout(latest_layout, latest_copies))``
        With ``latest_fields``: the copies of the latest result (``latest_layout``: those fields);
        every field 0 but ``all_excluded`` (1, when it is kept) from reset.
    arriving : ``Out(1)``
        With ``latest_fields``: a pixel reaches the output buffer this clock.
    """

    def __init__(self, *, sink: str, source: str, in_layout: data.Layout, out_layout: data.Layout,
                 stages: Sequence[Stage], latest_fields: Sequence[str] = (), latest_copies: int = 1) -> None:
        self._sink, self._source = sink, source
        self._stages = tuple(stages)
        members = {sink: In(stream.Signature(in_layout)), source: Out(stream.Signature(out_layout))}
        self._latest = latest_layout(out_layout, latest_fields) if latest_fields else None
        self._latest_n = as_int("latest_copies", latest_copies, 1, 64)
        if self._latest is not None:
            members["latest"] = Out(data.ArrayLayout(self._latest, latest_copies))
            members["arriving"] = Out(1)
        super().__init__(members)

    @property
    def stream_names(self) -> tuple[str, str]:
        """The names of the input and the output stream members."""
        return self._sink, self._source

    @property
    def latency(self) -> int:
        return len(self._stages)

    def remaining(self, m: Module, stage: int, bank: Bank) -> Value:
        """The output payload (flat) the stages after ``stage`` make of its register ``bank``:
        logic built anew in ``m``, for a proof's invariants."""
        wire = wires(m)
        return Value.cast(reduce(lambda b, f: f(_resolved(b), wire), self._stages[stage + 1:], bank))

    def elaborate(self, platform: object) -> Module:
        return self.build(platform)[0]

    def build(self, platform: object) -> tuple[Module, PipelineNets]:
        """The pipeline's module (what :meth:`elaborate` gives) and its registers, which a proof's
        invariants read (a mutant changes them)."""
        m = Module()
        sink, source = getattr(self, self._sink), getattr(self, self._source)
        last = self.latency - 1
        # go and its copies (init 1: the output buffer is empty), one per group of ENABLE_GROUP
        # register bits; named *_rep*: the FPGA flow keeps them apart.
        go = [Signal(name="go_rep_in", init=1), Signal(name="go_rep_ctl", init=1)]
        m.d.comb += sink.ready.eq(go[0])
        bank, valid = sink.payload, sink.valid
        valids, banks = [], []
        wire = wires(m)
        for i, stage in enumerate(self._stages[:last]):
            pairs: list = []
            lookups: list = []
            bank = _register(stage(bank, wire), f"stage{i}", pairs, lookups)
            for j, group in enumerate(_groups(pairs, ENABLE_GROUP)):
                go.append(Signal(name=f"go_rep{i}_{j}", init=1))
                with m.If(go[-1] & valid):
                    m.d.sync += [reg.eq(value) for reg, value in group]
            for j, (lookup, words) in enumerate(lookups):
                # Not a kept *_rep* copy: a table whose reads nothing uses is removed with its copy.
                go.append(Signal(name=f"go_table{i}_{j}", init=1))
                _read(m, lookup, words, go[-1] & valid, f"stage{i}_table{j}")
            v = Signal(name=f"stage{i}_valid")
            with m.If(go[1]):
                m.d.sync += v.eq(valid)
            valid = v
            valids.append(v)
            banks.append(bank)
        value = Value.cast(self._stages[last](bank, wire))
        buf = self._output_buffer(m, value, valid, go)
        valids.append(source.valid)
        banks.append(buf.head)
        return m, PipelineNets(valid=tuple(valids), banks=tuple(banks), skid_valid=buf.skid_valid,
                               skid=buf.skid, go=tuple(go), output=buf)

    def _output_buffer(self, m: Module, value: Value, valid: Value, go: list[Signal]) -> OutputBuffer:
        """The last stage's two entries, written in turn and read in turn (module docstring), by
        groups of ENABLE_GROUP bits, each group with its own copies of ``go`` and of the read pointer."""
        source = getattr(self, self._source)
        e0, e1 = (Signal(len(value), name=f"out{k}", reset_less=True) for k in range(2))
        v0, v1 = (Signal(name=f"out{k}_valid") for k in range(2))
        write = Signal(name="out_write")
        reads, head, skid = [Signal(name="out_read_rep")], [], []
        arriving = go[1] & valid
        taken = source.valid & source.ready
        for j, lo in enumerate(range(0, len(value), ENABLE_GROUP)):
            part = slice(lo, min(lo + ENABLE_GROUP, len(value)))
            go.append(Signal(name=f"go_rep_out{j}", init=1))
            reads.append(Signal(name=f"out_read_rep{j}"))
            with m.If(go[-1] & valid):
                with m.If(write):
                    m.d.sync += e1[part].eq(value[part])
                with m.Else():
                    m.d.sync += e0[part].eq(value[part])
            head.append(Mux(reads[-1], e1[part], e0[part]))
            skid.append(Mux(reads[-1], e0[part], e1[part]))
        read = reads[0]
        m.d.comb += [source.valid.eq(Mux(read, v1, v0)), source.payload.eq(Cat(*head))]
        with m.If(taken):
            m.d.sync += [r.eq(~r) for r in reads]
        with m.If(arriving):
            m.d.sync += write.eq(~write)
        if self._latest is not None:
            self._keep_latest(m, value, arriving)
        nexts = []
        for k, v in enumerate((v0, v1)):
            nxt = (v & ~(taken & (read == k))) | (arriving & (write == k))
            m.d.sync += v.eq(nxt)
            nexts.append(nxt)
        m.d.sync += [g.eq(~(nexts[0] & nexts[1])) for g in go]  # go: an entry is free
        return OutputBuffer(entries=(e0, e1), entry_valid=(v0, v1), reads=tuple(reads), write=write,
                            head=Cat(*head), skid=Cat(*skid), skid_valid=Mux(read, v0, v1))

    def _keep_latest(self, m: Module, value: Value, arriving: Value) -> None:
        """The latest result's copies, each its own register (``latest_rep*``: the FPGA flow keeps them)."""
        source = getattr(self, self._source)
        got = source.payload.shape()(value)
        init = {"all_excluded": 1} if "all_excluded" in self._latest.members else {}
        m.d.comb += self.arriving.eq(arriving)
        for k in range(self._latest_n):
            reg = Signal(self._latest, name=f"latest_rep{k}", init=init)
            with m.If(arriving):
                m.d.sync += [getattr(reg, f).eq(getattr(got, f)) for f in self._latest.members]
            m.d.comb += self.latest[k].eq(reg)


def latest_layout(layout: data.StructLayout, fields: Sequence[str]) -> data.StructLayout:
    """The fields ``fields`` of ``layout`` (a pipeline's latest result)."""
    if not isinstance(layout, data.StructLayout) or not set(fields) <= set(layout.members):
        raise ValueError(f"latest_fields must be fields of the output layout, not {list(fields)}")
    return data.StructLayout({f: layout.members[f] for f in fields})


class LogBlock(StallPipeline):
    """A stall pipeline of the log integrator, built from a :class:`~.rule.LogParams` (``params``,
    checked first, read-only); the other arguments are :class:`StallPipeline`'s."""

    def __init__(self, *, params: LogParams, **pipeline: object) -> None:
        self._params = check_params(params)
        super().__init__(**pipeline)  # type: ignore[arg-type]

    @property
    def params(self) -> LogParams:
        return self._params
