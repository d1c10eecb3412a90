"""The scan ring of a word generator whose pass scans an output pixel's beats before its words (a fused
column's smallest sum: ``Lanes.scan_latency``), part of its shared pipeline
(:class:`~.wordpipe.WordPipeline`).

The pixels taken from the stream (``fed_take``) wait in a ring of ``slots`` registers, in order, for
their scans and for the lanes (``take``, the slot ``take_slot``: the oldest pixel not taken, once its scan
is done and the previous pixel's words have issued). A slot is free again when its pixel is taken, or for
an output pixel after its last issue (its scan's results in the slot, ``issue_slot``, are read until
then); so the scans run up to ``slots`` - 1 pixels ahead of the issues, enough for a pixel every
``beats_per_pixel`` cycles (the slot of a pixel taken at its stream take T is free from
T + 2·beats_per_pixel + scan_latency + 1 on). An output pixel's take from the stream starts its scan, a
fetch (``fetch``, beat ``fetch_beat``, of the slot ``fetch_slot``: the delay line's entries) each cycle,
whatever the stream does; the next pixel's take from the stream waits for the last fetch, so the scans
follow each other back to back. ``scan_latency`` cycles after the last fetch (what a fetch's results
need to be complete) the slot's pixel is ``scanned``.
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, Value
from amaranth.lib import data

from .lookup import pick

__all__ = ["ScanRing", "scan_slots"]


def scan_slots(scan_latency: int, n_beats: int) -> int:
    """The ring's slots for a scan of ``scan_latency`` cycles at ``n_beats`` beats per pixel."""
    return 2 + -(-(scan_latency + 1) // n_beats)


class ScanRing:
    """The ring of a pass that scans (module text): its nets, then its logic in two steps around the
    beat pipeline's (:meth:`build_queue` before it, :meth:`build_scan` after it).

    Parameters
    ----------
    m : Module
    fed : View
        The pixel stream's payload.
    take, last_issue : Signal
        The lanes take the ring's pixel ``pixel``; the issue of an output pixel's last beat.
    n_beats, scan_latency : int
        Beats per pixel; the cycles from a fetch to the results it gives (>= 1).
    """

    def __init__(self, m: Module, fed: data.View, take: Signal, last_issue: Signal, n_beats: int,
                 scan_latency: int) -> None:
        self._m, self._fed, self._take, self._last_issue = m, fed, take, last_issue
        self._n_beats, self._latency = n_beats, scan_latency
        self.slots = scan_slots(scan_latency, n_beats)
        self.fed_take = Signal()
        self.pixel = Signal(fed.shape(), name="held_pixel")
        self.scan_pixel = Signal(fed.shape(), name="scan_pixel", reset_less=True)  # being scanned
        # the slot a pixel from the stream goes to
        self._feed_slot = Signal(range(self.slots), name="feed_slot")
        self.take_slot = Signal(range(self.slots))
        self.issue_slot = Signal(range(self.slots))
        self._busy = [Signal(name=f"slot_busy{k}") for k in range(self.slots)]  # a pixel or its results
        self._waiting = [Signal(name=f"slot_waiting{k}") for k in range(self.slots)]  # its pixel not taken
        self._scanned = [Signal(name=f"slot_scanned{k}") for k in range(self.slots)]  # (or it has no words)

    def build_queue(self) -> None:
        """The slots: a pixel from the stream into the next slot, the lanes' pixel from the oldest."""
        m, fed = self._m, self._fed
        held = [Signal(fed.shape(), name=f"held_pixel{k}", reset_less=True) for k in range(self.slots)]
        m.d.comb += self.pixel.eq(pick([h.as_value() for h in held], self.take_slot))
        for k in range(self.slots):
            self._slot(k, held[k])
        with m.If(self._take):
            m.d.sync += self.take_slot.eq(self._next(self.take_slot))
            with m.If(self.pixel.output):
                m.d.sync += self.issue_slot.eq(self.take_slot)
        with m.If(self.fed_take):
            m.d.sync += [self.scan_pixel.eq(fed), self._feed_slot.eq(self._next(self._feed_slot))]

    def _slot(self, k: int, held: Signal) -> None:
        """Slot k's flags and pixel (a pixel from the stream goes to a free slot, so a slot is never both
        freed and filled in one cycle)."""
        m = self._m
        with m.If(self._take & (self.take_slot == k)):
            m.d.sync += self._waiting[k].eq(0)
            with m.If(~self.pixel.output):
                m.d.sync += self._busy[k].eq(0)
        with m.If(self._last_issue & (self.issue_slot == k)):
            m.d.sync += self._busy[k].eq(0)
        with m.If(self.fed_take & (self._feed_slot == k)):
            m.d.sync += [self._busy[k].eq(1), self._waiting[k].eq(1), self._scanned[k].eq(~self._fed.output),
                         held.eq(self._fed)]

    def _next(self, slot: Signal) -> Value:
        """The slot after ``slot`` in the ring."""
        return Mux(slot == self.slots - 1, 0, slot + 1)

    def build_scan(self) -> None:
        """The fetches of an output pixel's beats, from its take from the stream, and its slot
        ``scanned`` ``scan_latency`` cycles after the last."""
        m, n_beats = self._m, self._n_beats
        self.fetch = Signal()  # scanning: one fetch a cycle
        self.fetch_beat = Signal(range(max(2, n_beats)))
        self.fetch_slot = Signal(range(self.slots))
        self._fetch_last = Signal()
        m.d.comb += self._fetch_last.eq(self.fetch & (self.fetch_beat == n_beats - 1))
        done, slot = self._fetch_last, self.fetch_slot
        for k in range(self._latency - 1):  # scanned, scan_latency cycles after the last fetch
            done_q = Signal(name=f"scan_done{k}")
            slot_q = Signal.like(self.fetch_slot, name=f"scan_slot{k}")
            m.d.sync += [done_q.eq(done), slot_q.eq(slot)]
            done, slot = done_q, slot_q
        for k, scanned in enumerate(self._scanned):
            with m.If(done & (slot == k)):
                m.d.sync += scanned.eq(1)
        with m.If(self.fetch):
            m.d.sync += self.fetch_beat.eq(self.fetch_beat + 1)
            with m.If(self._fetch_last):
                m.d.sync += [self.fetch.eq(0), self.fetch_beat.eq(0)]
        with m.If(self.fed_take & self._fed.output):
            m.d.sync += [self.fetch.eq(1), self.fetch_beat.eq(0), self.fetch_slot.eq(self._feed_slot)]

    def ready(self, ready: Value) -> Value:
        """Drives ``take`` (the oldest pixel, scanned, while the lanes are ``ready``); returns the ring's
        part of the stream's ready: a free slot, and the scan idle or fetching a pixel's last beat."""
        ripe = pick(self._waiting, self.take_slot) & pick(self._scanned, self.take_slot)
        self._m.d.comb += self._take.eq(ripe & ready)
        return ~pick(self._busy, self._feed_slot) & (~self.fetch | self._fetch_last)
