"""The ULX3S top: :class:`~.core.BoardCore` on the board's FTDI UART, its 25 MHz clock through the
ECP5 PLL (``EHXPLLL``) to the design's clock, status on the LEDs, FIRE1 as reset.

LEDs 0-4 are the core's (frame in progress, last frame failed, byte received, byte sent, receive
overflow); LED 7 blinks at about 1 Hz while the clock runs and the PLL is locked.
"""

from __future__ import annotations

from amaranth.hdl import ClockDomain, Instance, Module, Signal
from amaranth.lib import io, wiring
from amaranth.lib.cdc import ResetSynchronizer

from .core import BoardCore
from .devices import CLK_IN_MHZ, PLLConfig

__all__ = ["ULX3STop"]


class ULX3STop(wiring.Component):
    """The board top (no ports: its pins are the platform's resources).

    Parameters
    ----------
    core : BoardCore
        The design behind the UART.
    pll : PLLConfig
        The PLL's dividers (the core's clock).
    """

    def __init__(self, *, core: BoardCore, pll: PLLConfig) -> None:
        if not isinstance(core, BoardCore):
            raise TypeError(f"core must be a BoardCore, not {type(core).__name__}")
        if not isinstance(pll, PLLConfig):
            raise TypeError(f"pll must be a PLLConfig, not {type(pll).__name__}")
        self._core, self._pll = core, pll
        super().__init__({})

    @property
    def core(self) -> BoardCore:
        return self._core

    @property
    def pll(self) -> PLLConfig:
        return self._pll

    def elaborate(self, platform) -> Module:  # noqa: ANN001 - an amaranth_boards platform
        m = Module()
        pll, freq = self._pll, self._pll.out_mhz
        # The pins as ports (dir="-") behind amaranth.lib.io buffers; a port carries its pin's inversion.
        m.submodules.clk25 = clk25 = io.Buffer("i", platform.request("clk25", 0, dir="-"))
        locked = Signal()
        m.domains.sync = cd_sync = ClockDomain("sync")
        m.submodules.pll = Instance(
            "EHXPLLL",
            p_PLLRST_ENA="DISABLED",
            p_INTFB_WAKE="DISABLED",
            p_STDBY_ENABLE="DISABLED",
            p_DPHASE_SOURCE="DISABLED",
            p_OUTDIVIDER_MUXA="DIVA",
            p_OUTDIVIDER_MUXB="DIVB",
            p_OUTDIVIDER_MUXC="DIVC",
            p_OUTDIVIDER_MUXD="DIVD",
            p_CLKI_DIV=pll.clki_div,
            p_CLKOP_ENABLE="ENABLED",
            p_CLKOP_DIV=pll.clkop_div,
            p_CLKOP_CPHASE=pll.clkop_div - 1,
            p_CLKOP_FPHASE=0,
            p_FEEDBK_PATH="CLKOP",
            p_CLKFB_DIV=pll.clkfb_div,
            i_RST=0,
            i_STDBY=0,
            i_CLKI=clk25.i,
            o_CLKOP=cd_sync.clk,
            i_CLKFB=cd_sync.clk,
            i_PHASESEL0=0,
            i_PHASESEL1=0,
            i_PHASEDIR=1,
            i_PHASESTEP=1,
            i_PHASELOADREG=1,
            i_PLLWAKESYNC=0,
            i_ENCLKOP=0,
            o_LOCK=locked,
            a_FREQUENCY_PIN_CLKI=f"{CLK_IN_MHZ:g}",
            a_FREQUENCY_PIN_CLKOP=f"{freq:g}",
            a_ICP_CURRENT="12",
            a_LPF_RESISTOR="8",
            a_MFG_ENABLE_FILTEROPAMP="1",
            a_MFG_GMCREF_SEL="2",
        )
        platform.add_clock_constraint(cd_sync.clk, freq * 1e6)
        m.submodules.button = button = io.Buffer("i", platform.request("button_fire", 0, dir="-"))
        m.submodules.reset_sync = ResetSynchronizer(~locked | button.i, domain="sync")

        m.submodules.core = core = self._core
        uart = platform.request("uart", 0, dir="-")
        m.submodules.uart_rx = uart_rx = io.Buffer("i", uart.rx)
        m.submodules.uart_tx = uart_tx = io.Buffer("o", uart.tx)
        m.d.comb += [core.rx.eq(uart_rx.i), uart_tx.o.eq(core.tx)]
        beat = Signal(range(int(freq * 1e6 / 2) + 1))
        heartbeat = Signal()
        with m.If(beat == int(freq * 1e6 / 2)):
            m.d.sync += [beat.eq(0), heartbeat.eq(~heartbeat)]
        with m.Else():
            m.d.sync += beat.eq(beat + 1)
        for i in range(8):
            m.submodules[f"led{i}"] = led = io.Buffer("o", platform.request("led", i, dir="-"))
            m.d.comb += led.o.eq(heartbeat if i == 7 else core.leds[i])
        return m
