"""What every engine returns and what it accepts: results, validation, number sources, decoding.

Amaranth-free at import (the model needs none of it): the result decoder reads the field
offsets from :func:`bayesmachine.hdl.signatures.result_layout`, imported when first needed and
cached per parameters, so that one place, the layout, decides the field order.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesmachine.params import MachineParams

if TYPE_CHECKING:
    from bayesmachine.sources import NumberSource

__all__ = [
    "ArrayNumbers",
    "EngineClosedError",
    "EngineStateError",
    "MachineResult",
    "NumberFeed",
    "answered",
    "check_numbers",
    "check_line_start", "check_words",
    "decode_results",
    "disparities",
    "layout_fields",
    "neighbour_answers",
    "ran_out_error",
]


class EngineClosedError(RuntimeError):
    """``run()`` or ``reset()`` on an engine after its ``close()``."""


class EngineStateError(RuntimeError):
    """An earlier run was cut short: pixels were left in flight, so results would no longer match."""


# The dtype of each result field; the fields themselves come from result_layout.
_DTYPES = {"counts": np.uint32, "map": np.int32, "nomatch": np.bool_, "timeout": np.bool_, "cycles": np.int64}


@dataclass
class MachineResult:
    """Per-pixel results, in load order. Build it by keyword: the field order is the layout's business."""

    # counts, cycles: None only from the board's engine asked for the MAP without them
    counts: np.ndarray  # (P, rows) uint32: overflow counters at the stop (winner = n_max)
    map: np.ndarray  # (P,) int32: MAP row index (0 on timeout)
    nomatch: np.ndarray  # (P,) bool: the no-match row won
    timeout: np.ndarray  # (P,) bool: the watchdog stopped the run
    cycles: np.ndarray  # (P,) int64: compute cycles of the run

    def __len__(self) -> int:
        return len(self.map)

    @classmethod
    def zeros(cls, pixels: int, rows: int) -> MachineResult:
        """``pixels`` zeroed results, to be filled in place."""
        shapes = {f: (pixels, rows) if f == "counts" else (pixels,) for f in _DTYPES}
        return cls(**{f: np.zeros(shapes[f], dt) for f, dt in _DTYPES.items()})

    @classmethod
    def empty(cls, rows: int) -> MachineResult:
        return cls.zeros(0, rows)

    @classmethod
    def concatenate(cls, parts: list[MachineResult], rows: int) -> MachineResult:
        if not parts:
            return cls.empty(rows)
        return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)})

    def disparities(self, params: MachineParams) -> np.ndarray:
        """:func:`disparities` of these results, from the machine of ``params``."""
        return disparities(self.map, self.nomatch, self.timeout, params)

    def neighbour_answers(self) -> np.ndarray:
        """:func:`neighbour_answers` of these results."""
        return neighbour_answers(self.map, self.nomatch, self.timeout)

    def equal(self, other: MachineResult) -> bool:
        return all(np.array_equal(getattr(self, f.name), getattr(other, f.name)) for f in fields(self))


def answered(params: MachineParams, timeout: np.ndarray) -> np.ndarray:
    """Where a result's ``map`` is the machine's answer: a run that overflowed, and with
    ``timeout_answer = "leading"`` a run the watchdog stopped too (its leading row)."""
    timeout = np.asarray(timeout, bool)
    return np.ones_like(timeout) if params.timeout_answer == "leading" else ~timeout


def disparities(map_: np.ndarray, nomatch: np.ndarray, timeout: np.ndarray,
                params: MachineParams) -> np.ndarray:
    """The answer of each pixel (int16) of the machine of ``params``: its MAP row, -1 where the
    no-match row won or the run gave no answer (stopped by the watchdog with ``timeout_answer =
    "none"``). The one rule every engine's caller reads a pixel's answer by (what a neighbour
    follows is :func:`neighbour_answers`)."""
    none = np.asarray(nomatch, bool) | ~answered(params, timeout)
    return np.where(none, -1, map_).astype(np.int16)


def neighbour_answers(map_: np.ndarray, nomatch: np.ndarray, timeout: np.ndarray) -> np.ndarray:
    """What the neighbours of each pixel follow (int16): the neighbour prior's above column and
    census-lr's right MAPs, as the machine's feedback column does on chip. The MAP of a run that
    overflowed; -1 where the no-match row won and for every timeout, answered or not: a timed-out
    pixel's leading row is its answer, not information for its neighbours (measured on the bundled
    pair, docs/architecture.md "The watchdog's answer")."""
    none = np.asarray(nomatch, bool) | np.asarray(timeout, bool)
    return np.where(none, -1, map_).astype(np.int16)


# --- Validation: the same checks, hence the same errors, in every engine ---

def check_words(params: MachineParams, words: np.ndarray) -> np.ndarray:
    """Validate a block of pixels' likelihood-memory words; returns them as (P, words_per_pixel) int32.

    Accepts shape (P, rows, loaded_columns) or (P, words_per_pixel); values must be integers in
    [0, 2**word_bits] (energy codes in [0, ``load_max``] with ``integrator = "log"``). The loaded columns
    are all operator columns but a neighbour prior's feedback column, which the machine forms itself.
    """
    w = np.asarray(words)
    n, cols = params.words_per_pixel, params.loaded_columns
    expect = f"(pixels, {params.rows}, {cols})"
    if params.feedback_columns:
        expect += f" (the loaded columns: column 0 of the {params.operator_columns} is the feedback prior)"
    if w.ndim == 3:
        if w.shape[1:] != (params.rows, cols):
            raise ValueError(f"likelihood memories have shape {w.shape}; this machine expects {expect}")
        w = w.reshape(w.shape[0], n)
    elif w.ndim != 2 or w.shape[1] != n:
        raise ValueError(
            f"likelihood memories have shape {w.shape}; this machine expects {expect} or (pixels, {n})"
        )
    if w.dtype.kind not in "iu":
        raise ValueError(f"likelihood memory words must be integers, got dtype {w.dtype}")
    if w.size and (w.min() < 0 or w.max() > params.load_max):
        what = (f"likelihood memory words must lie in [0, {params.word_one}] (p = q / 2**{params.word_bits})"
                if params.kind.loads == "words" else
                f"energy codes (integrator = {params.integrator!r}) must lie in [0, {params.load_max}]")
        raise ValueError(f"{what}; got [{w.min()}, {w.max()}]")
    return np.ascontiguousarray(w, dtype=np.int32)


def check_line_start(params: MachineParams, line_start: object, pixels: int) -> np.ndarray | None:
    """Validate the per-pixel ``line_start`` flags: required with a neighbour prior, refused otherwise.

    Returns them as (P,) uint8 (None without a neighbour prior)."""
    if not params.feedback_columns:
        if line_start is not None:
            raise ValueError(f"line_start flags are only taken by a machine with prior = 'neighbour', "
                             f"not {params.prior!r}")
        return None
    if line_start is None:
        raise ValueError("a machine with prior = 'neighbour' needs line_start= (one flag per pixel: True "
                         "where a pixel has no left neighbour)")
    f = np.asarray(line_start)
    if f.shape != (pixels,):
        raise ValueError(f"line_start must have shape ({pixels},) (one flag per pixel), got {f.shape}")
    if f.dtype.kind not in "biu" or (f.size and (f.min() < 0 or f.max() > 1)):
        raise ValueError("line_start flags must be booleans (or 0/1)")
    return np.ascontiguousarray(f, dtype=np.uint8)


def check_numbers(params: MachineParams, numbers: np.ndarray) -> np.ndarray:
    """Validate random numbers for the ``entropy`` port; returns them as contiguous (T, operators) uint16.

    One row per compute cycle, one W-bit number per operator: integers (not float, bool or
    object) in [0, 2**word_bits).
    """
    n = np.asarray(numbers)
    if n.ndim != 2 or n.shape[1] != params.operators:
        raise ValueError(f"random numbers must have shape (cycles, {params.operators}), got {n.shape}")
    if n.dtype.kind not in "iu":
        raise ValueError(f"random numbers must be integers, got dtype {n.dtype}")
    top = 1 << params.word_bits
    if n.size and (n.min() < 0 or n.max() >= top):
        raise ValueError(f"random numbers must lie in [0, {top}) (W = {params.word_bits} bits); "
                         f"got [{n.min()}, {n.max()}]")
    return np.ascontiguousarray(n, dtype=np.uint16)


class ArrayNumbers:
    """A finite :class:`~bayesmachine.sources.NumberSource` over a caller's (T, operators) array."""

    def __init__(self, params: MachineParams, numbers: np.ndarray) -> None:
        self._rows = check_numbers(params, numbers)
        self.operators = params.operators
        self._next = 0

    def __len__(self) -> int:
        return len(self._rows)

    def take(self, count: int) -> np.ndarray:
        part = self._rows[self._next : self._next + max(0, count)]
        self._next += len(part)
        return part


def ran_out_error(source: object) -> ValueError:
    """The one error of a run whose random numbers ran out."""
    if isinstance(source, ArrayNumbers):
        return ValueError(f"the {len(source)} cycles of random numbers ran out before the run ended")
    return ValueError(f"the random source {type(source).__name__} ran out before the run ended")


class NumberFeed:
    """Rows from a number source, with rows taken but not used kept for the next run.

    Engines fetch numbers in blocks (the model) or one row ahead (the simulators); rows fetched
    but not consumed by a compute cycle stay here, so a stateful source gives the same stream
    of numbers to the same compute cycles in every engine. Switching to another source drops them.
    """

    def __init__(self, params: MachineParams) -> None:
        self.source: NumberSource | None = None
        self._params = params
        self._operators = params.operators
        self._pending = np.zeros((0, params.operators), np.uint16)

    def use(self, source: NumberSource | None) -> bool:
        """Feed from ``source`` from now on; True if it is a different source (pending rows dropped)."""
        if source is self.source:
            return False
        self.source = source
        self._pending = np.zeros((0, self._operators), np.uint16)
        return True

    def take(self, count: int) -> np.ndarray:
        """Up to ``count`` rows: the pending ones first, then the source's (fewer: it ran out)."""
        out = self._pending[:count]
        self._pending = self._pending[len(out):]
        if len(out) < count and self.source is not None:
            # A device model's rows get the checks of a caller's array: no engine packs a bad number.
            more = check_numbers(self._params, self.source.take(count - len(out)))
            out = np.concatenate([out, more]) if len(out) else more
        return out

    def unread(self, rows: np.ndarray) -> None:
        """Put rows back in front of the stream (fetched but not consumed)."""
        if len(rows):
            self._pending = np.concatenate([rows, self._pending])

    def take_clocks(self, count: int) -> np.ndarray:
        """Up to ``count`` compute cycles' numbers, whole ones: (clocks, B * operators), clock t's
        sample i in columns ``i * operators ...`` (B = ``samples_per_clock`` rows of the stream per
        clock; a partial clock at the stream's end stays pending: fewer than B rows run no clock)."""
        b = self._params.samples_per_clock
        rows = self.take(count * b)
        whole = len(rows) // b * b
        self.unread(rows[whole:])
        return rows[:whole].reshape(-1, b * self._operators)

    def unread_clocks(self, clocks: np.ndarray) -> None:
        """Put :meth:`take_clocks` clocks back in front of the stream."""
        self.unread(np.asarray(clocks).reshape(-1, self._operators))


# --- Decoding raw result payloads, from the layout ---

def layout_fields(layout: Any, base: int = 0, prefix: str = "") -> dict[str, tuple[int, int]]:
    """Leaf fields of an Amaranth data layout as ``{"counts[3]": (offset, width)}``, offsets from bit 0."""
    from amaranth.lib import data

    out: dict[str, tuple[int, int]] = {}
    for key, field in layout:
        name = f"{prefix}[{key}]" if isinstance(key, int) else (f"{prefix}.{key}" if prefix else key)
        if isinstance(field.shape, data.Layout):
            out.update(layout_fields(field.shape, base + field.offset, name))
        else:
            out[name] = (base + field.offset, field.width)
    return out


@functools.lru_cache(maxsize=32)
def _result_plan(params: MachineParams) -> tuple[int, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """(payload bits, {field: (bit offsets, widths)}) of ``result_layout(params)``, per result field."""
    from amaranth.hdl import Shape

    from bayesmachine.hdl.signatures import result_layout

    layout = result_layout(params)
    leaves = layout_fields(layout)
    plan: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name in _DTYPES:
        if name in leaves:  # a scalar field
            cols = [leaves[name]]
        else:  # an array field: its elements in index order
            cols = [v for k, v in leaves.items() if k.startswith(name + "[")]
        if not cols:
            raise ValueError(f"result layout {layout!r} has no field {name!r}")
        if any(w > 32 for _, w in cols):
            raise ValueError(f"result field {name!r} is wider than 32 bits")
        plan[name] = (np.array([o for o, _ in cols], np.int64), np.array([w for _, w in cols], np.int64))
    return Shape.cast(layout).width, plan


def result_words(params: MachineParams) -> int:
    """32-bit words of one raw result payload."""
    return (_result_plan(params)[0] + 31) // 32


def decode_results(params: MachineParams, raw: np.ndarray | list[int]) -> MachineResult:
    """Raw ``result`` payloads -> :class:`MachineResult`, by the offsets of ``result_layout(params)``.

    ``raw``: Python ints (one payload each, as the simulator samples them) or a (P, words) array
    of little-endian uint32 words (as the Verilator harness returns them).
    """
    nwords = result_words(params)
    if isinstance(raw, list):
        blob = b"".join(int(r).to_bytes(4 * nwords, "little") for r in raw)
        raw = np.frombuffer(blob, dtype="<u4").reshape(len(raw), nwords)
    words = np.asarray(raw, dtype=np.uint64)
    if words.ndim != 2 or words.shape[1] != nwords:
        raise ValueError(f"raw results must have shape (pixels, {nwords}), got {words.shape}")
    words = np.concatenate([words, np.zeros((len(words), 1), np.uint64)], axis=1)  # for straddling fields
    _, plan = _result_plan(params)
    out: dict[str, np.ndarray] = {}
    for name, (offsets, widths) in plan.items():
        lo = words[:, offsets >> 5]
        hi = words[:, (offsets >> 5) + 1]
        shift, mask = (offsets & 31).astype(np.uint64), ((1 << widths) - 1).astype(np.uint64)
        v = ((lo | (hi << np.uint64(32))) >> shift) & mask
        v = v.astype(_DTYPES[name])
        out[name] = v if name == "counts" else v[:, 0]
    return MachineResult(**out)
