"""The output region: which pixels get a disparity, in every coordinate system the host uses.

The features are 5x5 correlations over the valid region, (H-4)x(W-4) "map" pixels, map
pixel (y, x) centred on image pixel (y+2, x+2). Costs for every d in 0..Dmax exist for map
columns x >= Dmax, so the output region is map rows 0..H-5 x map columns Dmax..W-5:
(H-4)x(W-4-Dmax) pixels in row-major order, image rows 2..H-3 x columns Dmax+2..W-3.
Features, likelihoods, reference, metrics and plots all take the geometry from here.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

__all__ = ["FILTER_SIZE", "MARGIN", "OutputRegion"]

# The paper's three features are 5x5 correlations: maps lose 2 pixels on every side.
FILTER_SIZE = 5
MARGIN = FILTER_SIZE // 2

# Output pixels per band when the host streams over rows: a float64 posterior band of
# Dmax 80 is then ~43 MB, whatever the frame size.
BAND_PIXELS = 1 << 16


@dataclass(frozen=True)
class OutputRegion:
    """Geometry of the output region of an ``image_height`` x ``image_width`` pair at ``dmax``."""

    image_height: int
    image_width: int
    dmax: int

    def __post_init__(self) -> None:
        if self.image_height < FILTER_SIZE or self.image_width < FILTER_SIZE:
            raise ValueError(
                f"images of {self.image_width}x{self.image_height} are too small for the "
                f"{FILTER_SIZE}x{FILTER_SIZE} filters (need at least {FILTER_SIZE}x{FILTER_SIZE})"
            )
        usable = self.image_width - 2 * MARGIN
        if self.dmax >= usable:
            raise ValueError(
                f"dmax ({self.dmax}) must be below the usable width ({usable} = image width "
                f"{self.image_width} - {2 * MARGIN}): no pixel would have all {self.dmax + 1} disparities; "
                f"use a wider image or a smaller --dmax"
            )

    @classmethod
    def of_image(cls, shape: tuple[int, ...], dmax: int) -> OutputRegion:
        return cls(int(shape[0]), int(shape[1]), dmax)

    @classmethod
    def of_features(cls, shape: tuple[int, ...], dmax: int) -> OutputRegion:
        """From the (H-4, W-4) shape of the feature maps."""
        return cls(int(shape[0]) + 2 * MARGIN, int(shape[1]) + 2 * MARGIN, dmax)

    @property
    def feature_shape(self) -> tuple[int, int]:
        return self.image_height - 2 * MARGIN, self.image_width - 2 * MARGIN

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the output region."""
        h4, w4 = self.feature_shape
        return h4, w4 - self.dmax

    @property
    def pixels(self) -> int:
        h, w = self.shape
        return h * w

    @property
    def map_slice(self) -> slice:
        """The output columns as a slice of feature-map columns (Dmax .. W-5)."""
        return slice(self.dmax, self.feature_shape[1])

    @property
    def map_columns(self) -> np.ndarray:
        """Feature-map column of each output column (Dmax .. W-5)."""
        return np.arange(self.dmax, self.feature_shape[1])

    @property
    def match_columns(self) -> np.ndarray:
        """(Wo, Dmax+1): the right feature-map column x - d of each output column and disparity."""
        return self.map_columns[:, None] - np.arange(self.dmax + 1)[None, :]

    def cut(self, array: np.ndarray) -> np.ndarray:
        """An image-coordinate array (H, W, ...) cut to the output region (a view)."""
        h, w = array.shape[:2]
        if (h, w) != (self.image_height, self.image_width):
            raise ValueError(
                f"array of shape {array.shape[:2]} is not {self.image_height}x{self.image_width}"
            )
        return array[MARGIN : h - MARGIN, MARGIN + self.dmax : w - MARGIN]

    def band_rows(self, pixels: int | None = None) -> int:
        """Output rows per band: about ``pixels`` (default BAND_PIXELS) output pixels, at least one row."""
        pixels = BAND_PIXELS if pixels is None else pixels
        return max(1, pixels // max(1, self.shape[1]))

    def bands(self, rows: int | None = None) -> Iterator[slice]:
        """Slices of output rows, ``rows`` at a time (default :meth:`band_rows`), top to bottom."""
        step = rows if rows is not None else self.band_rows()
        if step < 1:
            raise ValueError(f"band rows must be >= 1, got {step}")
        h = self.shape[0]
        for y0 in range(0, h, step):
            yield slice(y0, min(h, y0 + step))
