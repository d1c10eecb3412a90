"""Line buffers for the windows: the ``height - 1`` previous lines of both images in one ``Memory``.

For each incoming pixel pair at column ``col`` the block outputs, one cycle later, its
``height``-high column (5 for the paper's 5x5 filters, 7 with a 7x7 census): the pixels of the
lines above it at that column (from the memory) and the pixel itself. The memory word at
``col`` holds the pair's last lines at that column; it is read
when the pixel comes in and written back, shifted by one line, in the next cycle. A read port
with an enable and a write port on one address space: block RAM on an FPGA.
"""

from __future__ import annotations

import numpy as np
from amaranth.hdl import Module, Signal, unsigned
from amaranth.lib import data, memory, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int

__all__ = ["WINDOW", "LineBuffer", "column_windows", "pair_layout"]

WINDOW = 5  # the paper's 5x5 filters


def pair_layout() -> data.StructLayout:
    """A rectified pixel pair: 8-bit left and right gray levels."""
    return data.StructLayout({"left": unsigned(8), "right": unsigned(8)})


class LineBuffer(wiring.Component):
    """``height - 1`` lines of pixel pairs, ``width`` pixels each.

    Two pixels taken at the same column must be at least two cycles apart: guaranteed for
    raster order and width >= 2.

    Parameters
    ----------
    width : int
        Pixels per line (>= 2).
    height : int
        The column's height, the windows' (``WINDOW`` = 5 by default; 7 for a 7x7 census).

    Attributes
    ----------
    en : ``In(1)``
        Take ``pixel`` at column ``col``.
    col : ``In(range(width))``
        The column of the pixel taken.
    pixel : ``In(pair_layout())``
        The pixel pair taken.
    column : ``Out(ArrayLayout(pair_layout(), height))``
        From the cycle after ``en`` until the next ``en``, the ``height``-high column of the last
        pixel taken (index 0 = ``height - 1`` lines up, the last index = the pixel). Columns of a
        frame's first ``height - 1`` lines hold older data.
    """

    def __init__(self, *, width: int, height: int = WINDOW) -> None:
        self._width = width = as_int("width", width, 2)
        self._height = height = as_int("height", height, 3)
        super().__init__({
            "en": In(1),
            "col": In(range(width)),
            "pixel": In(pair_layout()),
            "column": Out(data.ArrayLayout(pair_layout(), height)),
        })

    @property
    def width(self) -> int:
        return self._width

    @property
    def height(self) -> int:
        return self._height

    def elaborate(self, platform: object) -> Module:
        m = Module()
        n = self._height
        lines = data.ArrayLayout(pair_layout(), n - 1)
        m.submodules.mem = mem = memory.Memory(shape=lines, depth=self._width, init=[])
        rd = mem.read_port()
        wr = mem.write_port()
        pixel_q = Signal(pair_layout())
        col_q = Signal(range(self._width))
        write = Signal()
        m.d.comb += [rd.en.eq(self.en), rd.addr.eq(self.col)]
        m.d.sync += write.eq(self.en)
        with m.If(self.en):
            m.d.sync += [pixel_q.eq(self.pixel), col_q.eq(self.col)]
        # Write back the column shifted up by one line, the new pixel at the bottom.
        m.d.comb += [wr.en.eq(write), wr.addr.eq(col_q)]
        for i in range(n - 2):
            m.d.comb += wr.data[i].eq(rd.data[i + 1])
        m.d.comb += wr.data[n - 2].eq(pixel_q)
        for i in range(n - 1):
            m.d.comb += self.column[i].eq(rd.data[i])
        m.d.comb += self.column[n - 1].eq(pixel_q)
        return m


def column_windows(image: np.ndarray, height: int = WINDOW) -> np.ndarray:
    """Twin: the ``height``-high column of every pixel at or below line ``height - 1``, shape
    (H - height + 1, W, height), index 0 oldest."""
    img = np.asarray(image)
    return np.lib.stride_tricks.sliding_window_view(img, height, axis=0)
