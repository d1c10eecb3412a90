"""Argument types every command and every ``benchmarks/`` script reads its values with.

Each is an argparse type: a function of the option's text raising :class:`argparse.ArgumentTypeError`
with the project's own message (argparse prints it after the option's name, on one line). Numbers are
read in any Python spelling (``int_arg``: ``16``, ``0x10``), always finite, and bounded where they
are used (``int_in_range``, ``float_in_range``: nothing reaches the work out of range); lists are
``A,B,...`` with none twice (``value_list``); paths are never empty (``input_path``, ``output_path``:
an unset ``$VAR`` is not the current directory). ``bayesmachine.cliargs`` re-exports them.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TypeVar

__all__ = ["int_arg", "argument_type", "output_path", "input_path", "float_arg", "positive_float_arg",
           "int_in_range", "float_in_range", "size_pair", "positive_float_at_most", "value_list", "int_of",
           "choice_of", "on_off_list", "counter_max_list", "MAX_COUNTER_MAX"]

T = TypeVar("T")


def int_arg(text: str) -> int:
    """An integer in any Python spelling: ``16``, ``0x10``, ``0b10000``, ``0o20`` (and ``010`` = 10)."""
    s = text.strip().replace("_", "")
    try:
        return int(s, 0)
    except ValueError:
        pass
    try:
        return int(s, 10)  # base 0 refuses leading zeros ("010"); read them as decimal
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer (e.g. 16 or 0x10), got {text!r}") from None


def argument_type(parse: Callable[[str], T], name: str | None = None) -> Callable[[str], T]:
    """Wrap ``parse`` (raising ValueError with a message) as an argparse type keeping that message."""

    def convert(text: str) -> T:
        try:
            return parse(text)
        except argparse.ArgumentTypeError:
            raise
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = name or getattr(parse, "__name__", "value")
    return convert


def output_path(text: str) -> Path:
    """``-o``: a path, never empty or blank (an unset shell variable in ``-o "$OUT"`` would otherwise
    mean the current directory)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            f"the output path is {'empty' if not text else 'blank'} (an unset variable in -o \"$OUT\"?); "
            "name the output"
        )
    return Path(text)


def input_path(text: str) -> str:
    """A file or directory to read (an image, ``--gt``, ``--calib``, ``--dataset``, ``--port``): never
    empty or blank, which would name the current directory (``--calib "$CALIB"`` with CALIB unset)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            f"the path is {'empty' if not text else 'blank'} (an unset variable?); name the file")
    return text


def float_arg(text: str) -> float:
    """A finite float (``nan`` and ``inf`` are refused here, with the option's name)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_float_arg(text: str) -> float:
    """A finite float > 0 (a scale, a divisor)."""
    value = float_arg(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


def _in_range(parse: Callable[[str], T], lo: T, hi: T, what: str) -> Callable[[str], T]:
    """An argparse type: ``parse``'s value in [lo, hi] (``what``: "an integer", "a number")."""

    def convert(text: str) -> T:
        value = parse(text)
        if not lo <= value <= hi:  # type: ignore[operator]
            bounds = ", ".join(f"{b:g}" if isinstance(b, float) else str(b) for b in (lo, hi))
            raise argparse.ArgumentTypeError(f"expected {what} in [{bounds}], got {text!r}")
        return value

    convert.__name__ = what.split()[-1]
    return convert


def int_in_range(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: an integer (:func:`int_arg`'s spellings) in [lo, hi]."""
    return _in_range(int_arg, lo, hi, "an integer")


def float_in_range(lo: float, hi: float) -> Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi]."""
    return _in_range(float_arg, lo, hi, "a number")


def size_pair(names: str, lo: tuple[int, int], hi: tuple[int, int]) -> Callable[[str], tuple[int, int]]:
    """An argparse type: ``AxB`` (``names`` "WxH" or "HxW"), two integers, each in its [lo, hi]."""

    def convert(text: str) -> tuple[int, int]:
        try:
            a, b = (int(v) for v in text.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {names}, got {text!r}") from None
        if not (lo[0] <= a <= hi[0] and lo[1] <= b <= hi[1]):
            first, second = names.split("x")
            raise argparse.ArgumentTypeError(f"{first} must be {lo[0]} .. {hi[0]} and {second} {lo[1]} .. "
                                             f"{hi[1]}, got {text!r}")
        return a, b

    convert.__name__ = "size"
    return convert


def positive_float_at_most(hi: float) -> Callable[[str], float]:
    """An argparse type: a number in (0, hi] (a time out, bounded so that nothing waits for ever)."""

    def convert(text: str) -> float:
        value = positive_float_arg(text)
        if value > hi:
            raise argparse.ArgumentTypeError(f"expected a number in (0, {hi:g}], got {text!r}")
        return value

    convert.__name__ = "number"
    return convert


def value_list(parse: Callable[[str], T], what: str = "value") -> Callable[[str], list[T]]:
    """An argparse type: ``A,B,...``, each value read by the argparse type ``parse`` (its message kept,
    naming the value), at least one, none twice, in the order given (a benchmark's list option)."""

    def convert(text: str) -> list[T]:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"give at least one {what} (comma-separated), got {text!r}")
        try:
            values = [parse(p) for p in parts]
        except (argparse.ArgumentTypeError, ValueError) as exc:
            where = f" (in {text!r})" if len(parts) > 1 else ""
            raise argparse.ArgumentTypeError(f"{exc}{where}") from None
        if len(set(values)) != len(values):
            raise argparse.ArgumentTypeError(f"a {what} is listed twice: {text!r}")
        return values

    convert.__name__ = f"{what} list"
    return convert


def int_of(choices: Iterable[int]) -> Callable[[str], int]:
    """An argparse type: an integer among ``choices`` (``--samples-per-clock``'s 1, 2, 4, 8, 16)."""
    values = tuple(choices)

    def convert(text: str) -> int:
        value = int_arg(text)
        if value not in values:
            raise argparse.ArgumentTypeError(f"expected one of {', '.join(map(str, values))}, got {text!r}")
        return value

    convert.__name__ = "integer"
    return convert


def choice_of(choices: Iterable[str]) -> Callable[[str], str]:
    """An argparse type: one of ``choices`` (for :func:`value_list`)."""
    names = tuple(choices)

    def convert(text: str) -> str:
        if text not in names:
            raise argparse.ArgumentTypeError(f"expected one of {', '.join(names)}, got {text!r}")
        return text

    convert.__name__ = "choice"
    return convert


_ON_OFF = {"on": True, "true": True, "yes": True, "1": True,
           "off": False, "false": False, "no": False, "0": False}


def on_off_list(text: str) -> bool | list[bool]:
    """``on``, ``off`` or ``on,off`` (also true/false, yes/no, 1/0): one value, or several (a sweep's grid
    axis), no repeats."""
    parts = [p.strip().lower() for p in text.split(",") if p.strip()]
    if not parts or any(p not in _ON_OFF for p in parts):
        raise argparse.ArgumentTypeError(f"expected on, off or on,off (or true/false), got {text!r} (give "
                                         "LEFT RIGHT before this option, or its value after =, as in =on)")
    values = [_ON_OFF[p] for p in parts]
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"a value is listed twice: {text!r}")
    return values if len(values) > 1 else values[0]


MAX_COUNTER_MAX = (1 << 24) - 1  # MachineParams' bound on counter_max


def counter_max_list(text: str) -> list[int]:
    """``N,N,...`` counter max values (each 1 .. :data:`MAX_COUNTER_MAX`), sorted ascending with repeats
    removed."""
    values = []
    for part in text.split(","):
        if part.strip():
            try:
                values.append(int_arg(part))
            except argparse.ArgumentTypeError:
                raise argparse.ArgumentTypeError(
                    f"counter max values must be comma-separated integers, got {text!r}"
                ) from None
    if not values:
        raise argparse.ArgumentTypeError("give at least one counter max value")
    bad = [v for v in values if not 1 <= v <= MAX_COUNTER_MAX]
    if bad:
        raise argparse.ArgumentTypeError(f"counter max values must be in [1, {MAX_COUNTER_MAX}], "
                                         f"got {bad[0]}")
    return sorted(set(values))
