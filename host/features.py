"""The planes of an image a model reads, on its map grid: each declared by a column, computed once.

A column kind declares the planes it reads (:meth:`~bayesmachine.columns.Term.planes`: a
:class:`~bayesmachine.columns.Plane`, its name, filter and window), so a model's planes
(``ModelParams.planes``) are exactly its passes' columns' and its no-match rule's, and its margin k
(``ModelParams.margin``) the largest half-window among them: 2 for 5x5 windows, 3 with a 7x7 census.
:func:`model_planes` computes them on the model's map grid (``bayesmachine.region``): (H-2k, W-2k)
pixels, map pixel (y, x) centred on image pixel (y+k, x+k), each plane cut from its own filter's grid,
so no window reads outside the image. :class:`Planes` holds them by name.

The filters: :mod:`bayesmachine.columns.planes` (the paper's 5x5 sums ``m25``, ``gh20``, ``gv20`` and
the gradient magnitude ``g20``, exact integers) and :func:`~bayesmachine.columns.census_codes` (the
census codes, uint64). :func:`feature_sums` gives the paper's three sums (and census codes) without a
model; ``feature_sums_plain`` and ``census_codes_plain`` are the plain oracles of the tests.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping

import numpy as np

from bayesmachine.columns import CENSUS_WINDOWS, MAX_ABS, SCALES, Plane, census_codes, census_offsets
from bayesmachine.columns.census import CENSUS_PLANES
from bayesmachine.columns.planes import SUM_PLANES
from bayesmachine.models import ModelParams

__all__ = [
    "Planes",
    "SCALES",
    "MAX_ABS",
    "compute_planes",
    "model_planes",
    "feature_sums",
    "feature_sums_plain",
    "census_offsets",
    "census_codes",
    "census_codes_plain",
]


class Planes(Mapping[str, np.ndarray]):
    """One image's planes on one map grid, by name: each (H-2k, W-2k), read as ``planes["m25"]`` (or
    ``planes.m25``). Read-only."""

    __slots__ = ("_planes", "_shape")

    def __init__(self, planes: Mapping[str, np.ndarray]) -> None:
        arrays = {str(name): np.asarray(a) for name, a in planes.items()}
        shapes = {a.shape for a in arrays.values()}
        if not arrays or len(shapes) != 1 or len(next(iter(shapes))) != 2:
            got = {name: a.shape for name, a in arrays.items()}
            raise ValueError(f"planes must be 2-D arrays of one shape, at least one, got {got}")
        object.__setattr__(self, "_planes", arrays)
        object.__setattr__(self, "_shape", shapes.pop())

    def __getitem__(self, name: str) -> np.ndarray:
        return self._planes[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._planes)

    def __len__(self) -> int:
        return len(self._planes)

    def __getattr__(self, name: str) -> np.ndarray:
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._planes[name]
        except KeyError:
            raise AttributeError(f"no plane {name!r} (planes: {', '.join(self._planes)})") from None

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("Planes are read-only")

    def __reduce__(self) -> tuple[type[Planes], tuple[dict[str, np.ndarray]]]:
        return Planes, (dict(self._planes),)

    def __repr__(self) -> str:
        return f"Planes({', '.join(self._planes)}; {self._shape[0]}x{self._shape[1]})"

    @property
    def shape(self) -> tuple[int, int]:
        """The map grid (rows, columns)."""
        return self._shape  # type: ignore[return-value]

    def band(self, rows: slice) -> Planes:
        """The planes of map rows ``rows`` (views: a band costs no copy)."""
        return Planes({name: a[rows] for name, a in self._planes.items()})


def compute_planes(image: np.ndarray, planes: Iterable[Plane], margin: int | None = None) -> Planes:
    """``planes`` of a gray (H, W) image on the map grid of ``margin`` (default: their largest
    half-window), each by its filter."""
    planes = list(planes)
    if not planes:
        raise ValueError("compute_planes: no plane asked for")
    k = max(p.margin for p in planes) if margin is None else margin
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 2 * k + 1 or img.shape[1] < 2 * k + 1:
        size = 2 * k + 1
        raise ValueError(f"image of shape {img.shape} is too small for the {size}x{size} windows")
    return Planes({p.name: p.on_grid(img, k) for p in planes})


def model_planes(image: np.ndarray, model: ModelParams) -> Planes:
    """The planes every pass of ``model`` reads (``model.planes``), on its map grid (margin
    ``model.margin``)."""
    return compute_planes(image, model.planes.values(), model.margin)


def feature_sums(image: np.ndarray, census_window: int | None = None) -> Planes:
    """The paper's three sums ``m25``, ``gh20``, ``gv20`` of a gray (H, W) image, and with
    ``census_window`` (5 or 7) the census codes ``census``, on the grid of their largest window:
    (H-4, W-4) without a census or with a 5x5 one, (H-6, W-6) with a 7x7 census."""
    planes = list(SUM_PLANES.values())
    if census_window is not None:
        if census_window not in CENSUS_WINDOWS:
            raise ValueError(f"census window must be one of {CENSUS_WINDOWS}, got {census_window!r}")
        planes.append(CENSUS_PLANES[census_window])
    return compute_planes(image, planes)


def census_codes_plain(image: np.ndarray, window: int) -> np.ndarray:
    """The census codes pixel by pixel in plain Python (a test oracle), on the grid of margin window // 2."""
    img = np.asarray(image)
    h, w = img.shape
    k = window // 2
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


def feature_sums_plain(image: np.ndarray) -> Planes:
    """The paper's three sums by direct window-by-window correlation with the kernels (a test oracle)."""
    img = np.asarray(image, dtype=np.int64)
    h4, w4 = img.shape[0] - 4, img.shape[1] - 4
    windows = np.lib.stride_tricks.sliding_window_view(img, (5, 5))[:h4, :w4]
    return Planes({SUM_PLANES[f].name: np.einsum("yxij,ij->yx", windows, KERNELS[f]).astype(np.int32)
                   for f in ("m", "gh", "gv")})
