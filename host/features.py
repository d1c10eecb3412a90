"""The paper's three 5x5 feature filters, computed exactly from integer sums.

Maps cover the valid region: (H-4, W-4), map pixel (y, x) centred on image pixel
(y+2, x+2). We keep integer multiples of the features so that costs are exact:

* ``m25``  = 25 * m  = sum of the 5x5 window                      (0 .. 6375)
* ``gh20`` = 20 * gH = two rightmost columns - two leftmost columns (-2550 .. 2550)
* ``gv20`` = 20 * gV = two bottom rows - two top rows               (-2550 .. 2550)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.likelihood import MAX_ABS, SCALES

from .region import FILTER_SIZE

__all__ = ["FeatureSums", "SCALES", "MAX_ABS", "feature_sums", "feature_sums_plain"]


@dataclass(frozen=True)
class FeatureSums:
    """Integer feature maps of one image, each (H-4, W-4) int32."""

    m25: np.ndarray
    gh20: np.ndarray
    gv20: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.m25.shape  # type: ignore[return-value]

    def as_tuple(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.m25, self.gh20, self.gv20

    def band(self, rows: slice) -> FeatureSums:
        """The maps of map rows ``rows`` (views: a band costs no copy)."""
        return FeatureSums(self.m25[rows], self.gh20[rows], self.gv20[rows])


def feature_sums(image: np.ndarray) -> FeatureSums:
    """m, gH, gV sums of an (H, W) uint8 image with separable running sums."""
    img = np.asarray(image, dtype=np.int32)
    if img.ndim != 2 or img.shape[0] < FILTER_SIZE or img.shape[1] < FILTER_SIZE:
        raise ValueError(f"image of shape {img.shape} is too small for the 5x5 filters")
    k = FILTER_SIZE
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
    return FeatureSums(
        np.ascontiguousarray(m25, dtype=np.int32),
        np.ascontiguousarray(gh20, dtype=np.int32),
        np.ascontiguousarray(gv20, dtype=np.int32),
    )


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
