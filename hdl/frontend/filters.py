"""The paper's three 5x5 features as exact integer sums, one window per column taken.

For each 5-high column of 8-bit pixels the filter keeps two per-column values in a 5-deep
shift register: ``s`` = the column's sum and ``v`` = its two bottom pixels minus its two top
ones. The window ending at the last column taken then gives, as ``host.features`` computes
them (its ``feature_sums`` is this block's twin):

* ``m25``  = Σ s over the 5 columns                        (0 .. 6375)
* ``gh20`` = s[3] + s[4] - s[0] - s[1]  (columns, 0 oldest) (-2550 .. 2550)
* ``gv20`` = Σ v over the 5 columns                        (-2550 .. 2550)
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal, signed, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from .linebuffer import WINDOW

__all__ = ["FeatureFilter", "feature_layout"]


def feature_layout() -> data.StructLayout:
    """One pixel's feature sums (the widths hold every 8-bit window exactly)."""
    return data.StructLayout({"m25": unsigned(13), "gh20": signed(13), "gv20": signed(13)})


class FeatureFilter(wiring.Component):
    """Feature sums of one image's 5x5 windows.

    Ports: ``en`` (In 1) and ``column`` (In, ``ArrayLayout(unsigned(8), 5)``, index 0 the top
    line): take a column; ``features`` (Out, ``feature_layout()``): the sums of the window of
    the last five columns taken (combinational from the shift register, valid from the cycle
    after ``en``).
    """

    def __init__(self) -> None:
        super().__init__({
            "en": In(1),
            "column": In(data.ArrayLayout(unsigned(8), WINDOW)),
            "features": Out(feature_layout()),
        })

    def elaborate(self, platform: object) -> Module:
        m = Module()
        col = self.column
        s_in = Signal(unsigned(11))
        v_in = Signal(signed(11))
        m.d.comb += [
            s_in.eq(col[0] + col[1] + col[2] + col[3] + col[4]),
            v_in.eq((col[3] + col[4]) - (col[0] + col[1])),
        ]
        s = [Signal(unsigned(11), name=f"s{i}") for i in range(WINDOW)]  # s[0]: oldest column
        v = [Signal(signed(11), name=f"v{i}") for i in range(WINDOW)]
        with m.If(self.en):
            m.d.sync += [s[i].eq(s[i + 1]) for i in range(WINDOW - 1)]
            m.d.sync += [v[i].eq(v[i + 1]) for i in range(WINDOW - 1)]
            m.d.sync += [s[-1].eq(s_in), v[-1].eq(v_in)]
        f = self.features
        m.d.comb += [
            f.m25.eq(s[0] + s[1] + s[2] + s[3] + s[4]),
            f.gh20.eq((s[3] + s[4]) - (s[0] + s[1])),
            f.gv20.eq(v[0] + v[1] + v[2] + v[3] + v[4]),
        ]
        return m
