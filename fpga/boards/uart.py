"""A UART at bit level (8 data bits, no parity, one stop bit, LSB first): receiver and transmitter.

Both count ``clocks_per_bit`` clock cycles per bit (the board's clock over the baud rate, at
least 4). The receiver samples the middle of each bit after a 2-flip-flop synchronizer; a stop
bit read as 0 (a framing error, or a break) drops the byte and raises ``error`` for a cycle.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int

__all__ = ["UARTRx", "UARTTx", "check_clocks_per_bit"]


def check_clocks_per_bit(clocks_per_bit: object) -> int:
    return as_int("clocks_per_bit", clocks_per_bit, 4, 1 << 16)


class UARTRx(wiring.Component):
    """Serial line in, one byte per ``data.valid`` pulse out (no back-pressure: a UART cannot wait).

    Parameters
    ----------
    clocks_per_bit : int
        Clock cycles per bit (4 .. 65536).

    Attributes
    ----------
    rx : ``In(1)``
        The serial line (idle high); synchronized inside.
    data : ``Out(stream.Signature(8))``
        A received byte; ``ready`` is ignored.
    error : ``Out(1)``
        A framing error (stop bit 0): the byte was dropped.
    active : ``Out(1)``
        A byte is being received.
    """

    def __init__(self, *, clocks_per_bit: int) -> None:
        self._cpb = check_clocks_per_bit(clocks_per_bit)
        super().__init__(
            {"rx": In(1, init=1), "data": Out(stream.Signature(8)), "error": Out(1), "active": Out(1)}
        )

    @property
    def clocks_per_bit(self) -> int:
        return self._cpb

    def elaborate(self, platform: object) -> Module:
        m = Module()
        cpb = self._cpb
        rx = Signal(init=1)
        m.submodules.sync = FFSynchronizer(self.rx, rx, init=1)
        timer = Signal(range(cpb))
        bit = Signal(range(9))
        shift = Signal(8)
        m.d.sync += [self.data.valid.eq(0), self.error.eq(0)]
        with m.FSM():
            with m.State("IDLE"):
                with m.If(~rx):
                    m.d.sync += timer.eq(cpb // 2 - 1)
                    m.next = "START"
            with m.State("START"):
                m.d.comb += self.active.eq(1)
                with m.If(timer != 0):
                    m.d.sync += timer.eq(timer - 1)
                with m.Elif(rx):  # a glitch, not a start bit
                    m.next = "IDLE"
                with m.Else():
                    m.d.sync += [timer.eq(cpb - 1), bit.eq(0)]
                    m.next = "DATA"
            with m.State("DATA"):
                m.d.comb += self.active.eq(1)
                with m.If(timer != 0):
                    m.d.sync += timer.eq(timer - 1)
                with m.Else():
                    m.d.sync += [timer.eq(cpb - 1), shift.eq(Cat(shift[1:], rx))]
                    with m.If(bit == 7):
                        m.next = "STOP"
                    with m.Else():
                        m.d.sync += bit.eq(bit + 1)
            with m.State("STOP"):
                m.d.comb += self.active.eq(1)
                with m.If(timer != 0):
                    m.d.sync += timer.eq(timer - 1)
                with m.Else():
                    with m.If(rx):
                        m.d.sync += [self.data.payload.eq(shift), self.data.valid.eq(1)]
                        m.next = "IDLE"
                    with m.Else():
                        m.d.sync += self.error.eq(1)
                        m.next = "BREAK"
            with m.State("BREAK"):  # wait for the line to go idle again
                with m.If(rx):
                    m.next = "IDLE"
        return m


class UARTTx(wiring.Component):
    """Bytes in (a stream), the serial line out.

    Parameters
    ----------
    clocks_per_bit : int
        Clock cycles per bit (4 .. 65536).

    Attributes
    ----------
    data : ``In(stream.Signature(8))``
        The bytes to send; taken when the transmitter is idle.
    tx : ``Out(1)``
        The serial line (idle high).
    active : ``Out(1)``
        A byte is being sent.
    """

    def __init__(self, *, clocks_per_bit: int) -> None:
        self._cpb = check_clocks_per_bit(clocks_per_bit)
        super().__init__({"data": In(stream.Signature(8)), "tx": Out(1, init=1), "active": Out(1)})

    @property
    def clocks_per_bit(self) -> int:
        return self._cpb

    def elaborate(self, platform: object) -> Module:
        m = Module()
        cpb = self._cpb
        timer = Signal(range(cpb))
        bits = Signal(range(11))  # bits left to send: start, 8 data, stop
        shift = Signal(10, init=0x3FF)
        m.d.comb += [self.tx.eq(shift[0]), self.active.eq(bits != 0)]
        m.d.comb += self.data.ready.eq(bits == 0)
        with m.If(bits == 0):
            with m.If(self.data.valid):
                m.d.sync += [shift.eq(1 << 9 | self.data.payload << 1), bits.eq(10), timer.eq(cpb - 1)]
        with m.Elif(timer != 0):
            m.d.sync += timer.eq(timer - 1)
        with m.Else():
            m.d.sync += [shift.eq(1 << 9 | shift >> 1), bits.eq(bits - 1), timer.eq(cpb - 1)]
        return m
