"""Image planes: what a FEATURES column (and the no-match rule) reads of both images, declared by the column.

A :class:`Plane` is named (the name a column's ``plane`` gives), made by its filter from a gray image,
over ``window`` x ``window`` windows: the filter's plane of an (H, W) image is (H - 2r, W - 2r), r =
``window // 2``, plane pixel (y, x) centred on image pixel (y + r, x + r). A model's planes
(``ModelParams.planes``) are the ones its passes' columns declare, and its map grid's margin is their
largest r (``ModelParams.margin``); :meth:`Plane.on_grid` cuts a plane to that grid, so every window
lies inside the image. The host computes exactly a model's planes (``host.features.model_planes``); the
on-chip front end's plane filters (``hdl.frontend.lanes``) are the RTL twins of these filters.

The filters here keep integer multiples of the paper's 5x5 features, so that costs are exact:

* ``m25``  = 25 * m  = sum of the 5x5 window                        (0 .. 6375)
* ``gh20`` = 20 * gH = two rightmost columns - two leftmost columns  (-2550 .. 2550)
* ``gv20`` = 20 * gV = two bottom rows - two top rows                (-2550 .. 2550)
* ``g20``  = |gh20| + |gv20|, the gradient magnitude                 (0 .. 5100)

and the census codes (:mod:`.census`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["Plane", "SUM_WINDOW", "mean_sums", "hgrad_sums", "vgrad_sums", "gradmag_sums", "SUM_PLANES",
           "G20"]

# The paper's features are sums over 5x5 windows.
SUM_WINDOW = 5


@dataclass(frozen=True)
class Plane:
    """One image plane: ``name``, ``window`` (the odd side of its filter's windows) and ``filter`` (a gray
    (H, W) image -> its (H - 2r, W - 2r) plane, r = window // 2). Two planes are the same plane when all
    three are equal (one filter function, one window)."""

    name: str
    window: int
    filter: Callable[[np.ndarray], np.ndarray]

    @property
    def margin(self) -> int:
        """Pixels from a window's centre to its edge."""
        return self.window // 2

    def on_grid(self, image: np.ndarray, margin: int) -> np.ndarray:
        """The plane of ``image`` on the map grid of ``margin`` (>= this plane's): (H - 2 margin,
        W - 2 margin), map pixel (y, x) centred on image pixel (y + margin, x + margin)."""
        own = self.filter(image)
        inset = margin - self.margin
        if inset < 0:
            raise ValueError(f"plane {self.name}: a grid of margin {margin} is inside its {self.window}x"
                             f"{self.window} windows' margin {self.margin}")
        h, w = own.shape
        return np.ascontiguousarray(own[inset : h - inset, inset : w - inset])


def _column_sums(img: np.ndarray) -> np.ndarray:
    """cols5[y, x] = sum img[y:y+5, x]: (H-4, W), by a running sum."""
    c = np.cumsum(img, axis=0)
    cols = c[SUM_WINDOW - 1 :].copy()
    cols[1:] -= c[:-SUM_WINDOW]
    return cols


def _row_sums(img: np.ndarray) -> np.ndarray:
    """rows5[y, x] = sum img[y, x:x+5]: (H, W-4)."""
    r = np.cumsum(img, axis=1)
    rows = r[:, SUM_WINDOW - 1 :].copy()
    rows[:, 1:] -= r[:, :-SUM_WINDOW]
    return rows


def _gray(image: np.ndarray) -> np.ndarray:
    return np.asarray(image, dtype=np.int32)


def mean_sums(image: np.ndarray) -> np.ndarray:
    """``m25``: each 5x5 window's sum, int32 (H-4, W-4)."""
    cols = _column_sums(_gray(image))
    w4 = cols.shape[1] - (SUM_WINDOW - 1)
    return sum(cols[:, j : w4 + j] for j in range(SUM_WINDOW)).astype(np.int32)  # type: ignore[union-attr]


def hgrad_sums(image: np.ndarray) -> np.ndarray:
    """``gh20``: the window's two right columns minus its two left ones, int32 (H-4, W-4)."""
    cols = _column_sums(_gray(image))
    w4 = cols.shape[1] - (SUM_WINDOW - 1)
    right = cols[:, 3 : w4 + 3] + cols[:, 4 : w4 + 4]
    return (right - (cols[:, 0:w4] + cols[:, 1 : w4 + 1])).astype(np.int32)


def vgrad_sums(image: np.ndarray) -> np.ndarray:
    """``gv20``: the window's two bottom rows minus its two top ones, int32 (H-4, W-4)."""
    rows = _row_sums(_gray(image))
    h4 = rows.shape[0] - (SUM_WINDOW - 1)
    return ((rows[3 : h4 + 3] + rows[4 : h4 + 4]) - (rows[0:h4] + rows[1 : h4 + 1])).astype(np.int32)


def gradmag_sums(image: np.ndarray) -> np.ndarray:
    """``g20``: |gh20| + |gv20|, int32 (H-4, W-4)."""
    return (np.abs(hgrad_sums(image)) + np.abs(vgrad_sums(image))).astype(np.int32)


# The paper's three feature planes, by feature, and the gradient magnitude's.
SUM_PLANES = {"m": Plane("m25", SUM_WINDOW, mean_sums), "gh": Plane("gh20", SUM_WINDOW, hgrad_sums),
              "gv": Plane("gv20", SUM_WINDOW, vgrad_sums)}
G20 = Plane("g20", SUM_WINDOW, gradmag_sums)
