"""The word generator's shared pipeline (:class:`WordNets`), on which every column kind's lane builder
(:mod:`.lanes`) builds its lanes, for one elaboration of a
:class:`~bayesmachine.hdl.frontend.words.WordGenerator`.

One beat per cycle, in a four-step pipeline that stalls as a whole while the stream does: in the cycle
of the beat's issue each lane's cost (a difference, a Hamming distance, row minus the MAP above) goes
into a register; its absolute value, clamped, into the address register in the next; the look-up
(block RAM read) in the next; the beat on the stream the one after. The registers keep the subtraction
(on the reference features' wide fan-out), the absolute value and clamp, and the long route to the
block RAM apart. The cost's operands are registers: the reference features, and per lane the
delay-line entry of the beat, chosen a cycle ahead (beat 0's when the pixel is taken, the next beat's
at each issue), so no path runs from the beat counter through the entry multiplexer into a table
address. The delay line (:meth:`WordNets._delay_line`) is a circular buffer in distributed RAM, banked
so that each lane row of a beat reads a bank of its own, or for wide beats a shift register of taps,
each lane row reading its entry's tap of the beat (:func:`tapped_line`); a pixel is written into it a
cycle after its take (from a register holding the taken match features), so the take (which depends on the
stream's ready) drives only the entry registers and the reference features, not the buffer's write
enables. Each entry register loads from one tap (or bank read) at the take and one at a fetch, not from a
choice by whether that write is still pending: at two beats or more per pixel an output pixel is not
taken in the cycle after a take (:meth:`WordNets.accept`; output pixels come every ``beats_per_pixel``
cycles, so this costs a cycle only for a line's first output pixel, after the pixels outside the output
region), and in a pass that scans beat 0's fetch is always the cycle after the take, its pixel's write
pending. The choice remains at one beat per pixel (a take each cycle: waiting would halve the rate) and at
beat 0's issue in a pass that does not scan (the issue may stall). Shifting the taps at the take would
leave no write pending but make the take drive the enables of all Dmax + 1 taps.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from amaranth.hdl import Const, Module, Mux, Signal, Value, unsigned
from amaranth.lib import memory

from bayesmachine.hdl.signatures import beat_words

from .tables import LoadForm, padded_table

__all__ = ["BLOCK_TABLE_DEPTH", "COST_BITS", "TABLE_READ_PORTS", "WordNets", "clamped_magnitude", "pick",
           "table_depth", "tapped_line"]

# Tables deeper than this go to block RAM (a DP16KD holds 1024 words of up to 18 bits, or 2048 of 9);
# shallower ones (a census distance's, the prior's) stay logic.
BLOCK_TABLE_DEPTH = 128
# Read ports per copy of a table: a block RAM's two. A lookup of more lane rows reads more copies (Yosys's
# memory mapping searches its port assignments per memory: dozens of ports on one exhaust its memory).
TABLE_READ_PORTS = 2
# The widest cost a lane's table address takes (a difference of two 13-bit feature sums).
COST_BITS = 14
# A block RAM's (DP16KD's) shapes, (depth, width): a table takes the fewest blocks of any one of them.
BLOCK_SHAPES = ((16384, 1), (8192, 2), (4096, 4), (2048, 9), (1024, 18))


def _blocks(depth: int, width: int) -> int:
    """The block RAMs a table of ``depth`` words of ``width`` bits takes."""
    return min(-(-depth // d) * -(-width // w) for d, w in BLOCK_SHAPES)


def table_depth(entries: int, width: int) -> int:
    """The hardware depth of a table of ``entries`` words of ``width`` bits: the next power of two (the
    table padded with its last word, so the clamp of its address is an OR of high bits:
    :func:`clamped_magnitude`) unless that takes more block RAMs (a table in logic is padded while it
    stays in logic)."""
    padded = 1 << max(0, entries - 1).bit_length()
    if entries <= BLOCK_TABLE_DEPTH:
        return padded if padded <= BLOCK_TABLE_DEPTH else entries
    return padded if _blocks(padded, width) <= _blocks(entries, width) else entries


def clamped_magnitude(x: Value, last: int) -> Value:
    """min(|x|, ``last``), as ``range(last + 1)``. When ``last`` + 1 is a power of two 2^k the clamp is
    an OR of x's high bits into its k low ones (x <= -2^k for a negative x: not all of its high bits
    set, or none of its low ones), and the absolute value negates only the k low bits; otherwise
    |x| >= ``last`` is two compares on x itself, beside the absolute value."""
    x = Value.cast(x)
    signed_, width = x.shape().signed, x.shape().width
    k = max(1, last.bit_length())
    if (2 ** (width - 1) if signed_ else 2 ** width - 1) <= last:  # never past the last entry
        return abs(x) if signed_ else x
    if (1 << k) != last + 1:
        far = (x >= last) | (x <= -last) if signed_ else x >= last
        return Mux(far, last, abs(x) if signed_ else x)
    low = x[:k]
    if not signed_:
        return low | x[k:].any().replicate(k)
    sign, high = x[-1], x[k:-1]
    far = Mux(sign, ~high.all() | ~low.any(), high.any())
    return Mux(sign, (-low)[:k], low) | far.replicate(k)


def tapped_line(rows_per_beat: int, beats_per_pixel: int) -> bool:
    """Whether a word generator's delay line is a shift register of taps (lane row j of beat b reads the
    fixed tap of its entry: a multiplexer over the pixel's beats per lane) rather than the circular buffer
    banked by lane row (lane row j reads bank s - g·j, s the pixel's first bank: a multiplexer over the R
    banks per lane, so R² multiplexer inputs a plane bit). The taps cost Dmax + 1 registers a plane bit
    more than the distributed RAM; the banks' multiplexers outgrow them when a pixel has fewer beats than
    a beat has lane rows (wide beats: a pixel every few clocks)."""
    return beats_per_pixel < rows_per_beat


def pick(values: list[Value], index: Value) -> Value:
    """``values[index]``, by a chain of multiplexers (``index`` < ``len(values)``; a complete choice where an
    indexed ``Array`` of a length not a power of two would be an incomplete case)."""
    out = values[-1]
    for k in reversed(range(len(values) - 1)):
        out = Mux(index == k, values[k], out)
    return out


class WordNets:
    """The word generator's shared pipeline, on which every lane builder builds its lanes.

    One beat per cycle, in four steps that stall together with the stream (``advance``): the beat's
    issue (``issue``, beat number ``beat``: each lane's cost into a register, :meth:`address`), the
    cost's clamped absolute value into the address register, the table read (:meth:`table`), the beat
    on the stream (:meth:`aligned` carries a value of the issue's cycle along). ``take``: the lanes take
    a pixel (``pixel``); ``fed_take``: the stream's pixel (``fed``) is taken, the same but in a pass that
    scans (:meth:`_queue`, :meth:`_scan`); ``left``: its reference features; :meth:`entry`: a lane's match
    features.

    Attributes
    ----------
    m : Module
        The generator's module.
    params : MachineParams
    pass_ : Pass
    reference : Reference
    tables : FrontEndTables
    pixel, beats : View
        The pixel the lanes take and the load stream's payload.
    fed : View
        The pixel stream's payload (``pixel`` unless the pass scans: then ``pixel`` is the oldest pixel
        of the ring the lanes have not taken, :meth:`_queue`).
    form : LoadForm
        What the machine loads (its integrator's: words or energy codes).
    tapped : bool
        The delay line is a shift register of taps, not banks (:func:`tapped_line`).
    dmax, rows_per_beat, n_beats, one, zero : int
        The largest disparity, lane rows per beat (R), beats per pixel, the loaded value of a factor
        1.0 and of a factor 0 (``form``'s).
    take, fed_take, advance, issue, beat, free : Value
    active : Signal
        Writing the words of an output pixel (``beat`` counts its beats).
    left : Signal
        The reference features of the pixel taken from the stream (its ``left`` field).
    slots, scan_pixel, fetch, fetch_beat, fetch_slot, take_slot, issue_slot : int, View, Signal
        A pass that scans: its ring of ``slots`` pixels (:meth:`_queue`), the pixel being scanned, the
        fetch (:meth:`_scan`), the slots of the pixel fetched, taken next and issued.
    """

    def __init__(self, m: Module, gen: Any, scan_latency: int = 0) -> None:
        p = gen.params
        self.m = m
        self.params = p
        self.pass_ = gen.pass_
        self.reference = gen.reference
        self.tables = gen.tables
        self.generator = gen
        self.pixel = gen.pixel.payload
        self.beats = gen.beats.payload
        self.dmax = gen.pass_.model.dmax
        self.rows_per_beat = p.words_per_beat // p.loaded_columns
        self.n_beats = p.beats_per_pixel
        self.form = LoadForm.of(p)
        self.one, self.zero = self.form.one, self.form.zero
        self.take = Signal()
        self.advance = Signal()  # the look-up pipeline (address registers, table reads, stream) moves
        self.issue = Signal()
        self.beat = Signal(range(max(2, self.n_beats)))
        side = gen.pixel.payload.left.shape()
        self.left = Signal(side, reset_less=True)
        self._entries: dict[tuple[str, int], Signal] = {}
        self.scan_latency = scan_latency
        # The pixel stream's take and payload: the delay line's, the reference features', a scan's.
        self.fed, self.fed_take = self.pixel, self.take
        self._last_issue = Signal()  # the issue of an output pixel's last beat
        self._may_take: Value = Const(1, 1)  # lane builders' conditions on a scan's take (hold_scan)
        if scan_latency:
            self._queue()
        self._pipeline()
        if scan_latency:
            self._scan()
        else:  # the delay line's entries step with the words' issues
            self.fetch, self.fetch_beat = self.issue, self.beat
        self.free = ~self.active | self._last_issue
        self._delay_line(side)

    def _queue(self) -> None:
        """A pass that scans (:meth:`_scan`): the pixels taken from the stream (``fed_take``) wait in a ring
        of ``slots`` registers, in order, for their scans and for the lanes (``take``, the slot
        ``take_slot``: the oldest pixel not taken, once its scan is done and the previous pixel's words
        have issued, :meth:`accept`). A slot is free again when its pixel is taken, or for an output
        pixel after its last issue (its scan's results in the slot, ``issue_slot``, are read until
        then); so the scans run up to ``slots`` - 1 pixels ahead of the issues, enough for a pixel every
        ``beats_per_pixel`` cycles (the slot of a pixel taken at its stream take T is free from
        T + 2·beats_per_pixel + scan_latency + 1 on)."""
        m = self.m
        self.slots = 2 + -(-(self.scan_latency + 1) // self.n_beats)
        self.fed_take = Signal()
        self.pixel = Signal(self.fed.shape(), name="held_pixel")
        self.scan_pixel = Signal(self.fed.shape(), name="scan_pixel", reset_less=True)  # being scanned
        self.feed_slot = Signal(range(self.slots))  # the slot a pixel from the stream goes to
        self.take_slot = Signal(range(self.slots))
        self.issue_slot = Signal(range(self.slots))
        self.busy = [Signal(name=f"slot_busy{k}") for k in range(self.slots)]  # a pixel or its results
        self.waiting = [Signal(name=f"slot_waiting{k}") for k in range(self.slots)]  # its pixel not taken
        self.scanned = [Signal(name=f"slot_scanned{k}") for k in range(self.slots)]  # (or it has no words)
        held = [Signal(self.fed.shape(), name=f"held_pixel{k}", reset_less=True) for k in range(self.slots)]
        m.d.comb += self.pixel.eq(pick([h.as_value() for h in held], self.take_slot))
        for k in range(self.slots):
            self._slot(k, held[k])
        with m.If(self.take):
            m.d.sync += self._next(self.take_slot)
            with m.If(self.pixel.output):
                m.d.sync += self.issue_slot.eq(self.take_slot)
        with m.If(self.fed_take):
            m.d.sync += [self.scan_pixel.eq(self.fed), self._next(self.feed_slot)]

    def _slot(self, k: int, held: Any) -> None:
        """Slot k's flags and pixel (a pixel from the stream goes to a free slot, so a slot is never both
        freed and filled in one cycle)."""
        m = self.m
        with m.If(self.take & (self.take_slot == k)):
            m.d.sync += self.waiting[k].eq(0)
            with m.If(~self.pixel.output):
                m.d.sync += self.busy[k].eq(0)
        with m.If(self._last_issue & (self.issue_slot == k)):
            m.d.sync += self.busy[k].eq(0)
        with m.If(self.fed_take & (self.feed_slot == k)):
            m.d.sync += [self.busy[k].eq(1), self.waiting[k].eq(1), self.scanned[k].eq(~self.fed.output),
                         held.eq(self.fed)]

    def _next(self, slot: Signal) -> Any:
        """``slot`` to the next slot of the ring."""
        return slot.eq(Mux(slot == self.slots - 1, 0, slot + 1))

    def accept(self, ready: Value) -> Value:
        """The pixel stream's ``ready``, given ``ready``: the lanes may take a pixel (``free`` and each
        lane builder's ``ready``); in a pass that scans it drives ``take``, and the stream's ready is that
        of the ring (a free slot) and of the scan (idle, or fetching a pixel's last beat). At two beats or
        more per pixel, not for an output pixel while the previous pixel's delay-line write is pending
        (``shift_q``), so that its entries read no pending write (:meth:`_delay_line`); in a pass that scans,
        not for an output pixel while a lane builder holds the scans (:meth:`hold_scan`)."""
        # No output pixel taken while a write is pending (_delay_line), but at one beat per pixel.
        settled = ~(self.shift_q & self.fed.output) if self._pending_at_take is None else Const(1, 1)
        if not self.scan_latency:
            return ready & settled
        ripe = pick(self.waiting, self.take_slot) & pick(self.scanned, self.take_slot)
        self.m.d.comb += self.take.eq(ripe & ready)
        held = ~self.fed.output | self._may_take
        return ~pick(self.busy, self.feed_slot) & (~self.fetch | self._fetch_last) & settled & held

    def hold_scan(self, may: Value) -> None:
        """In a pass that scans: an output pixel is taken from the stream (its scan starts) only while
        ``may`` too (a lane builder's condition: the shared fused sums', :mod:`.shared`)."""
        if not self.scan_latency:
            raise ValueError("hold_scan: only a pass that scans takes its pixels for a scan")
        self._may_take = self._may_take & may

    def _pipeline(self) -> None:
        """The beat counter and the valid flags of the four steps."""
        m, n_beats = self.m, self.n_beats
        out = self.generator.beats
        active = Signal()  # writing the words of an output pixel
        self.active = active
        beat_d = Signal(range(max(2, n_beats)))  # the beat in the cost registers
        diff_valid = Signal()
        beat_a = Signal(range(max(2, n_beats)))  # the beat in the address registers
        addr_valid = Signal()
        self.beat_q = Signal(range(max(2, n_beats)))  # the beat on the stream
        m.d.comb += [self.advance.eq(~out.valid | out.ready), self.issue.eq(active & self.advance),
                     self.fed_take.eq(self.generator.pixel.valid & self.generator.pixel.ready)]
        last = self.beat == n_beats - 1
        m.d.comb += self._last_issue.eq(self.issue & last)
        with m.If(self.advance):
            m.d.sync += [diff_valid.eq(self.issue), beat_d.eq(self.beat), addr_valid.eq(diff_valid),
                         beat_a.eq(beat_d), out.valid.eq(addr_valid), self.beat_q.eq(beat_a)]
        with m.If(self.issue):
            with m.If(last):
                m.d.sync += [self.beat.eq(0), active.eq(0)]
            with m.Else():
                m.d.sync += self.beat.eq(self.beat + 1)
        with m.If(self.fed_take):
            m.d.sync += self.left.eq(self.fed.left)
            if not self.scan_latency:
                with m.If(self.pixel.output):
                    m.d.sync += [active.eq(1), self.beat.eq(0)]
        if self.scan_latency:  # the lanes take the scanned pixel (_queue)
            with m.If(self.take & self.pixel.output):
                m.d.sync += [active.eq(1), self.beat.eq(0)]

    def _scan(self) -> None:
        """A pass whose words need every row of the pixel first (a fused column's smallest sum): an output
        pixel's take from the stream starts its scan, a fetch (``fetch``, beat ``fetch_beat``, of the slot
        ``fetch_slot``: the delay line's entries) each cycle, whatever the stream does; the next pixel's
        take from the stream waits for the last fetch (:meth:`accept`), so the scans follow each other
        back to back. ``scan_latency`` cycles after the last fetch (what a fetch's results need to be
        complete) the slot's pixel is ``scanned``."""
        m, n_beats = self.m, self.n_beats
        self.fetch = Signal()  # scanning: one fetch a cycle
        self.fetch_beat = Signal(range(max(2, n_beats)))
        self.fetch_slot = Signal(range(self.slots))
        self._fetch_last = Signal()
        m.d.comb += self._fetch_last.eq(self.fetch & (self.fetch_beat == n_beats - 1))
        done, slot = self._fetch_last, self.fetch_slot
        for k in range(self.scan_latency - 1):  # scanned, scan_latency cycles after the last fetch
            done_q = Signal(name=f"scan_done{k}")
            slot_q = Signal.like(self.fetch_slot, name=f"scan_slot{k}")
            m.d.sync += [done_q.eq(done), slot_q.eq(slot)]
            done, slot = done_q, slot_q
        for k, scanned in enumerate(self.scanned):
            with m.If(done & (slot == k)):
                m.d.sync += scanned.eq(1)
        with m.If(self.fetch):
            m.d.sync += self.fetch_beat.eq(self.fetch_beat + 1)
            with m.If(self._fetch_last):
                m.d.sync += [self.fetch.eq(0), self.fetch_beat.eq(0)]
        with m.If(self.fed_take & self.fed.output):
            m.d.sync += [self.fetch.eq(1), self.fetch_beat.eq(0), self.fetch_slot.eq(self.feed_slot)]

    def _delay_line(self, side: Any) -> None:
        """The match features of the last pixels (:func:`tapped_line`: :meth:`_tapped_line` or
        :meth:`_banked_line`); a pixel enters a cycle after its take, from a register holding its match
        features (``right_in``): the take (FIFO ready -> issue -> take) drives the entry registers, not
        the line's write enables. While that write is pending (``shift_q``) the newest pixel is in
        ``right_in``: where the entry registers load, at an output pixel's take only at one beat per
        pixel, at beat 0's fetch always in a pass that scans (``_pending_at_take``,
        ``_pending_at_fetch``: None never, True always, else when). Uninitialized entries: an output
        pixel is at least Dmax pixels into its line, so none reads an entry of an earlier line or
        frame."""
        self.right_in = Signal(side, reset_less=True)
        self.shift_q = Signal()
        # (accept waits a cycle at two beats or more; a scan fetches beat 0 the cycle after the take)
        self._pending_at_take: Value | None = self.shift_q if self.n_beats == 1 else None
        self._pending_at_fetch: Value | bool = True if self.scan_latency else self.shift_q
        self.m.d.sync += self.shift_q.eq(self.fed_take)
        with self.m.If(self.fed_take):
            self.m.d.sync += self.right_in.eq(self.fed.right)
        self.tapped = tapped_line(self.rows_per_beat, self.n_beats)
        if self.tapped:
            self._tapped_line(side)
        else:
            self._banked_line(side)

    def _tapped_line(self, side: Any) -> None:
        """A shift register of Dmax + 1 taps, tap k the match features of the k-th newest pixel written
        (``_taps``), shifted at each write: the entries of a pixel sit at fixed taps while its beats load
        (no pixel is taken between its take and its last fetch)."""
        self._taps = [Signal(side, name=f"tap_{k}", reset_less=True) for k in range(self.dmax + 1)]
        with self.m.If(self.shift_q):
            self.m.d.sync += [self._taps[0].eq(self.right_in),
                              *(self._taps[k].eq(self._taps[k - 1]) for k in range(1, self.dmax + 1))]

    def _banked_line(self, side: Any) -> None:
        """The match features of the last pixels: pixel t (the t-th taken) at address t mod N of a
        circular buffer of N = R·M entries (R lane rows per beat, M = ceil((Dmax + 1) / R)), banked by
        address mod R, bank k holding addresses k, k + R, ... at index address // R (distributed RAM,
        one combinational read port each). Entry d of pixel t (the match features d pixels back) is at
        address t - d; a beat's R lanes read R consecutive entries, so R consecutive addresses, one in
        each bank (:meth:`_next_load`). Entries of a lane row past Dmax read some older pixel (their
        words are the no-match row's or 0, not a table's)."""
        m, rows = self.m, self.rows_per_beat
        self._bank_depth = -(-(self.dmax + 1) // rows)  # M: entries per bank
        write_bank = Signal(range(rows))  # the next write's address t mod N, as bank and index
        write_index = Signal(range(self._bank_depth))
        q, q_wrap, start = self._next_load()
        self._bank_data = []
        for k in range(rows):
            mem = memory.Memory(shape=side, depth=self._bank_depth, init=[])
            m.submodules[f"line_{k}"] = mem
            write, read = mem.write_port(), mem.read_port(domain="comb")
            # The window runs from bank ``start`` towards lower banks (left reference) or higher ones;
            # the banks it reaches after wrapping around hold its end at the neighbouring index.
            # (a bank no window reaches after wrapping is never compared: a constant compare lints)
            if self._towards < 0:
                wraps = start[0] < k if k > 0 else Const(0, 1)
            else:
                wraps = start[0] > k if k < rows - 1 else Const(0, 1)
            m.d.comb += [write.addr.eq(write_index), write.data.eq(self.right_in),
                         write.en.eq(self.shift_q & (write_bank == k)), read.addr.eq(Mux(wraps, q_wrap, q))]
            self._bank_data.append(read.data)
        with m.If(self.shift_q):
            m.d.sync += [write_bank.eq(Mux(write_bank == rows - 1, 0, write_bank + 1)),
                         write_index.eq(Mux(write_bank == rows - 1, self._step(write_index, 1), write_index))]

    def _step(self, index: Value, by: int) -> Value:
        """A bank index plus ``by`` (-2 .. 2) modulo M (a compare and a multiplexer a step)."""
        last = self._bank_depth - 1
        for _ in range(abs(by)):
            index = Mux(index == last, 0, index + 1) if by > 0 else Mux(index == 0, last, index - 1)
        return index

    def _next_load(self) -> tuple[Signal, Signal, list[Signal]]:
        """Where the next entry load reads: (``q``, ``q_wrap``, ``start``). Beat b of pixel t reads
        entries c + g·(b·R + j) (lane j; c, g from the pass's reference: entry = c + g·row), addresses
        u - g·(b·R + j) with u = t - c: its window starts at address u - g·b·R, in bank s = u mod R
        (fixed for the pixel) at index q (one step of -g a beat), and runs through the banks s - g·j,
        those past the last bank at index ``q_wrap`` = q - g; lane j reads bank s - g·j (``start``: s, a
        registered copy per lane row for the rotations' fan-out). The next load is beat 0 of the next
        pixel until an output pixel's take, then beats 1 .. n - 1 of that pixel at its issues of beats
        0 .. n - 2, then beat 0 of the pixel after; all in registers, so a bank's address is a
        multiplexer of registers."""
        m, rows, n_beats = self.m, self.rows_per_beat, self.n_beats
        c = self.reference.entry(0, self.dmax)
        g = self.reference.entry(1, self.dmax) - c
        self._towards = -g
        u0 = (-c) % (rows * self._bank_depth)
        q0 = Signal(range(self._bank_depth), init=u0 // rows)  # beat 0 of the pixel taken next
        s0 = Signal(range(rows), init=u0 % rows)
        q = Signal(range(self._bank_depth), init=u0 // rows)  # the next load's window
        q_wrap = Signal(range(self._bank_depth), init=(u0 // rows - g) % self._bank_depth)
        start = [Signal(range(rows), init=u0 % rows, name=f"load_start_rep{j}") for j in range(rows)]
        carry = s0 == rows - 1
        q0_next = Mux(carry, self._step(q0, 1), q0)
        s0_next = Mux(carry, 0, s0 + 1)
        next_pixel = [q.eq(q0_next), q_wrap.eq(self._step(q0_next, -g)), *(r.eq(s0_next) for r in start)]
        with m.If(self.fed_take):
            m.d.sync += [q0.eq(q0_next), s0.eq(s0_next)]
            if n_beats > 1:
                with m.If(self.fed.output):  # next: beat 1 of this pixel
                    m.d.sync += [q.eq(self._step(q0, -g)), q_wrap.eq(self._step(q0, -2 * g))]
                with m.Else():  # next: beat 0 of the next pixel
                    m.d.sync += next_pixel
            else:
                m.d.sync += next_pixel
        if n_beats > 1:
            with m.Elif(self.fetch & (self.fetch_beat == n_beats - 2)):  # next: beat 0 of the next pixel
                m.d.sync += [q.eq(q0), q_wrap.eq(self._step(q0, -g)), *(r.eq(s0) for r in start)]
        if n_beats > 2:
            with m.Elif(self.fetch & (self.fetch_beat < n_beats - 2)):  # next: beat b + 2
                m.d.sync += [q.eq(self._step(q, -g)), q_wrap.eq(self._step(q_wrap, -g))]
        self._start = start
        return q, q_wrap, start

    def row(self, j: int) -> Value:
        """The row of lane row j of the beat being issued."""
        return self.beat * self.rows_per_beat + j

    def at_take(self, value: Value, name: str) -> Signal:
        """``value`` of the pixel taken (registered at the take)."""
        reg = Signal.like(value, name=name)
        with self.m.If(self.take):
            self.m.d.sync += reg.eq(value)
        return reg

    def aligned(self, value: Value, name: str) -> Signal:
        """``value`` of the issue's cycle, with its beat on the stream (the three steps' registers)."""
        stages = [Signal.like(Value.cast(value), name=f"{name}_{s}") for s in "daq"]
        with self.m.If(self.advance):
            self.m.d.sync += [stages[0].eq(value), stages[1].eq(stages[0]), stages[2].eq(stages[1])]
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
        with self.m.If(self.advance if en is None else en):
            self.m.d.sync += [cost.eq(value), reg.eq(clamped_magnitude(cost, depth - 1))]
        return reg

    def table(self, name: str, words: Any, bits: int | None = None) -> memory.Memory:
        """A read-only table of W + 1-bit words (or of ``bits``-bit values: energy codes), submodule
        ``table_{name}`` (a copy's name, :meth:`lookup`): in block RAM when deeper than
        :data:`BLOCK_TABLE_DEPTH` (Yosys would otherwise build each read port's multiplexer tree over
        every entry before mapping it to logic); padded with its last word to :func:`table_depth`."""
        width = self._table_width(bits)
        init = [int(w) for w in padded_table(np.asarray(words), table_depth(len(words), width))]
        attrs = {"rom_style": "block"} if len(init) > BLOCK_TABLE_DEPTH else None
        mem = memory.Memory(shape=unsigned(width), depth=len(init), init=init, attrs=attrs)
        self.m.submodules[f"table_{name}"] = mem
        return mem

    def lookup(self, name: str, words: Any, costs: list[Value], en: Value | None = None,
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
            self.m.d.comb += [port.en.eq(self.advance if en is None else en), port.addr.eq(addr)]
            out.append(port.data)
        return out

    def _table_width(self, bits: int | None) -> int:
        """A table's word width: W + 1 (a word), or ``bits`` (energy codes)."""
        return self.params.memory_word_width if bits is None else bits

    def _identity(self, name: str, j: int, cost: Value, depth: int, en: Value | None,
                  bits: int | None) -> Signal:
        """Lane row j's read of an identity table of ``depth`` words: its address, a cycle later."""
        addr = self.address(cost, depth, f"{name}_{j}", en)
        # As a read port's data: loaded on the read's enable, no reset.
        data = Signal(unsigned(self._table_width(bits)), name=f"read_{name}_{j}", reset_less=True)
        with self.m.If(self.advance if en is None else en):
            self.m.d.sync += data.eq(addr)
        return data

    def entry(self, plane: str, j: int) -> Signal:
        """The ``plane`` value of lane row j's match pixel for the beat being issued: a register loaded a
        cycle ahead from the delay line (the beat counter ends there, not at the table address), with
        beat 0's entry when a pixel is taken, the next beat's on a fetch (:meth:`_tap_reads`,
        :meth:`_bank_reads`)."""
        key = (plane, j)
        if key not in self._entries:
            at_take, at_fetch = (self._tap_reads if self.tapped else self._bank_reads)(plane, j)
            sel = Signal(getattr(self.right_in, plane).shape(), name=f"right_{plane}_{j}", reset_less=True)
            with self.m.If(self.fed_take):
                self.m.d.sync += sel.eq(at_take)
            if at_fetch is not None:
                with self.m.Elif(self.fetch):  # beat b + 1's entry
                    self.m.d.sync += sel.eq(at_fetch)
            self._entries[key] = sel
        return self._entries[key]

    def _tap_reads(self, plane: str, j: int) -> tuple[Value, Value | None]:
        """Lane row j's entry at the take and at a fetch from the taps (:meth:`_tapped_line`): entry d of
        pixel t is pixel t - d, tap d - 1 at its take, tap d at its fetches, one tap nearer while pixel
        t - 1 (at the take) or t (at beat 0's fetch, the latest a write is pending) is in ``right_in``
        (:meth:`_delay_line`: where that may be). An entry past Dmax (a lane row past Dmax: its words are
        the no-match row's or 0) reads 0 or an older pixel."""
        pending = getattr(self.right_in, plane)
        taps = [pending, *(getattr(t, plane) for t in self._taps)]  # taps[k + 1]: tap k

        def read(k: int, pend: Value | bool | None) -> Value:  # tap k once a write pending (``pend``) is done
            if not 0 <= k <= self.dmax:
                return Const(0, len(pending))
            return self._unless_pending(pend, taps[k], taps[k + 1])

        d0 = self.reference.entry(j, self.dmax)
        at_take = getattr(self.fed.right, plane) if d0 == 0 else read(d0 - 1, self._pending_at_take)
        if self.n_beats == 1:
            return at_take, None
        fetched = [read(self.reference.entry((b + 1) * self.rows_per_beat + j, self.dmax),
                        self._pending_at_fetch if b == 0 else None) for b in range(self.n_beats - 1)]
        return at_take, pick(fetched, self.fetch_beat)

    @staticmethod
    def _unless_pending(pend: Value | bool | None, pending: Value, written: Value) -> Value:
        """``written``, or ``pending`` while a write is pending: ``pend`` (None: never, True: always)."""
        if pend is None:
            return written
        return pending if pend is True else Mux(pend, pending, written)

    def _bank_reads(self, plane: str, j: int) -> tuple[Value, Value]:
        """Lane row j's entry at the take and at a fetch from the banks (:meth:`_banked_line`), at the
        address of the next load (:meth:`_next_load`). The newest pixels come from the registers in front
        of the buffer until they are written (:meth:`_delay_line`: where that may be): at the take the
        taken pixel (entry 0) and the one before it (entry 1) while its write is pending; at beat 0's
        fetch the taken pixel while its write is pending."""
        m, rows = self.m, self.rows_per_beat
        banks = [getattr(d, plane) for d in self._bank_data]
        read = Signal(banks[0].shape(), name=f"line_{plane}_{j}")
        with m.Switch(self._start[j]):  # lane j reads bank s - g·j (s < R: the last case is the default)
            for start in range(rows):
                with m.Case(start) if start < rows - 1 else m.Default():
                    m.d.comb += read.eq(banks[(start + self._towards * j) % rows])
        pending = getattr(self.right_in, plane)

        def newest(d: int, pend: Value | bool | None) -> Value:  # entry d of the pixel being loaded
            return self._unless_pending(pend, pending, read) if d == 0 else read

        d0 = self.reference.entry(j, self.dmax)
        at_take = getattr(self.fed.right, plane) if d0 == 0 else newest(d0 - 1, self._pending_at_take)
        # Beat 0's fetch is the latest a write is pending (a lane row of entry 0 at beat 1 is past Dmax after)
        return at_take, newest(self.reference.entry(rows + j, self.dmax), self._pending_at_fetch)

    def write_beats(self, columns: list[tuple[list[Any], Any]]) -> None:
        """The beat on the stream: lane L's word by its (row, operator column) from ``columns`` (each
        loaded column's words of lane rows 0..R-1 and its no-match word); 0 past the last row."""
        m, dmax, rows = self.m, self.dmax, self.rows_per_beat
        lc = len(columns)
        words = beat_words(self.params, self.beats)
        unused = range(self.n_beats, 1 << len(self.beat_q))  # never occur; in the last case: a complete case
        with m.Switch(self.beat_q):
            for b in range(self.n_beats):
                with m.Case(b, *(unused if b == self.n_beats - 1 else ())):
                    for lane in range(self.params.words_per_beat):
                        row, (col_words, nomatch) = b * rows + lane // lc, columns[lane % lc]
                        if row > dmax + 1:
                            word: Any = 0  # past the last operator: the machine ignores it
                        else:
                            word = col_words[lane // lc] if row <= dmax else nomatch
                        m.d.comb += words[lane].eq(word)

