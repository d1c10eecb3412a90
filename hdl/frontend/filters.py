"""The paper's three 5x5 features as exact integer sums, one window per column taken.

For each 5-high column of 8-bit pixels the filter keeps two per-column values in a 5-deep
shift register: ``s`` = the column's sum and ``v`` = its two bottom pixels minus its two top
ones. A column is summed in two registered steps: its two top pixels, its middle one and its
two bottom ones into registers (``load``), then ``s`` and ``v`` from those into the shift
register (``en``), so a block RAM's slow output feeds one adder, not the whole column sum. The
window ending at the last column shifted in then gives, as ``host.features`` computes them (its
``feature_sums`` is this block's twin):

* ``m25``  = Σ s over the 5 columns                        (0 .. 6375)
* ``gh20`` = s[3] + s[4] - s[0] - s[1]  (columns, 0 oldest) (-2550 .. 2550)
* ``gv20`` = Σ v over the 5 columns                        (-2550 .. 2550)

With ``lag`` = 1 (a 7x7 census beside the features: its window's centre is a column behind the
5x5 window's) the register is one deeper and the sums are those of the window ending at the
column before the last one shifted in.
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal, signed, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int

from .linebuffer import WINDOW

__all__ = ["FeatureFilter", "feature_layout"]


def feature_layout(census_bits: int = 0) -> data.StructLayout:
    """One pixel's feature sums (the widths hold every 8-bit window exactly), and with
    ``census_bits`` > 0 its census code (``census``)."""
    fields = {"m25": unsigned(13), "gh20": signed(13), "gv20": signed(13)}
    if census_bits:
        fields["census"] = unsigned(census_bits)
    return data.StructLayout(fields)


class FeatureFilter(wiring.Component):
    """Feature sums of one image's 5x5 windows.

    Parameters
    ----------
    lag : int
        0 (default): the window ends at the last column shifted in; 1: at the one before.

    Attributes
    ----------
    load : ``In(1)``
        Take ``column`` into the partial-sum registers.
    column : ``In(ArrayLayout(unsigned(8), 5))``
        A 5-high column of gray levels, index 0 the top line.
    en : ``In(1)``
        Shift the column last loaded (in an earlier cycle) into the window.
    features : ``Out(feature_layout())``
        The sums of the window of the last five columns shifted in (combinational from the
        shift register, valid from the cycle after ``en``).

    A pipeline loads a column in the cycle it advances into the stage before the filter, and
    shifts it in when it advances out of that stage; ``load`` and ``en`` in the same cycle shift
    the earlier column in while loading the next.
    """

    def __init__(self, *, lag: int = 0) -> None:
        self._lag = as_int("lag", lag, 0, 1)
        super().__init__({
            "load": In(1),
            "column": In(data.ArrayLayout(unsigned(8), WINDOW)),
            "en": In(1),
            "features": Out(feature_layout()),
        })

    @property
    def lag(self) -> int:
        return self._lag

    def elaborate(self, platform: object) -> Module:
        m = Module()
        col = self.column
        depth = WINDOW + self._lag
        # Partial sums (reset-less: a column is loaded before it is shifted in).
        top = Signal(unsigned(9), reset_less=True)  # lines 0 + 1
        mid = Signal(unsigned(8), reset_less=True)  # line 2
        bottom = Signal(unsigned(9), reset_less=True)  # lines 3 + 4
        with m.If(self.load):
            m.d.sync += [top.eq(col[0] + col[1]), mid.eq(col[2]), bottom.eq(col[3] + col[4])]
        s_in = Signal(unsigned(11))
        v_in = Signal(signed(11))
        m.d.comb += [s_in.eq(top + mid + bottom), v_in.eq(bottom - top)]
        s = [Signal(unsigned(11), name=f"s{i}") for i in range(depth)]  # s[0]: oldest column
        v = [Signal(signed(11), name=f"v{i}") for i in range(depth)]
        with m.If(self.en):
            m.d.sync += [s[i].eq(s[i + 1]) for i in range(depth - 1)]
            m.d.sync += [v[i].eq(v[i + 1]) for i in range(depth - 1)]
            m.d.sync += [s[-1].eq(s_in), v[-1].eq(v_in)]
        f = self.features
        m.d.comb += [
            f.m25.eq(s[0] + s[1] + s[2] + s[3] + s[4]),
            f.gh20.eq((s[3] + s[4]) - (s[0] + s[1])),
            f.gv20.eq(v[0] + v[1] + v[2] + v[3] + v[4]),
        ]
        return m
