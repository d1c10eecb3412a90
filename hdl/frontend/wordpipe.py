"""The word generator's shared pipeline (:class:`WordPipeline`), on which every column kind's lane builder
(:mod:`.lanes`) builds its lanes, for one elaboration of a
:class:`~bayesmachine.hdl.frontend.words.WordGenerator`; the lane builders see it as a
:class:`~.lanes.context.LaneContext`.

One beat per cycle, in a four-step pipeline that stalls as a whole while the stream does: in the cycle
of the beat's issue each lane's cost (a difference, a Hamming distance, row minus the MAP above) goes
into a register; its absolute value, clamped, into the address register in the next; the look-up
(block RAM read) in the next; the beat on the stream the one after. The registers keep the subtraction
(on the reference features' wide fan-out), the absolute value and clamp, and the long route to the
block RAM apart. The cost's operands are registers: the reference features, and per lane the
delay-line entry of the beat (:class:`~.delayline.DelayLine`), chosen a cycle ahead (beat 0's when the
pixel is taken, the next beat's at each issue), so no path runs from the beat counter through the entry
multiplexer into a table address. A pass that scans its pixels' beats before their words keeps its
pixels in a ring (:class:`~.scan.ScanRing`). :func:`word_pipeline` builds it.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from amaranth.hdl import Const, Module, Signal, Value, ValueLike, unsigned
from amaranth.lib import data, memory, stream, wiring

from bayesmachine.hdl.signatures import beat_words
from bayesmachine.models import Pass
from bayesmachine.params import MachineParams

from .delayline import DelayLine
from .lookup import BLOCK_TABLE_DEPTH, COST_BITS, TABLE_READ_PORTS, clamped_magnitude, table_depth
from .reference import Reference
from .scan import ScanRing
from .shared import FusedShare
from .tables import FrontEndTables, LoadForm, padded_table

__all__ = ["Generator", "WordPipeline", "word_pipeline"]


class Generator(Protocol):
    """What the pipeline reads of its word generator (:class:`~.words.WordGenerator`): its arguments, its
    pixel and beat streams, and by name the ports its lane builders declared."""

    @property
    def params(self) -> MachineParams: ...
    @property
    def pass_(self) -> Pass: ...
    @property
    def reference(self) -> Reference: ...
    @property
    def tables(self) -> FrontEndTables: ...
    @property
    def output_columns(self) -> int | None: ...
    @property
    def leads(self) -> bool: ...
    @property
    def fused_share(self) -> FusedShare | None: ...
    @property
    def pixel(self) -> stream.Interface: ...
    @property
    def beats(self) -> stream.Interface: ...


def word_pipeline(m: Module, gen: Generator, scan_latency: int = 0) -> WordPipeline:
    """The shared pipeline of ``gen``'s elaboration into ``m``, built (its beat counter and stages, the
    delay line, a pass that scans its ring); the lanes are built on it after (their tables, entries and
    registers, :class:`WordPipeline`'s methods), then :meth:`WordPipeline.accept` and
    :meth:`WordPipeline.write_beats`."""
    pipe = WordPipeline(m, gen, scan_latency)
    pipe._build()
    return pipe


class WordPipeline:
    """The word generator's shared pipeline (module text), implementing
    :class:`~.lanes.context.LaneContext`: its properties and methods are the lanes' view.

    One beat per cycle, in four steps that stall together with the stream (``advance``): the beat's
    issue (``issue``, beat number ``beat``: each lane's cost into a register, :meth:`address`), the
    cost's clamped absolute value into the address register, the table read (:meth:`lookup`), the beat
    on the stream (:meth:`aligned` carries a value of the issue's cycle along). ``take``: the lanes take
    a pixel (``pixel``); ``fed_take``: the stream's pixel (``fed``) is taken, the same but in a pass that
    scans (:class:`~.scan.ScanRing`); ``left``: its reference features; :meth:`entry`: a lane's match
    features. Built by :func:`word_pipeline`; ``active``, ``issue`` and ``free`` are read by the
    generator (and a mutant of ``hdl.formal``).
    """

    def __init__(self, m: Module, gen: Generator, scan_latency: int) -> None:
        p = gen.params
        self._m, self._gen, self._params = m, gen, p
        self._dmax = gen.pass_.model.dmax
        self._rows = p.words_per_beat // p.loaded_columns
        self._n_beats = p.beats_per_pixel
        self._form = LoadForm.of(p)
        self._scan_latency = scan_latency
        self._take = Signal(name="take")
        # the look-up pipeline (address registers, table reads, stream) moves
        self._advance = Signal(name="advance")
        self._issue = Signal(name="issue")
        self._beat = Signal(range(max(2, self._n_beats)), name="beat")
        self._left = Signal(gen.pixel.payload.left.shape(), name="left", reset_less=True)
        # The pixel stream's payload: the delay line's, the reference features', a scan's.
        self._fed = gen.pixel.payload
        self._last_issue = Signal()  # the issue of an output pixel's last beat
        self._may_take: Value = Const(1, 1)  # lane builders' conditions on a scan's take (hold_scan)
        self._taken: dict[str, Signal] = {}

    def _build(self) -> None:
        ring = None
        if self._scan_latency:
            ring = self._ring = ScanRing(self._m, self._fed, self._take, self._last_issue, self._n_beats,
                                         self._scan_latency)
            ring.build_queue()
            self._fed_take, self._pixel = ring.fed_take, ring.pixel
        else:
            self._fed_take, self._pixel = self._take, self._fed
        self._pipeline()
        if ring is not None:
            ring.build_scan()
            self._fetch, self._fetch_beat = ring.fetch, ring.fetch_beat
        else:  # the delay line's entries step with the words' issues
            self._fetch, self._fetch_beat = self._issue, self._beat
        self._free = ~self._active | self._last_issue
        self._line = DelayLine(self._m, fed=self._fed, fed_take=self._fed_take, fetch=self._fetch,
                               fetch_beat=self._fetch_beat, reference=self._gen.reference, dmax=self._dmax,
                               rows_per_beat=self._rows, n_beats=self._n_beats, scans=bool(ring))
        self._line.build()

    # --- PassShape ---
    @property
    def m(self) -> Module:
        return self._m

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def pass_(self) -> Pass:
        return self._gen.pass_

    @property
    def reference(self) -> Reference:
        return self._gen.reference

    @property
    def tables(self) -> FrontEndTables:
        return self._gen.tables

    @property
    def form(self) -> LoadForm:
        return self._form

    @property
    def dmax(self) -> int:
        return self._dmax

    @property
    def rows_per_beat(self) -> int:
        return self._rows

    @property
    def n_beats(self) -> int:
        return self._n_beats

    @property
    def one(self) -> int:
        return self._form.one

    @property
    def zero(self) -> int:
        return self._form.zero

    # --- PixelTake ---
    @property
    def pixel(self) -> data.View:
        return self._pixel

    @property
    def take(self) -> Value:
        return self._take

    @property
    def left(self) -> Signal:
        return self._left

    def taken(self, field: str) -> Signal:
        if field not in self._taken:
            self._taken[field] = self.at_take(getattr(self._pixel, field), field)
        return self._taken[field]

    def entry(self, plane: str, j: int) -> Signal:
        return self._line.entry(plane, j)

    # --- BeatIssue ---
    @property
    def beats(self) -> data.View:
        return self._gen.beats.payload

    @property
    def beat(self) -> Signal:
        return self._beat

    @property
    def advance(self) -> Value:
        return self._advance

    @property
    def issue(self) -> Value:
        """A beat is issued this cycle."""
        return self._issue

    @property
    def active(self) -> Signal:
        """Writing the words of an output pixel (``beat`` counts its beats)."""
        return self._active

    @property
    def free(self) -> Value:
        """The lanes may take a pixel (no output pixel being written, or its last beat's issue)."""
        return self._free

    # --- PixelScan ---
    @property
    def fed(self) -> data.View:
        return self._fed

    @property
    def fed_take(self) -> Value:
        return self._fed_take

    @property
    def scan_pixel(self) -> Signal:
        return self._scanning().scan_pixel

    @property
    def fetch(self) -> Value:
        return self._fetch

    @property
    def fetch_beat(self) -> Signal:
        return self._fetch_beat

    @property
    def fetch_slot(self) -> Signal:
        return self._scanning().fetch_slot

    @property
    def slots(self) -> int:
        return self._scanning().slots

    @property
    def take_slot(self) -> Signal:
        return self._scanning().take_slot

    @property
    def issue_slot(self) -> Signal:
        return self._scanning().issue_slot

    def _scanning(self) -> ScanRing:
        if not self._scan_latency:
            raise ValueError("only a pass that scans has a ring of pixels (Lanes.scan_latency)")
        return self._ring

    def hold_scan(self, may: Value) -> None:
        """In a pass that scans: an output pixel is taken from the stream (its scan starts) only while
        ``may`` too (a lane builder's condition: the shared fused sums', :mod:`.shared`)."""
        if not self._scan_latency:
            raise ValueError("hold_scan: only a pass that scans takes its pixels for a scan")
        self._may_take = self._may_take & may

    # --- GeneratorPorts ---
    @property
    def output_columns(self) -> int | None:
        return self._gen.output_columns

    @property
    def leads(self) -> bool:
        return self._gen.leads

    @property
    def fused_share(self) -> FusedShare | None:
        return self._gen.fused_share

    def map_stream(self, name: str) -> stream.Interface:
        return getattr(self._gen, name)

    def signal_port(self, name: str) -> Signal:
        return getattr(self._gen, name)

    def shared_port(self, name: str) -> wiring.PureInterface:
        return getattr(self._gen, name)

    # --- The generator's ---
    def accept(self, ready: Value) -> Value:
        """The pixel stream's ``ready``, given ``ready``: the lanes may take a pixel (``free`` and each
        lane builder's ``ready``); in a pass that scans it drives ``take``, and the stream's ready is that
        of the ring (a free slot) and of the scan (idle, or fetching a pixel's last beat). At two beats or
        more per pixel, not for an output pixel while the previous pixel's delay-line write is pending
        (``DelayLine.shift_q``), so that its entries read no pending write; in a pass that scans, not for
        an output pixel while a lane builder holds the scans (:meth:`hold_scan`)."""
        # No output pixel taken while a write is pending (DelayLine), but at one beat per pixel.
        line = self._line
        settled = ~(line.shift_q & self._fed.output) if line.pending_at_take is None else Const(1, 1)
        if not self._scan_latency:
            return ready & settled
        ring = self._ring.ready(ready)
        held = ~self._fed.output | self._may_take
        return ring & settled & held

    def _pipeline(self) -> None:
        """The beat counter and the valid flags of the four steps."""
        m, n_beats = self._m, self._n_beats
        out = self._gen.beats
        active = Signal()  # writing the words of an output pixel
        self._active = active
        beat_d = Signal(range(max(2, n_beats)))  # the beat in the cost registers
        diff_valid = Signal()
        beat_a = Signal(range(max(2, n_beats)))  # the beat in the address registers
        addr_valid = Signal()
        self._beat_q = Signal(range(max(2, n_beats)), name="beat_q")  # the beat on the stream
        m.d.comb += [self._advance.eq(~out.valid | out.ready), self._issue.eq(active & self._advance),
                     self._fed_take.eq(self._gen.pixel.valid & self._gen.pixel.ready)]
        last = self._beat == n_beats - 1
        m.d.comb += self._last_issue.eq(self._issue & last)
        with m.If(self._advance):
            m.d.sync += [diff_valid.eq(self._issue), beat_d.eq(self._beat), addr_valid.eq(diff_valid),
                         beat_a.eq(beat_d), out.valid.eq(addr_valid), self._beat_q.eq(beat_a)]
        with m.If(self._issue):
            with m.If(last):
                m.d.sync += [self._beat.eq(0), active.eq(0)]
            with m.Else():
                m.d.sync += self._beat.eq(self._beat + 1)
        with m.If(self._fed_take):
            m.d.sync += self._left.eq(self._fed.left)
            if not self._scan_latency:
                with m.If(self._pixel.output):
                    m.d.sync += [active.eq(1), self._beat.eq(0)]
        if self._scan_latency:  # the lanes take the scanned pixel (_queue)
            with m.If(self._take & self._pixel.output):
                m.d.sync += [active.eq(1), self._beat.eq(0)]

    def row(self, j: int) -> Value:
        """The row of lane row j of the beat being issued."""
        return self._beat * self._rows + j

    def at_take(self, value: Value, name: str) -> Signal:
        """``value`` of the pixel taken (registered at the take)."""
        reg = Signal.like(value, name=name)
        with self._m.If(self._take):
            self._m.d.sync += reg.eq(value)
        return reg

    def aligned(self, value: Value, name: str) -> Signal:
        """``value`` of the issue's cycle, with its beat on the stream (the three steps' registers)."""
        stages = [Signal.like(Value.cast(value), name=f"{name}_{s}") for s in "daq"]
        with self._m.If(self._advance):
            self._m.d.sync += [stages[0].eq(value), stages[1].eq(stages[0]), stages[2].eq(stages[1])]
        return stages[2]

    def address(self, value: Value, depth: int, name: str, en: Value | None = None) -> Signal:
        """The table address of a lane's cost ``value`` (of the issue's cycle): its absolute value clamped
        to ``depth - 1`` (:func:`clamped_magnitude`), a cycle later (the cost in a register of its own
        shape, then the address in one); the registers load while ``en`` (default ``advance``: a scan's,
        every cycle). A cost of an unsigned shape (a Hamming distance, a sum above its least) is its
        own absolute value."""
        shape = Value.cast(value).shape()
        if shape.width > COST_BITS:
            raise ValueError(f"{name}: a cost of {shape} does not fit the {COST_BITS}-bit register")
        cost = Signal(shape, name=f"diff_{name}", reset_less=True)  # guarded by the pipeline's valid
        reg = Signal(range(depth), name=f"addr_{name}", reset_less=True)  # guarded by the pipeline's valid
        with self._m.If(self._advance if en is None else en):
            self._m.d.sync += [cost.eq(value), reg.eq(clamped_magnitude(cost, depth - 1))]
        return reg

    def table(self, name: str, words: np.ndarray, bits: int | None = None) -> memory.Memory:
        """A read-only table of W + 1-bit words (or of ``bits``-bit values: energy codes), submodule
        ``table_{name}`` (a copy's name, :meth:`lookup`): in block RAM when deeper than
        :data:`BLOCK_TABLE_DEPTH` (Yosys would otherwise build each read port's multiplexer tree over
        every entry before mapping it to logic); padded with its last word to :func:`table_depth`."""
        width = self._table_width(bits)
        init = [int(w) for w in padded_table(np.asarray(words), table_depth(len(words), width))]
        attrs = {"rom_style": "block"} if len(init) > BLOCK_TABLE_DEPTH else None
        mem = memory.Memory(shape=unsigned(width), depth=len(init), init=init, attrs=attrs)
        self._m.submodules[f"table_{name}"] = mem
        return mem

    def lookup(self, name: str, words: np.ndarray, costs: list[Value], en: Value | None = None,
               bits: int | None = None) -> list[Value]:
        """The words of a table ``words`` (``bits``: :meth:`table`) at each lane row's cost ``costs[j]``,
        with the beat on the stream (one read port per lane row, ``TABLE_READ_PORTS`` per copy of the table:
        ``table_{name}``, ``table_{name}_1``, ...); ``en``: :meth:`address` (the words three
        cycles after the cost). A table whose every word is its index (the log machine's way back from a
        fused sum) is its clamped address, registered as a read would be: no memory."""
        if np.array_equal(np.asarray(words), np.arange(len(words))):
            return [self._identity(name, j, cost, len(words), en, bits) for j, cost in enumerate(costs)]
        out = []
        for j, cost in enumerate(costs):
            if j % TABLE_READ_PORTS == 0:
                mem = self.table(name if j == 0 else f"{name}_{j // TABLE_READ_PORTS}", words, bits)
            port = mem.read_port()
            addr = self.address(cost, mem.depth, f"{name}_{j}", en)
            self._m.d.comb += [port.en.eq(self._advance if en is None else en), port.addr.eq(addr)]
            out.append(port.data)
        return out

    def _table_width(self, bits: int | None) -> int:
        """A table's word width: W + 1 (a word), or ``bits`` (energy codes)."""
        return self._params.memory_word_width if bits is None else bits

    def _identity(self, name: str, j: int, cost: Value, depth: int, en: Value | None,
                  bits: int | None) -> Signal:
        """Lane row j's read of an identity table of ``depth`` words: its address, a cycle later."""
        addr = self.address(cost, depth, f"{name}_{j}", en)
        # As a read port's data: loaded on the read's enable, no reset.
        data = Signal(unsigned(self._table_width(bits)), name=f"read_{name}_{j}", reset_less=True)
        with self._m.If(self._advance if en is None else en):
            self._m.d.sync += data.eq(addr)
        return data

    def write_beats(self, columns: list[tuple[list[ValueLike], ValueLike]]) -> None:
        """The beat on the stream: lane L's word by its (row, operator column) from ``columns`` (each
        loaded column's words of lane rows 0..R-1 and its no-match word); 0 past the last row."""
        m, dmax, rows = self._m, self._dmax, self._rows
        lc = len(columns)
        words = beat_words(self._params, self._gen.beats.payload)
        unused = range(self._n_beats, 1 << len(self._beat_q))  # never occur; in the last case: complete
        with m.Switch(self._beat_q):
            for b in range(self._n_beats):
                with m.Case(b, *(unused if b == self._n_beats - 1 else ())):
                    for lane in range(self._params.words_per_beat):
                        row, (col_words, nomatch) = b * rows + lane // lc, columns[lane % lc]
                        if row > dmax + 1:
                            word: ValueLike = 0  # past the last operator: the machine ignores it
                        else:
                            word = col_words[lane // lc] if row <= dmax else nomatch
                        m.d.comb += words[lane].eq(word)
