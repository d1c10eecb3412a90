"""The census column: the likelihood of the Hamming distance between two census codes.

``L_c(h) = census_p0 + (1-census_p0) exp(-h^2 / (2 census_sigma^2))`` of ``h = popcount(C_l(x) xor
C_r(x - d))``, a table indexed by h = 0..bits (the features' formula with scale 1). Its entry in the
no-match row is the same table at the constant distance ``census_nomatch_h`` (a no-match row
calibrated against the census column: L_c(h_nm), not 1). The codes: ``host.features.census_codes``
(and the front end's ``hdl.frontend.census``), on a 7x7 (48 bits) or 5x5 (24 bits) window.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesmachine.checks import as_int

from .base import Column, Option, Source, Table, check_int, check_probability, check_sigma, likelihood_formula

__all__ = ["CENSUS_WINDOWS", "CENSUS_SIGMA", "Census", "census_bits", "hamming"]

# Census windows the model takes: 7x7 (48 bits, codes fit a uint64) or the cheaper 5x5 (24 bits).
CENSUS_WINDOWS = (5, 7)
# Default census sigma per window: 6 for 7x7, 3 for 5x5.
CENSUS_SIGMA = {7: 6.0, 5: 3.0}


def census_bits(window: int) -> int:
    """Bits of a census code: the window's neighbours (48 for 7x7, 24 for 5x5)."""
    return window * window - 1


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


class Census(Column):
    """The census column (``plane`` "census": the codes of both images)."""

    name = "census"
    source = Source.FEATURES
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

    @property
    def margin(self) -> int:  # type: ignore[override]
        return max(2, self.window // 2)

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
