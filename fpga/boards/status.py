"""The board's receive timeout and its status LEDs, each with its twin (per cycle)."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int

__all__ = ["ReceiveTimeout", "ReceiveTimeoutTwin", "StatusLEDs", "StatusLEDsTwin"]


class ReceiveTimeout(wiring.Component):
    """Fires after ``cycles`` consecutive quiet cycles: the board waits for the host's bytes and
    nothing else is happening. The count starts again at every cycle that is not quiet, and after
    firing.

    Parameters
    ----------
    cycles : int
        Quiet cycles before it fires (at least 2).

    Attributes
    ----------
    waiting : ``In(1)``
        The board waits for the host's bytes.
    busy : ``In(1)``
        Something is in flight on the board's side (a byte coming in or going out, a pixel being
        answered): not quiet.
    fired : ``Out(1)``
        The ``cycles``-th quiet cycle in a row.
    """

    def __init__(self, *, cycles: int) -> None:
        cycles = as_int("cycles", cycles, 2)
        self._cycles = cycles
        super().__init__({"waiting": In(1), "busy": In(1), "fired": Out(1)})

    @property
    def cycles(self) -> int:
        return self._cycles

    def elaborate(self, platform: object) -> Module:
        m = Module()
        silence = Signal(range(self._cycles))
        quiet = self.waiting & ~self.busy
        m.d.comb += self.fired.eq(quiet & (silence == self._cycles - 1))
        m.d.sync += silence.eq(Mux(quiet & ~self.fired, silence + 1, 0))
        return m


@dataclass
class ReceiveTimeoutTwin:
    """:class:`ReceiveTimeout` cycle by cycle."""

    cycles: int
    silence: int = 0

    def step(self, waiting: bool, busy: bool) -> bool:
        """This cycle's ``fired``; then the clock edge."""
        quiet = waiting and not busy
        fired = quiet and self.silence == self.cycles - 1
        self.silence = self.silence + 1 if quiet and not fired else 0
        return fired


class StatusLEDs(wiring.Component):
    """The board's status on eight LEDs: 0 a frame in progress, 1 the last frame or header failed,
    2 and 3 toggle at each byte received and sent, 4 the receive buffer overflowed during the last
    frame; 5-7 off (a board top may use them).

    Attributes
    ----------
    in_frame, error, overflow : ``In(1)``
        Shown as they are (LEDs 0, 1, 4).
    received, sent : ``In(1)``
        A byte came in, went out, this cycle (LEDs 2, 3 toggle).
    leds : ``Out(8)``
    """

    def __init__(self) -> None:
        super().__init__({"in_frame": In(1), "error": In(1), "overflow": In(1), "received": In(1),
                          "sent": In(1), "leds": Out(8)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        received, sent = Signal(), Signal()
        m.d.sync += [received.eq(received ^ self.received), sent.eq(sent ^ self.sent)]
        m.d.comb += self.leds.eq(Cat(self.in_frame, self.error, received, sent, self.overflow))
        return m


@dataclass
class StatusLEDsTwin:
    """:class:`StatusLEDs` cycle by cycle."""

    received: bool = False
    sent: bool = False

    def step(self, in_frame: bool, error: bool, overflow: bool, received: bool, sent: bool) -> int:
        """This cycle's ``leds``; then the clock edge."""
        leds = in_frame | error << 1 | self.received << 2 | self.sent << 3 | overflow << 4
        self.received ^= received
        self.sent ^= sent
        return leds
