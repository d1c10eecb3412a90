"""A word generator's delay line: the match features of the last Dmax + 1 pixels taken from the stream,
part of its shared pipeline (:class:`~.wordpipe.WordPipeline`), and each lane row's entry of the beat
being issued (or fetched).

The delay line is a circular buffer in distributed RAM, banked so that each lane row of a beat reads a
bank of its own, or for wide beats a shift register of taps, each lane row reading its entry's tap of
the beat (:func:`tapped_line`); a pixel is written into it a cycle after its take (from a register holding
the taken match features), so the take (which depends on the stream's ready) drives only the entry
registers and the reference features, not the buffer's write enables. Each entry register loads from one
tap (or bank read) at the take and one at a fetch, not from a choice by whether that write is still
pending: at two beats or more per pixel an output pixel is not taken in the cycle after a take (the
pipeline's ``accept`` waits while :attr:`DelayLine.pending_at_take` is None), and in a pass that scans
beat 0's fetch is always the cycle after the take, its pixel's write pending. The choice remains at one
beat per pixel (a take each cycle: waiting would halve the rate) and at beat 0's issue in a pass that
does not scan (the issue may stall). Shifting the taps at the take would leave no write pending but make
the take drive the enables of all Dmax + 1 taps.
"""

from __future__ import annotations

from amaranth.hdl import Const, Module, Mux, Signal, Value
from amaranth.lib import data, memory

from .lookup import pick
from .reference import Reference

__all__ = ["DelayLine", "tapped_line"]


def tapped_line(rows_per_beat: int, beats_per_pixel: int) -> bool:
    """Whether a word generator's delay line is a shift register of taps (lane row j of beat b reads the
    fixed tap of its entry: a multiplexer over the pixel's beats per lane) rather than the circular buffer
    banked by lane row (lane row j reads bank s - g·j, s the pixel's first bank: a multiplexer over the R
    banks per lane, so R² multiplexer inputs a plane bit). The taps cost Dmax + 1 registers a plane bit
    more than the distributed RAM; the banks' multiplexers outgrow them when a pixel has fewer beats than
    a beat has lane rows (wide beats: a pixel every few clocks)."""
    return beats_per_pixel < rows_per_beat



class DelayLine:
    """The delay line of a word generator (module text): :meth:`build` its logic, then :meth:`entry` a
    lane row's entry register.

    Parameters
    ----------
    m : Module
    fed : View
        The pixel stream's payload (its ``right`` field enters the line).
    fed_take : Value
        A pixel is taken from the stream.
    fetch, fetch_beat : Value
        An entry load of the next beat (an issue, or in a pass that scans a fetch) and its beat.
    reference : Reference
        The pass's reference (lane d reads entry ``reference.entry(d, dmax)``).
    dmax, rows_per_beat, n_beats : int
    scans : bool
        The pass scans (its beat 0's fetch is always the cycle after the take).
    """

    def __init__(self, m: Module, *, fed: data.View, fed_take: Value, fetch: Value, fetch_beat: Value,
                 reference: Reference, dmax: int, rows_per_beat: int, n_beats: int, scans: bool) -> None:
        self._m, self._fed, self._fed_take = m, fed, fed_take
        self._fetch, self._fetch_beat, self._reference = fetch, fetch_beat, reference
        self._dmax, self._rows, self._n_beats, self._scans = dmax, rows_per_beat, n_beats, scans
        self._entries: dict[tuple[str, int], Signal] = {}

    @property
    def shift_q(self) -> Signal:
        """A write into the line is pending (the pixel taken in the cycle before)."""
        return self._shift_q

    @property
    def pending_at_take(self) -> Value | None:
        """Where an output pixel's take may find a write pending (None: never, the take waits)."""
        return self._pending_at_take

    @property
    def tapped(self) -> bool:
        return self._tapped

    def build(self) -> None:
        """The match features of the last pixels (:func:`tapped_line`: :meth:`_tapped_line` or
        :meth:`_banked_line`); a pixel enters a cycle after its take, from a register holding its match
        features (``right_in``): the take (FIFO ready -> issue -> take) drives the entry registers, not
        the line's write enables. While that write is pending (``shift_q``) the newest pixel is in
        ``right_in``: where the entry registers load, at an output pixel's take only at one beat per
        pixel, at beat 0's fetch always in a pass that scans (``_pending_at_take``,
        ``_pending_at_fetch``: None never, True always, else when). Uninitialized entries: an output
        pixel is at least Dmax pixels into its line, so none reads an entry of an earlier line or
        frame."""
        side = self._fed.right.shape()
        self._right_in = Signal(side, name="right_in", reset_less=True)
        self._shift_q = Signal(name="shift_q")
        # (accept waits a cycle at two beats or more; a scan fetches beat 0 the cycle after the take)
        self._pending_at_take: Value | None = self._shift_q if self._n_beats == 1 else None
        self._pending_at_fetch: Value | bool = True if self._scans else self._shift_q
        self._m.d.sync += self._shift_q.eq(self._fed_take)
        with self._m.If(self._fed_take):
            self._m.d.sync += self._right_in.eq(self._fed.right)
        self._tapped = tapped_line(self._rows, self._n_beats)
        if self._tapped:
            self._tapped_line(side)
        else:
            self._banked_line(side)

    def _tapped_line(self, side: data.Layout) -> None:
        """A shift register of Dmax + 1 taps, tap k the match features of the k-th newest pixel written
        (``_taps``), shifted at each write: the entries of a pixel sit at fixed taps while its beats load
        (no pixel is taken between its take and its last fetch)."""
        self._taps = [Signal(side, name=f"tap_{k}", reset_less=True) for k in range(self._dmax + 1)]
        with self._m.If(self._shift_q):
            self._m.d.sync += [self._taps[0].eq(self._right_in),
                              *(self._taps[k].eq(self._taps[k - 1]) for k in range(1, self._dmax + 1))]

    def _banked_line(self, side: data.Layout) -> None:
        """The match features of the last pixels: pixel t (the t-th taken) at address t mod N of a
        circular buffer of N = R·M entries (R lane rows per beat, M = ceil((Dmax + 1) / R)), banked by
        address mod R, bank k holding addresses k, k + R, ... at index address // R (distributed RAM,
        one combinational read port each). Entry d of pixel t (the match features d pixels back) is at
        address t - d; a beat's R lanes read R consecutive entries, so R consecutive addresses, one in
        each bank (:meth:`_next_load`). Entries of a lane row past Dmax read some older pixel (their
        words are the no-match row's or 0, not a table's)."""
        m, rows = self._m, self._rows
        self._bank_depth = -(-(self._dmax + 1) // rows)  # M: entries per bank
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
            m.d.comb += [write.addr.eq(write_index), write.data.eq(self._right_in),
                         write.en.eq(self._shift_q & (write_bank == k)), read.addr.eq(Mux(wraps, q_wrap, q))]
            self._bank_data.append(read.data)
        with m.If(self._shift_q):
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
        m, rows, n_beats = self._m, self._rows, self._n_beats
        c = self._reference.entry(0, self._dmax)
        g = self._reference.entry(1, self._dmax) - c
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
        with m.If(self._fed_take):
            m.d.sync += [q0.eq(q0_next), s0.eq(s0_next)]
            if n_beats > 1:
                with m.If(self._fed.output):  # next: beat 1 of this pixel
                    m.d.sync += [q.eq(self._step(q0, -g)), q_wrap.eq(self._step(q0, -2 * g))]
                with m.Else():  # next: beat 0 of the next pixel
                    m.d.sync += next_pixel
            else:
                m.d.sync += next_pixel
        if n_beats > 1:
            with m.Elif(self._fetch & (self._fetch_beat == n_beats - 2)):  # next: beat 0 of the next pixel
                m.d.sync += [q.eq(q0), q_wrap.eq(self._step(q0, -g)), *(r.eq(s0) for r in start)]
        if n_beats > 2:
            with m.Elif(self._fetch & (self._fetch_beat < n_beats - 2)):  # next: beat b + 2
                m.d.sync += [q.eq(self._step(q, -g)), q_wrap.eq(self._step(q_wrap, -g))]
        self._start = start
        return q, q_wrap, start

    def entry(self, plane: str, j: int) -> Signal:
        """The ``plane`` value of lane row j's match pixel for the beat being issued: a register loaded a
        cycle ahead from the delay line (the beat counter ends there, not at the table address), with
        beat 0's entry when a pixel is taken, the next beat's on a fetch (:meth:`_tap_reads`,
        :meth:`_bank_reads`)."""
        key = (plane, j)
        if key not in self._entries:
            at_take, at_fetch = (self._tap_reads if self._tapped else self._bank_reads)(plane, j)
            sel = Signal(getattr(self._right_in, plane).shape(), name=f"right_{plane}_{j}", reset_less=True)
            with self._m.If(self._fed_take):
                self._m.d.sync += sel.eq(at_take)
            if at_fetch is not None:
                with self._m.Elif(self._fetch):  # beat b + 1's entry
                    self._m.d.sync += sel.eq(at_fetch)
            self._entries[key] = sel
        return self._entries[key]

    def _tap_reads(self, plane: str, j: int) -> tuple[Value, Value | None]:
        """Lane row j's entry at the take and at a fetch from the taps (:meth:`_tapped_line`): entry d of
        pixel t is pixel t - d, tap d - 1 at its take, tap d at its fetches, one tap nearer while pixel
        t - 1 (at the take) or t (at beat 0's fetch, the latest a write is pending) is in ``right_in``
        (:meth:`_delay_line`: where that may be). An entry past Dmax (a lane row past Dmax: its words are
        the no-match row's or 0) reads 0 or an older pixel."""
        pending = getattr(self._right_in, plane)
        taps = [pending, *(getattr(t, plane) for t in self._taps)]  # taps[k + 1]: tap k

        def read(k: int, pend: Value | bool | None) -> Value:  # tap k once a write pending (``pend``) is done
            if not 0 <= k <= self._dmax:
                return Const(0, len(pending))
            return self._unless_pending(pend, taps[k], taps[k + 1])

        d0 = self._reference.entry(j, self._dmax)
        at_take = getattr(self._fed.right, plane) if d0 == 0 else read(d0 - 1, self._pending_at_take)
        if self._n_beats == 1:
            return at_take, None
        fetched = [read(self._reference.entry((b + 1) * self._rows + j, self._dmax),
                        self._pending_at_fetch if b == 0 else None) for b in range(self._n_beats - 1)]
        return at_take, pick(fetched, self._fetch_beat)

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
        m, rows = self._m, self._rows
        banks = [getattr(d, plane) for d in self._bank_data]
        read = Signal(banks[0].shape(), name=f"line_{plane}_{j}")
        with m.Switch(self._start[j]):  # lane j reads bank s - g·j (s < R: the last case is the default)
            for start in range(rows):
                with m.Case(start) if start < rows - 1 else m.Default():
                    m.d.comb += read.eq(banks[(start + self._towards * j) % rows])
        pending = getattr(self._right_in, plane)

        def newest(d: int, pend: Value | bool | None) -> Value:  # entry d of the pixel being loaded
            return self._unless_pending(pend, pending, read) if d == 0 else read

        d0 = self._reference.entry(j, self._dmax)
        at_take = getattr(self._fed.right, plane) if d0 == 0 else newest(d0 - 1, self._pending_at_take)
        # Beat 0's fetch is the latest a write is pending (a lane row of entry 0 at beat 1 is past Dmax after)
        return at_take, newest(self._reference.entry(rows + j, self._dmax), self._pending_at_fetch)
