"""The output region: which pixels get a disparity, in every coordinate system the host uses.

A model's output region is where every one of its windows lies inside the image. Its
``margin`` (``ModelParams.margin``) is the half-size of its largest window: 2 for the paper's
5x5 filters (and the census model's 5x5 census), 3 for the 7x7 census. The feature maps cover
the "map" grid of (H-2·margin)x(W-2·margin) pixels, map pixel (y, x) centred on image pixel
(y+margin, x+margin), so no feature, census bit included, ever reads outside the image. Costs
for every d in 0..Dmax exist for map columns x >= Dmax, so the output region is map rows
0..H-2·margin-1 x map columns Dmax..W-2·margin-1: (H-2·margin)x(W-2·margin-Dmax) pixels in
row-major order, image rows margin..H-1-margin x columns Dmax+margin..W-1-margin (margin 2:
rows 2..H-3, columns Dmax+2..W-3, the paper's, bit for bit as before margins existed).

Why the census model does not read past the image (a neighbour outside read as "not darker"):
the on-chip front end cannot know a frame's last line (a frame has any number of lines), so a
window reaching past the bottom line could never be completed there.
Features, likelihoods, reference, metrics and plots all take the geometry from here.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from bayesmachine.checks import as_int

__all__ = ["CAMERA_FPS", "FILTER_SIZE", "MARGIN", "VGA_HEIGHT", "VGA_WIDTH", "OutputRegion"]

# The paper's three features are 5x5 correlations: maps lose 2 pixels on every side (the paper
# model's margin; a model's own is ``ModelParams.margin``).
FILTER_SIZE = 5
MARGIN = FILTER_SIZE // 2
# A VGA frame, the frame the frame rates are given for (synth's report, its measured frame).
VGA_WIDTH, VGA_HEIGHT = 640, 480
# Camera rate: the frames per second a design is measured against (synth reports the clock it needs).
CAMERA_FPS = 60

# Output pixels per band when the host streams over rows: a float64 posterior band of
# Dmax 80 is then ~43 MB, whatever the frame size.
BAND_PIXELS = 1 << 16


@dataclass(frozen=True)
class OutputRegion:
    """Geometry of the output region of an ``image_height`` x ``image_width`` pair at ``dmax``,
    whose model's windows reach ``margin`` pixels from their centre (``ModelParams.margin``)."""

    image_height: int
    image_width: int
    dmax: int
    margin: int = MARGIN

    def __post_init__(self) -> None:
        # An integer as bayesmachine.checks takes it (np.int64(3) is 3), at least the 5x5 filters'.
        object.__setattr__(self, "margin", as_int("margin", self.margin, MARGIN))
        size = 2 * self.margin + 1
        if self.image_height < size or self.image_width < size:
            raise ValueError(
                f"images of {self.image_width}x{self.image_height} are too small for the model's "
                f"{size}x{size} windows (need at least {size}x{size})"
            )
        usable = self.image_width - 2 * self.margin
        if self.dmax >= usable:
            raise ValueError(
                f"dmax ({self.dmax}) must be below the usable width ({usable} = image width "
                f"{self.image_width} - {2 * self.margin}): no pixel would have all {self.dmax + 1} "
                "disparities; "
                f"use a wider image or a smaller --dmax"
            )

    @classmethod
    def of_image(cls, shape: tuple[int, ...], dmax: int, margin: int = MARGIN) -> OutputRegion:
        return cls(int(shape[0]), int(shape[1]), dmax, margin)

    @classmethod
    def of_model(cls, shape: tuple[int, ...], model: object) -> OutputRegion:
        """The output region of ``model`` (a ``ModelParams``: its ``dmax`` and ``margin``) on images of
        ``shape``."""
        return cls(int(shape[0]), int(shape[1]), model.dmax, model.margin)  # type: ignore[attr-defined]

    @classmethod
    def of_features(cls, shape: tuple[int, ...], dmax: int, margin: int = MARGIN) -> OutputRegion:
        """From the (H-2·margin, W-2·margin) shape of the feature maps (the map grid)."""
        return cls(int(shape[0]) + 2 * margin, int(shape[1]) + 2 * margin, dmax, margin)

    @property
    def feature_shape(self) -> tuple[int, int]:
        """The map grid: (H-2·margin, W-2·margin)."""
        return self.image_height - 2 * self.margin, self.image_width - 2 * self.margin

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
        """The output columns as a slice of feature-map columns (Dmax .. W-2·margin-1)."""
        return slice(self.dmax, self.feature_shape[1])

    @property
    def map_columns(self) -> np.ndarray:
        """Feature-map column of each output column (Dmax .. W-2·margin-1)."""
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
        k = self.margin
        return array[k : h - k, k + self.dmax : w - k]

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
