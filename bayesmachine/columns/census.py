"""The census column: the likelihood of the Hamming distance between two census codes.

``L_c(h) = census_p0 + (1-census_p0) exp(-h^2 / (2 census_sigma^2))`` of ``h = popcount(C_l(x) xor
C_r(x - d))``, a table indexed by h = 0..bits (the features' formula with scale 1). Its entry in the
no-match row is the same table at the constant distance ``census_nomatch_h`` (a no-match row
calibrated against the census column: L_c(h_nm), not 1).

Its plane ``census`` (:func:`census_codes`; on chip ``hdl.frontend.census``, its twin) holds each pixel's
census code, uint64, of a w x w window (w = 7 or 5, r = w // 2, ``census_window``): bit k (k = 0 the
least significant) is 1 when the k-th neighbour is darker than the centre (``neighbour < centre``), the
neighbours in raster order of the window (offsets (dy, dx) = (-r, -r), (-r, -r+1), ..., (r, r), the
centre skipped): 48 bits for 7x7, 24 for 5x5. The model's map grid keeps every window inside the image:
no bit reads outside it (the on-chip front end could not complete a window past a frame's last line).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesmachine.checks import as_int

from .base import Option, PlaneColumn, Table, check_int, check_probability, check_sigma, likelihood_formula
from .planes import Plane

__all__ = ["CENSUS_WINDOWS", "CENSUS_SIGMA", "Census", "census_bits", "census_offsets", "census_codes",
           "hamming"]

# Census windows the model takes: 7x7 (48 bits, codes fit a uint64) or the cheaper 5x5 (24 bits).
CENSUS_WINDOWS = (5, 7)
# Default census sigma per window: 6 for 7x7, 3 for 5x5.
CENSUS_SIGMA = {7: 6.0, 5: 3.0}


def census_bits(window: int) -> int:
    """Bits of a census code: the window's neighbours (48 for 7x7, 24 for 5x5)."""
    return window * window - 1


def census_offsets(window: int) -> list[tuple[int, int]]:
    """The neighbours (dy, dx) of a ``window`` x ``window`` census, in bit order (bit k = entry k)."""
    if window not in CENSUS_WINDOWS:
        raise ValueError(f"census window must be one of {CENSUS_WINDOWS}, got {window!r}")
    r = window // 2
    return [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1) if (dy, dx) != (0, 0)]


def census_codes(image: np.ndarray, window: int) -> np.ndarray:
    """The census codes, uint64 (H - 2r, W - 2r), r = window // 2, of an (H, W) gray image (module text)."""
    offsets = census_offsets(window)
    img = np.asarray(image)
    k = window // 2
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


# The census plane of each window (one object per window: equal declarations are one plane).
CENSUS_PLANES = {w: Plane("census", w, functools.partial(census_codes, window=w)) for w in CENSUS_WINDOWS}


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances popcount(a xor b) of uint64 census codes (broadcast), int64."""
    return np.bitwise_count(np.bitwise_xor(a, b)).astype(np.int64)


def _hamming_plain(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(np.bitwise_xor(a, b), dtype=np.uint64)
    return np.unpackbits(x.view(np.uint8).reshape(*x.shape, 8), axis=-1).sum(axis=-1).astype(np.int64)


def _window(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_int(name, value, 5, 7)
    if value not in CENSUS_WINDOWS:
        from bayesmachine.errors import ParameterError

        raise ParameterError(f"{name} must be 5 or 7 (a 5x5 or 7x7 census window), got {value!r}", name)


def _probability(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_probability(name, value)


def _sigma(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_sigma(name, value)


def _nomatch_h(name: str, value: object, values: Mapping[str, Any]) -> None:
    w = values["census_window"]
    bits = census_bits(w)
    as_int(name, value)  # the type (NumPy integers too)
    if not 0 <= value <= bits:
        from bayesmachine.errors import ParameterError

        raise ParameterError(f"{name} must be an integer Hamming distance in [0, {bits}] (the {w}x{w} census "
                             f"has {bits} bits), got {value!r}", name)


class Census(PlaneColumn):
    """The census column (``plane`` "census": the codes of both images)."""

    name = "census"
    plane = "census"
    hamming = True
    table_parameter = "census_sigma"
    options = (
        Option("census_window", "int", 7, _window, "census window: 7 (7x7, 48 bits) or 5 (5x5, 24 bits)"),
        Option("census_p0", "float", 0.02, _probability,
               "base census likelihood p0 of L_c(h) = p0 + (1 - p0) exp(-h^2 / (2 sigma_c^2))"),
        Option("census_sigma", "float", None, _sigma, "census sigma_c",
               resolve=lambda v: CENSUS_SIGMA[v["census_window"]], default_text="6 for 7x7, 3 for 5x5"),
        Option("census_nomatch_h", "int", None, _nomatch_h,
               "the no-match row's census entry L_c(h_nm): its Hamming distance (0 leaves the row "
               "uncalibrated)", resolve=lambda v: census_bits(v["census_window"]) // 8,
               default_text="bits / 8: 6 for 7x7, 3 for 5x5"),
    )

    @property
    def window(self) -> int:
        return int(self.values["census_window"])

    @property
    def bits(self) -> int:
        return census_bits(self.window)

    def planes(self) -> dict[str, Plane]:
        return {self.plane: CENSUS_PLANES[self.window]}

    @property
    def nomatch_h(self) -> int:
        return int(self.values["census_nomatch_h"])

    def cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return hamming(a, b)

    def plain_cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return _hamming_plain(a, b)  # by unpacking the bytes: independent of np.bitwise_count

    def costs(self) -> np.ndarray:
        return np.arange(self.bits + 1)

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        v = self.values
        return likelihood_formula(cost, 1, float(v["census_p0"]), float(v["census_sigma"]))

    def nomatch_values(self) -> tuple[float, ...]:
        return (float(self.likelihood(np.int64(self.nomatch_h))),)

    def nomatch_entry(self, table: Table) -> float | int:
        return table.values[self.nomatch_h]

    def check_machine(self, machine: Any) -> None:
        self._nonzero_word("census_nomatch_h", self.nomatch_values()[0], machine, "no match could never win",
                           "the no-match row's census likelihood")
