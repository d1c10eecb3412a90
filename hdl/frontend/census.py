"""The census transform of one image's windows, one window per column taken.

For each ``window``-high column of 8-bit pixels (7 or 5) the filter keeps the last ``window``
columns in a shift register; the code of the window ending at the last column shifted in is,
as ``host.features.census_codes`` computes it (its twin): bit k set when the k-th neighbour of
the window's centre is darker than the centre (``neighbour < centre``), the neighbours in raster
order of the window (top-left first), the centre skipped: 48 bits for 7x7, 24 for 5x5.

As ``FeatureFilter``: ``load`` takes a column into a register, ``en`` shifts the column loaded
earlier into the window, so a line buffer's block RAM output feeds registers only. The code
is formed by comparators from the window's registers (combinational, valid from the cycle
after ``en``); the word generator registers it with the pixel.
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.columns import CENSUS_WINDOWS
from bayesmachine.errors import ParameterError

__all__ = ["CensusFilter", "census_bits"]


def census_bits(window: int) -> int:
    """Bits of a ``window`` x ``window`` census code: the window's neighbours of its centre."""
    return window * window - 1


class CensusFilter(wiring.Component):
    """Census codes of one image's ``window`` x ``window`` windows.

    Parameters
    ----------
    window : int
        5 or 7 (``bayesmachine.columns.CENSUS_WINDOWS``).

    Attributes
    ----------
    load : ``In(1)``
        Take ``column`` into the column register.
    column : ``In(ArrayLayout(unsigned(8), window))``
        A ``window``-high column of gray levels, index 0 the top line.
    en : ``In(1)``
        Shift the column last loaded (in an earlier cycle) into the window.
    code : ``Out(window * window - 1)``
        The census code of the window of the last ``window`` columns shifted in.
    """

    def __init__(self, *, window: int) -> None:
        window = as_int("window", window)
        if window not in CENSUS_WINDOWS:
            raise ParameterError(f"window must be one of {CENSUS_WINDOWS}, got {window}", "window")
        self._window = window
        super().__init__({
            "load": In(1),
            "column": In(data.ArrayLayout(unsigned(8), window)),
            "en": In(1),
            "code": Out(census_bits(window)),
        })

    @property
    def window(self) -> int:
        return self._window

    def elaborate(self, platform: object) -> Module:
        m = Module()
        w = self._window
        r = w // 2
        # Reset-less: a window is filled by its line's own columns before any output reads it.
        loaded = Signal(data.ArrayLayout(unsigned(8), w), reset_less=True)
        with m.If(self.load):
            m.d.sync += loaded.eq(self.column)
        cols = [Signal(data.ArrayLayout(unsigned(8), w), name=f"col{i}", reset_less=True)
                for i in range(w)]  # cols[0]: the oldest (leftmost) column
        with m.If(self.en):
            m.d.sync += [cols[i].eq(cols[i + 1]) for i in range(w - 1)]
            m.d.sync += cols[-1].eq(loaded)
        centre = cols[r][r]
        bits = [cols[r + dx][r + dy] < centre
                for dy in range(-r, r + 1) for dx in range(-r, r + 1) if (dy, dx) != (0, 0)]
        for k, bit in enumerate(bits):
            m.d.comb += self.code[k].eq(bit)
        return m
