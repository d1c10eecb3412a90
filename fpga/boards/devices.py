"""The ULX3S boards the flow builds for and the ECP5 PLL's dividers of a clock (no Amaranth here: the
command line lists the boards without importing the RTL; :mod:`.ulx3s` is the board top)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BOARDS", "CLK_IN_MHZ", "Board", "PLLConfig", "get_board", "pll_config"]


@dataclass(frozen=True)
class Board:
    name: str
    platform: str  # the amaranth_boards.ulx3s class
    device: str


BOARDS = {
    b.name: b
    for b in (
        Board("ulx3s-85f", "ULX3S_85F_Platform", "LFE5U-85F"),
        Board("ulx3s-45f", "ULX3S_45F_Platform", "LFE5U-45F"),
        Board("ulx3s-25f", "ULX3S_25F_Platform", "LFE5U-25F"),
        Board("ulx3s-12f", "ULX3S_12F_Platform", "LFE5U-12F"),
    )
}

CLK_IN_MHZ = 25.0


def get_board(name: str) -> Board:
    try:
        return BOARDS[name]
    except KeyError:
        raise ValueError(f"unknown board {name!r}; choose one of {', '.join(BOARDS)}") from None


@dataclass(frozen=True)
class PLLConfig:
    clki_div: int
    clkfb_div: int
    clkop_div: int

    @property
    def vco_mhz(self) -> float:
        return CLK_IN_MHZ / self.clki_div * self.clkfb_div * self.clkop_div

    @property
    def out_mhz(self) -> float:
        return CLK_IN_MHZ / self.clki_div * self.clkfb_div


def pll_config(freq_mhz: float) -> PLLConfig:
    """The EHXPLLL dividers nearest ``freq_mhz`` from 25 MHz (PFD >= 3.125 MHz, VCO 400..800 MHz,
    feedback from CLKOP)."""
    if not 10.0 <= freq_mhz <= 200.0:
        raise ValueError(f"the clock must be in [10, 200] MHz, got {freq_mhz:g}")
    best: tuple[float, PLLConfig] | None = None
    for clki in range(1, 129):
        pfd = CLK_IN_MHZ / clki
        if pfd < 3.125:
            break
        for fb in range(1, 81):
            out = pfd * fb
            for op in range(1, 129):
                vco = out * op
                if 400.0 <= vco <= 800.0:
                    err = abs(out - freq_mhz)
                    if best is None or err < best[0] - 1e-9:
                        best = (err, PLLConfig(clki, fb, op))
                    break
    assert best is not None
    return best[1]
