"""The paper's three 5x5 feature filters, computed exactly from integer sums.

Maps cover the model's map grid (``bayesmachine.region``): (H-2k, W-2k) pixels for a model of margin
k (``ModelParams.margin``: 2 for the paper model, 3 with a 7x7 census column), map pixel (y, x)
centred on image pixel (y+k, x+k). We keep integer multiples of the features so that costs
are exact:

* ``m25``  = 25 * m  = sum of the 5x5 window                      (0 .. 6375)
* ``gh20`` = 20 * gH = two rightmost columns - two leftmost columns (-2550 .. 2550)
* ``gv20`` = 20 * gV = two bottom rows - two top rows               (-2550 .. 2550)

With a census column (:func:`model_features`), ``census`` holds each map pixel's census code
(uint64) on the same grid. The code of the w x w window (w = 7 or 5, r = w // 2) centred on
the map pixel: bit k (k = 0 is the least significant) is 1 when the k-th neighbour is darker
than the centre (``neighbour < centre``), the neighbours taken in raster order of the window
(offsets (dy, dx) = (-r, -r), (-r, -r+1), ..., (r, r), the centre skipped): 48 bits for 7x7,
24 for 5x5. The grid's margin is at least r, so every window lies inside the image: no bit
reads outside it (the on-chip front end could not complete a window past a frame's last line).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.columns import CENSUS_WINDOWS, MAX_ABS, SCALES
from bayesmachine.models import ModelParams
from bayesmachine.region import FILTER_SIZE, MARGIN

__all__ = [
    "FeatureSums",
    "SCALES",
    "MAX_ABS",
    "feature_sums",
    "feature_sums_plain",
    "census_offsets",
    "census_codes",
    "census_codes_plain",
    "grid_margin",
    "model_features",
]


@dataclass(frozen=True)
class FeatureSums:
    """Integer feature maps of one image on its map grid, each (H-2k, W-2k) int32 for margin k;
    ``census`` the same shape, uint64, or None."""

    m25: np.ndarray
    gh20: np.ndarray
    gv20: np.ndarray
    census: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.m25.shape  # type: ignore[return-value]

    @property
    def g20(self) -> np.ndarray:
        """The gradient magnitude |gh20| + |gv20| (the ``GradMag`` column's plane), int32."""
        return np.abs(self.gh20) + np.abs(self.gv20)

    def as_tuple(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.m25, self.gh20, self.gv20

    def band(self, rows: slice) -> FeatureSums:
        """The maps of map rows ``rows`` (views: a band costs no copy)."""
        census = self.census[rows] if self.census is not None else None
        return FeatureSums(self.m25[rows], self.gh20[rows], self.gv20[rows], census)


def feature_sums(image: np.ndarray, census_window: int | None = None) -> FeatureSums:
    """m, gH, gV sums of an (H, W) uint8 image with separable running sums (+ census codes if asked).

    The maps cover the grid of margin :func:`grid_margin` ``(census_window)``: (H-4, W-4) without a
    census or with a 5x5 one, (H-6, W-6) with a 7x7 census (the 5x5 sums around the same centres)."""
    img = np.asarray(image, dtype=np.int32)
    k = FILTER_SIZE
    margin = grid_margin(census_window)
    if img.ndim != 2 or img.shape[0] < 2 * margin + 1 or img.shape[1] < 2 * margin + 1:
        size = 2 * margin + 1
        raise ValueError(f"image of shape {img.shape} is too small for the {size}x{size} windows")
    # Column sums over 5 rows: cols5[y, x] = sum img[y:y+5, x]; (H-4, W).
    c = np.cumsum(img, axis=0)
    cols5 = c[k - 1 :].copy()
    cols5[1:] -= c[:-k]
    # Row sums over 5 columns: rows5[y, x] = sum img[y, x:x+5]; (H, W-4).
    r = np.cumsum(img, axis=1)
    rows5 = r[:, k - 1 :].copy()
    rows5[:, 1:] -= r[:, :-k]
    w4 = img.shape[1] - (k - 1)
    h4 = img.shape[0] - (k - 1)
    m25 = sum(cols5[:, j : w4 + j] for j in range(k))
    gh20 = (cols5[:, 3 : w4 + 3] + cols5[:, 4 : w4 + 4]) - (cols5[:, 0:w4] + cols5[:, 1 : w4 + 1])
    gv20 = (rows5[3 : h4 + 3] + rows5[4 : h4 + 4]) - (rows5[0:h4] + rows5[1 : h4 + 1])
    inset = margin - MARGIN  # the 5x5 grid cut to the model's
    cut = (slice(inset, h4 - inset), slice(inset, w4 - inset))
    return FeatureSums(
        np.ascontiguousarray(m25[cut], dtype=np.int32),
        np.ascontiguousarray(gh20[cut], dtype=np.int32),
        np.ascontiguousarray(gv20[cut], dtype=np.int32),
        census_codes(image, census_window) if census_window is not None else None,
    )


def grid_margin(census_window: int | None) -> int:
    """The map grid's margin for features with a ``census_window`` census (None: the 5x5 filters')."""
    return MARGIN if census_window is None else max(MARGIN, census_window // 2)


def model_features(image: np.ndarray, model: ModelParams) -> FeatureSums:
    """The planes every pass of ``model`` reads, on its map grid (margin ``model.margin``): the paper's
    three sums, and the census codes of a census column's window."""
    windows = {c.window for p in model.passes for c in p.columns if c.plane == "census"}
    return feature_sums(image, windows.pop() if windows else None)


def census_offsets(window: int) -> list[tuple[int, int]]:
    """The neighbours (dy, dx) of a ``window`` x ``window`` census, in bit order (bit k = entry k)."""
    if window not in CENSUS_WINDOWS:
        raise ValueError(f"census window must be one of {CENSUS_WINDOWS}, got {window!r}")
    r = window // 2
    return [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1) if (dy, dx) != (0, 0)]


def census_codes(image: np.ndarray, window: int) -> np.ndarray:
    """Census codes, uint64, of an (H, W) image on the map grid of margin ``grid_margin(window)``:
    (H-4, W-4) for 5x5, (H-6, W-6) for 7x7 (see the module's text); every window inside the image."""
    offsets = census_offsets(window)
    img = np.asarray(image)
    k = grid_margin(window)
    if img.ndim != 2 or img.shape[0] < 2 * k + 1 or img.shape[1] < 2 * k + 1:
        raise ValueError(f"image of shape {img.shape} is too small for the {2 * k + 1}x{2 * k + 1} windows")
    src = img.astype(np.int16)
    h, w = img.shape[0] - 2 * k, img.shape[1] - 2 * k
    centre = src[k : k + h, k : k + w]
    codes = np.zeros((h, w), dtype=np.uint64)
    for bit, (dy, dx) in enumerate(offsets):
        nb = src[k + dy : k + dy + h, k + dx : k + dx + w]
        codes |= (nb < centre).astype(np.uint64) << np.uint64(bit)
    return codes


def census_codes_plain(image: np.ndarray, window: int) -> np.ndarray:
    """The same codes pixel by pixel in plain Python (a test oracle)."""
    img = np.asarray(image)
    h, w = img.shape
    k = grid_margin(window)
    offsets = census_offsets(window)
    out = np.zeros((h - 2 * k, w - 2 * k), dtype=np.uint64)
    for y in range(out.shape[0]):
        for x in range(out.shape[1]):
            cy, cx = y + k, x + k
            code = 0
            for bit, (dy, dx) in enumerate(offsets):
                if int(img[cy + dy, cx + dx]) < int(img[cy, cx]):
                    code |= 1 << bit
            out[y, x] = code
    return out


# The 5x5 kernels, as correlation weights (row = y, column = x), times the feature scale.
KERNELS = {
    "m": np.ones((5, 5), dtype=np.int64),
    "gh": np.tile(np.array([-1, -1, 0, 1, 1], dtype=np.int64), (5, 1)),
    "gv": np.tile(np.array([-1, -1, 0, 1, 1], dtype=np.int64)[:, None], (1, 5)),
}


def feature_sums_plain(image: np.ndarray) -> FeatureSums:
    """The same maps by direct window-by-window correlation with the kernels (a test oracle)."""
    img = np.asarray(image, dtype=np.int64)
    h4, w4 = img.shape[0] - 4, img.shape[1] - 4
    windows = np.lib.stride_tricks.sliding_window_view(img, (5, 5))[:h4, :w4]
    out = [np.einsum("yxij,ij->yx", windows, KERNELS[f]).astype(np.int32) for f in ("m", "gh", "gv")]
    return FeatureSums(*out)
