"""The one rule for the type and range of a parameter's value, below ``params``, ``sources`` and
``columns`` (and the host's parameter objects).

* an integer is what Python's ``operator.index`` takes (``int``, a NumPy integer scalar), never a
  bool;
* a yes/no value is a ``bool`` or a NumPy bool scalar, never a number;
* a number is a real (``int``, ``float``, a NumPy integer or floating scalar), never a bool.

Each check returns the value as a plain Python ``int``, ``bool`` or ``float`` (what reports,
fingerprints and JSON hold), raises TypeError for a wrong type and :class:`ParameterError` naming the
parameter for a value out of range, and never OverflowError: a huge integer is compared exactly, then
refused, never converted.
"""

from __future__ import annotations

import math
import operator
import sys
from numbers import Real

from bayesmachine.errors import ParameterError

__all__ = ["as_int", "as_bool", "as_real", "plain", "shown", "type_name"]


def type_name(value: object) -> str:
    """``int 5``, ``str 'x'``: what a TypeError says was given."""
    return f"{type(value).__name__} {value!r}"


def _numpy_scalar(value: object, kind: str) -> bool:
    """Whether ``value`` is a NumPy scalar of ``kind`` (``"generic"``, ``"bool_"``, ``"integer"``,
    ``"floating"``): without importing NumPy, which made any such value."""
    np = sys.modules.get("numpy")
    return np is not None and isinstance(value, getattr(np, kind))


def plain(value: object) -> object:
    """A NumPy scalar as the Python value it holds (``np.int64(7)`` -> 7, ``np.True_`` -> True); any
    other value as it is."""
    return value.item() if _numpy_scalar(value, "generic") else value  # type: ignore[attr-defined]


def _is_bool(value: object) -> bool:
    return isinstance(value, bool) or _numpy_scalar(value, "bool_")


def _bounds(low: float | None, high: float | None) -> str:
    lo, hi = (b if isinstance(b, int) or b is None else f"{b:g}" for b in (low, high))
    if low is not None and high is not None:
        return f"in [{lo}, {hi}]"
    return f">= {lo}" if low is not None else f"<= {hi}"


def as_int(name: str, value: object, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int in [low, high] (a bound None: none)."""
    if _is_bool(value):
        raise TypeError(f"{name} must be an integer, not {type_name(value)}")
    try:
        v = operator.index(value)  # type: ignore[call-overload]
    except TypeError:
        raise TypeError(f"{name} must be an integer, not {type_name(value)}") from None
    if (low is not None and v < low) or (high is not None and v > high):
        raise ParameterError(f"{name} must be an integer {_bounds(low, high)}, got {shown(v)}", name)
    return v


def as_bool(name: str, value: object) -> bool:
    """``value`` as a bool (True, False or a NumPy bool scalar)."""
    if not _is_bool(value):
        raise TypeError(f"{name} must be True or False, not {type_name(value)}")
    return bool(value)


def as_real(name: str, value: object, low: float | None = None, high: float | None = None,
            unit: str = "") -> float:
    """``value`` as a finite float in [low, high] (a bound None: none); ``unit`` follows the bounds in a
    message (``" pixels"``)."""
    if _is_bool(value) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a number, not {type_name(value)}")
    # Compared before any conversion: an int of 400 digits is out of range, not an OverflowError.
    if (low is not None and not value >= low) or (high is not None and not value <= high):
        said = shown(value)
        raise ParameterError(f"{name} must be a finite number {_bounds(low, high)}{unit}, got {said}", name)
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v):
        raise ParameterError(f"{name} must be a finite number, got {shown(value)}", name)
    return v


def shown(value: object) -> str:
    """A value for a message: an integer too long to read is said by its size."""
    if isinstance(value, int) or _numpy_scalar(value, "integer"):
        v = int(value)  # type: ignore[call-overload]
        return f"an integer of {len(str(abs(v)))} digits" if abs(v) >= 10**30 else str(v)
    if isinstance(value, float) or _numpy_scalar(value, "floating"):
        return f"{float(value):g}"  # type: ignore[arg-type]
    return repr(value)
