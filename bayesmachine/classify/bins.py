"""Quantile bins: each feature's real values -> a bin index, the address of its likelihood memory.

A feature's edges are its training values' quantiles ``k / B`` (k = 1 .. B - 1), each moved to the
nearest midpoint between two consecutive distinct training values (the lower on a tie), repeated ones
dropped: no edge falls on a training value, so a value that most samples share (the digits' 0) has a
bin of its own instead of sharing one with its neighbours, and a feature with few distinct values gets
fewer bins (a constant one, one bin). A value goes to the bin of the edges below it
(``searchsorted(edges, x, side="right")``); values beyond the training range go to the end bins. B,
the largest count per feature, is chosen by measurement (docs/classifier.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.checks import as_int
from bayesmachine.errors import ParameterError

__all__ = ["DEFAULT_BINS", "MAX_BINS", "QuantileBins"]

# The count per feature: the best mean exact naive-Bayes accuracy of 3, 4, 5, 6, 8 and 16 bins over the four
# bundled data sets, 5-fold at three split seeds (docs/classifier.md).
DEFAULT_BINS = 4
# A feature's likelihood memory holds classes x bins words: 256 bins address it with one byte.
MAX_BINS = 256


@dataclass(frozen=True, eq=False)
class QuantileBins:
    """The bins of a training set's features (module text).

    Attributes
    ----------
    edges : tuple of ndarray
        Per feature its inner edges (float64, increasing; none: one bin).
    """

    edges: tuple[np.ndarray, ...]

    @classmethod
    def fit(cls, x: np.ndarray, bins: int = DEFAULT_BINS) -> QuantileBins:
        """The quantile bins of ``x`` (n, features), at most ``bins`` per feature."""
        bins = as_int("bins", bins, 1, MAX_BINS)
        x = _matrix(x)
        if x.shape[0] == 0:
            raise ParameterError("bins: no training values to take quantiles of", "bins")
        q = np.arange(1, bins) / bins
        return cls(tuple(_edges(x[:, j], q) for j in range(x.shape[1])))

    @property
    def features(self) -> int:
        return len(self.edges)

    @property
    def counts(self) -> np.ndarray:
        """(features,) int64: each feature's number of bins."""
        return np.array([e.size + 1 for e in self.edges], np.int64)

    def transform(self, x: np.ndarray) -> np.ndarray:
        """(n, features) int64 bin indices of ``x``."""
        x = _matrix(x)
        if x.shape[1] != self.features:
            raise ValueError(f"x has {x.shape[1]} features, the bins {self.features}")
        out = np.empty(x.shape, np.int64)
        for j, e in enumerate(self.edges):
            out[:, j] = np.searchsorted(e, x[:, j], side="right")
        return out


def _edges(values: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The inner edges of one feature (module text)."""
    v = np.unique(values)
    mid = (v[:-1] + v[1:]) / 2
    if mid.size == 0 or q.size == 0:
        return np.zeros(0)
    target = np.quantile(values, q)
    hi = np.clip(np.searchsorted(mid, target), 0, mid.size - 1)
    lo = np.maximum(hi - 1, 0)
    nearest = np.where(np.abs(target - mid[lo]) <= np.abs(mid[hi] - target), mid[lo], mid[hi])
    return np.unique(nearest)


def _matrix(x: np.ndarray) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 2:
        raise ValueError(f"x must be a 2-D array (samples, features), got {arr.ndim} dimensions")
    if not np.isfinite(arr).all():
        raise ValueError("x holds NaN or infinite values")
    return arr
