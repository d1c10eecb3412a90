"""The logarithmic integrator's rule, in NumPy: THE definition the log blocks are held to.

A pixel has M rows; row r has N energy codes ``E[r][c]`` (``code_bits`` unsigned bits each, the
code of −ln of a likelihood in fixed steps). The all-ones code ``2**code_bits - 1`` is infinite
energy (likelihood 0). Per pixel (``docs/integrators.md``, "The logarithmic integrator: exact
rule"):

- ``sums[r] = Σ_c E[r][c]`` exactly, ``excluded[r]`` = some code of row r is infinite;
- ``map`` = the row of the lowest sum among the rows not excluded, ties by ``tie_break``
  (``nomatch-first``: the no-match row, the last one, wins a tie it is part of, else the lowest
  index; ``lowest-index``: the lowest index); when every row is excluded, ``all_excluded`` and
  ``map`` is the no-match row (row 0 without one);
- ``s_min`` = ``sums[map]`` (0 when every row is excluded);
- ``nomatch`` = the pixel has a no-match row and ``map`` is it;
- ``weights[r] = X[min(sums[r] - s_min, len(X) - 1)]`` for the exp table X (a row's sum is never
  below ``s_min`` unless it is excluded), 0 for an excluded row.

:func:`log_integrate` computes it for any number of pixels at once.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass

import numpy as np

from bayesmachine.errors import ParameterError
from bayesmachine.params import DEFAULT_TIE_BREAK, TIE_BREAKS

__all__ = ["LogParams", "LogResult", "argmin_rows", "check_int", "exp_table", "log_integrate", "row_sums",
           "row_weights"]

MAX_CODE_BITS = 16
MAX_WEIGHT_BITS = 16


def check_int(name: str, value: object, lo: int, hi: int) -> int:
    """``value`` as an int (Python's or NumPy's, not a bool) in [lo, hi]."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an integer, not {type(value).__name__}")
    try:
        v = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise TypeError(f"{name} must be an integer, not {type(value).__name__}") from None
    if not lo <= v <= hi:
        raise ParameterError(f"{name} must be in [{lo}, {hi}], got {v}", name)
    return v


def _table(weights: object) -> tuple[int, ...]:
    """The exp table as a tuple of ints, checked: nonincreasing, at least 2 entries, the first
    positive and below ``2**(MAX_WEIGHT_BITS + 1)``, the last 0."""
    if isinstance(weights, (str, bytes)) or not hasattr(weights, "__iter__"):
        raise TypeError(f"weights must be a sequence of integers, not {type(weights).__name__}")
    table = tuple(check_int("weights", w, 0, 1 << MAX_WEIGHT_BITS) for w in weights)  # type: ignore[union-attr]
    if len(table) < 2 or table[0] == 0 or table[-1] != 0:
        raise ParameterError(f"weights must have at least 2 entries, the first positive and the last 0, "
                             f"got {table[:4]}...{table[-2:]}", "weights")
    if any(b > a for a, b in zip(table, table[1:], strict=False)):
        raise ParameterError("weights must be nonincreasing", "weights")
    return table


@dataclass(frozen=True)
class LogParams:
    """Parameters of one logarithmic integrator (the rule, the blocks and the top share them).

    Parameters
    ----------
    rows : int
        M, the rows (hypotheses) of a pixel, 1 ... 4096 (>= 2 with a no-match row); Dmax + 2 in
        disparity use.
    codes : int
        N, the energy codes per row, 1 ... 64.
    code_bits : int
        Bits of a code, 1 ... 16; the all-ones code is infinite energy.
    weights : sequence of int
        The exp table X: nonincreasing, at least 2 entries, the first positive, the last 0
        (:func:`exp_table` builds one).
    nomatch_row : bool
        Whether the last row is the no-match row.
    tie_break : str
        ``"nomatch-first"`` or ``"lowest-index"`` (``bayesmachine.params.TIE_BREAKS``).

    Attributes
    ----------
    sum_bits : int
        Bits of a row's sum: ``code_bits + ceil(log2 codes)``.
    map_width : int
        Bits of a row index: ``max(1, bit_length(rows - 1))``.
    weight_bits : int
        Bits of a weight: ``bit_length(weights[0])``.
    infinite : int
        The infinite code, ``2**code_bits - 1``.
    """

    rows: int
    codes: int
    code_bits: int
    weights: tuple[int, ...]
    nomatch_row: bool = True
    tie_break: str = DEFAULT_TIE_BREAK

    def __post_init__(self) -> None:
        object.__setattr__(self, "rows", check_int("rows", self.rows, 1, 4096))
        object.__setattr__(self, "codes", check_int("codes", self.codes, 1, 64))
        object.__setattr__(self, "code_bits", check_int("code_bits", self.code_bits, 1, MAX_CODE_BITS))
        object.__setattr__(self, "weights", _table(self.weights))
        if not isinstance(self.nomatch_row, (bool, np.bool_)):
            raise TypeError(f"nomatch_row must be a bool, not {type(self.nomatch_row).__name__}")
        object.__setattr__(self, "nomatch_row", bool(self.nomatch_row))
        if self.nomatch_row and self.rows < 2:
            raise ParameterError("rows: an integrator with a no-match row needs at least 2 rows", "rows")
        if not isinstance(self.tie_break, str):
            raise TypeError(f"tie_break must be a str, not {type(self.tie_break).__name__}")
        if self.tie_break not in TIE_BREAKS:
            raise ParameterError(f"tie_break must be one of {TIE_BREAKS}, got {self.tie_break!r}",
                                 "tie_break")

    @property
    def sum_bits(self) -> int:
        return self.code_bits + (self.codes - 1).bit_length()

    @property
    def map_width(self) -> int:
        return max(1, (self.rows - 1).bit_length())

    @property
    def weight_bits(self) -> int:
        return self.weights[0].bit_length()

    @property
    def infinite(self) -> int:
        return (1 << self.code_bits) - 1

    @property
    def nomatch_first(self) -> bool:
        """The no-match row wins the ties it is part of."""
        return self.nomatch_row and self.tie_break == "nomatch-first"

    @property
    def none_index(self) -> int:
        """The ``map`` of a pixel whose rows are all excluded: the no-match row, else row 0."""
        return self.rows - 1 if self.nomatch_row else 0


def exp_table(*, weight_bits: int, step: float) -> tuple[int, ...]:
    """The exp table ``X[e] = floor(2**weight_bits * exp(-e * step) + 1/2)`` for e = 0, 1, ...
    up to and including its first 0: the weight of a row whose sum exceeds the least by e codes,
    ``step`` the code's step in nats."""
    bits = check_int("weight_bits", weight_bits, 1, MAX_WEIGHT_BITS - 1)
    if isinstance(step, bool) or not isinstance(step, (int, float, np.floating, np.integer)):
        raise TypeError(f"step must be a number, not {type(step).__name__}")
    if not (math.isfinite(step) and step > 0):
        raise ParameterError(f"step must be a positive finite number, got {step}", "step")
    table = []
    while not table or table[-1]:
        table.append(math.floor((1 << bits) * math.exp(-len(table) * float(step)) + 0.5))
    return tuple(table)


@dataclass(frozen=True)
class LogResult:
    """The rule's answer for pixels of any leading shape P (arrays of shape P, or P + (M,)).

    ``map`` (int32), ``nomatch``, ``all_excluded`` (bool), ``s_min`` (int64), ``sums`` (int64, per
    row), ``excluded`` (bool, per row), ``weights`` (int64, per row).
    """

    map: np.ndarray
    nomatch: np.ndarray
    all_excluded: np.ndarray
    s_min: np.ndarray
    sums: np.ndarray
    excluded: np.ndarray
    weights: np.ndarray


def _check_codes(codes: object, params: LogParams) -> np.ndarray:
    if not isinstance(codes, np.ndarray) or codes.dtype.kind not in "ui":
        raise TypeError("codes must be a NumPy integer array of shape (..., rows, codes)")
    if codes.ndim < 2 or codes.shape[-2:] != (params.rows, params.codes):
        raise ValueError(f"codes must have shape (..., {params.rows}, {params.codes}), got {codes.shape}")
    if codes.size and (codes.min() < 0 or codes.max() > params.infinite):
        raise ValueError(f"codes must be in [0, {params.infinite}] ({params.code_bits} bits)")
    return codes


def row_sums(codes: np.ndarray, params: LogParams) -> tuple[np.ndarray, np.ndarray]:
    """The row adders' part: ``(sums, excluded)`` of ``codes`` (shape ``(..., rows, codes)``)."""
    codes = _check_codes(codes, params)
    return codes.sum(axis=-1, dtype=np.int64), (codes == params.infinite).any(axis=-1)


def argmin_rows(sums: np.ndarray, excluded: np.ndarray, params: LogParams
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The argmin tree's part: ``(map, nomatch, all_excluded, s_min)`` of rows' ``sums`` and
    ``excluded`` flags (shape ``(..., rows)``)."""
    # One key per row: the lowest key is the answer, np.argmin takes the first (lowest-index) of
    # equal keys, and under nomatch-first the no-match row's key is one lower than any row of the
    # same sum. An excluded row's key is above every sum's.
    key = np.asarray(sums, dtype=np.int64) * 2 + 1
    if params.nomatch_first:
        key[..., -1] -= 1
    key = np.where(excluded, np.int64(1) << 62, key)
    winner = key.argmin(axis=-1)
    all_excluded = np.asarray(excluded, bool).all(axis=-1)
    map_ = np.where(all_excluded, params.none_index, winner).astype(np.int32)
    best = np.take_along_axis(np.asarray(sums, dtype=np.int64), winner[..., None], axis=-1)[..., 0]
    s_min = np.where(all_excluded, 0, best).astype(np.int64)
    nomatch = (map_ == params.rows - 1) if params.nomatch_row else np.zeros(map_.shape, bool)
    return map_, nomatch, all_excluded, s_min


def row_weights(sums: np.ndarray, excluded: np.ndarray, s_min: np.ndarray, params: LogParams) -> np.ndarray:
    """The weights stage's part: ``X[min(sums - s_min, len(X) - 1)]`` per row, 0 for an excluded row
    (a sum below ``s_min``, which the rule never gives a row not excluded, reads X[0])."""
    table = np.asarray(params.weights, dtype=np.int64)
    clamped = np.clip(np.asarray(sums, dtype=np.int64) - np.asarray(s_min)[..., None], 0, len(table) - 1)
    return np.where(excluded, 0, table[clamped])


def log_integrate(codes: np.ndarray, params: LogParams) -> LogResult:
    """The rule (module docstring) on ``codes`` of shape ``(..., rows, codes)``, vectorized over
    the leading axes (pixels)."""
    if not isinstance(params, LogParams):
        raise TypeError(f"params must be a LogParams, not {type(params).__name__}")
    sums, excluded = row_sums(codes, params)
    map_, nomatch, all_excluded, s_min = argmin_rows(sums, excluded, params)
    return LogResult(map=map_, nomatch=nomatch, all_excluded=all_excluded, s_min=s_min, sums=sums,
                     excluded=excluded, weights=row_weights(sums, excluded, s_min, params))
