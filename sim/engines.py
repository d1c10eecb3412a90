"""Engines: interchangeable ways to run the machine on pixels' likelihood memories.

The contract (:class:`Engine`), which ``model``, ``pysim`` and ``verilator`` implement through
:class:`EngineBase`, so that they validate their input once, the same way, with the same errors:

- ``run(words, numbers=None, line_start=None) -> MachineResult``: pixels in order; the machine's state (LFSRs,
  or the position in an off-chip source's stream) carries over from one call to the next, so
  a frame can be run in chunks. ``numbers``: only for an off-chip random source (``rng``
  whose :class:`~bayesmachine.sources.SourceKind` has ``on_chip = False``): a (T, operators)
  array of W-bit numbers, one row per compute cycle, consumed from its first row by this call
  (running out is a ``ValueError``), or a :class:`~bayesmachine.sources.NumberSource`. With
  ``numbers=None`` the kind's own device model is used (one stream from reset on); the kind
  ``external`` has none, so it needs ``numbers``. ``line_start``: only for a machine with a
  neighbour prior (``prior = "neighbour"``): one flag per pixel, set where the pixel has no left
  neighbour (its feedback prior is flat); the machine's previous result carries over between calls.
- ``reset()``: back to the state after a hardware reset. ``close()``: release resources;
  ``run()`` or ``reset()`` afterwards raise :class:`EngineClosedError`.
- ``wall_cycles``: clock cycles since reset, loading included (``None`` for the model,
  which does not time loading).

A run cut short (its numbers ran out) leaves pixels in flight: every engine then refuses to
run (:class:`EngineStateError`) until ``reset()``.

- ``model``: the NumPy/numba machine model (the definition; whole frames in seconds).
- ``pysim``: the RTL in Amaranth's Python simulator (hundreds of cycles per second: crops).
- ``verilator``: the emitted Verilog compiled with Verilator (whole frames, cycle-accurate RTL).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING, ClassVar, Protocol, TypeVar

import numpy as np

from bayesmachine.params import MachineParams
from bayesmachine.sim.results import (
    ArrayNumbers,
    EngineClosedError,
    EngineStateError,
    MachineResult,
    NumberFeed,
    check_line_start,
    check_words,
)
from bayesmachine.sources import SOURCE_KINDS

if TYPE_CHECKING:
    from bayesmachine.sources import NumberSource

__all__ = ["ENGINES", "Engine", "EngineBase", "EngineClosedError", "EngineLifecycle", "EngineStateError",
           "get_engine"]

ENGINES = ("model", "pysim", "verilator")

_E = TypeVar("_E", bound="EngineLifecycle")

CLOSED_MESSAGE = "this engine is closed (close() was called): create a new one to run more pixels"
BROKEN_MESSAGE = ("an earlier run was cut short, so pixels are still in flight and later results would "
                  "not match; call reset() to start again from a hardware reset")


class Engine(Protocol):
    @property
    def params(self) -> MachineParams: ...

    def run(self, words: np.ndarray, numbers: np.ndarray | None = None,
            line_start: np.ndarray | None = None) -> MachineResult: ...

    def reset(self) -> None: ...

    def close(self) -> None: ...

    @property
    def wall_cycles(self) -> int | None: ...


class EngineLifecycle:
    """The contract's life cycle, shared with engines that take other input than words (the
    StereoMachine's pixel pairs): ``reset()``, ``close()``, ``EngineClosedError`` after it, and
    ``EngineStateError`` after a run cut short, until ``reset()``.

    A subclass runs each request inside ``with self._in_flight():`` after :meth:`_check_open` and its
    input checks, and may override ``_reset()`` and ``_close()``.
    """

    def __init__(self) -> None:
        self._closed = False
        self._broken = False

    @property
    def wall_cycles(self) -> int | None:
        return None

    def _check_open(self) -> None:
        if self._closed:
            raise EngineClosedError(CLOSED_MESSAGE)

    @contextlib.contextmanager
    def _in_flight(self) -> Iterator[None]:
        """Around a run: refused after a run cut short; a run that raises leaves the engine broken."""
        if self._broken:
            raise EngineStateError(BROKEN_MESSAGE)
        self._broken = True  # until every pixel of this call is back
        yield
        self._broken = False

    def reset(self) -> None:
        """Back to the state after a hardware reset."""
        self._check_open()
        self._broken = False
        self._reset()

    def _reset(self) -> None:
        pass

    def close(self) -> None:
        """Release the engine's resources; later ``run()``/``reset()`` raise :class:`EngineClosedError`."""
        if not self._closed:
            self._closed = True
            self._close()

    def _close(self) -> None:
        pass

    def __enter__(self: _E) -> _E:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class EngineBase(EngineLifecycle):
    """What the engines share: input checks, the random-number supply, reset/close, the error rules.

    A subclass implements ``_run(words, feed)`` (``words`` checked, (P, operators) int32;
    ``feed`` None for an on-chip source) and may override ``_reset()`` and ``_close()``.
    """

    name: ClassVar[str] = ""
    OPTIONS: ClassVar[tuple[str, ...]] = ()  # keyword options of the constructor (get_engine checks them)
    FEEDBACK: ClassVar[bool] = False  # runs a neighbour prior (``_run_feedback``)

    def __init__(self, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"an engine takes a MachineParams, not {type(params).__name__}")
        if params.feedback_columns and not self.FEEDBACK:
            raise ValueError(f"the {self.name} engine does not run a machine with prior = 'neighbour' yet")
        super().__init__()
        self._params = params
        self._kind = SOURCE_KINDS[params.rng]
        self._feed = NumberFeed(params)
        self._device: NumberSource | None = None
        self._new_supply = False  # this run's numbers come from another source than the last run's

    @property
    def params(self) -> MachineParams:
        return self._params

    def run(self, words: np.ndarray, numbers: np.ndarray | NumberSource | None = None,
            line_start: np.ndarray | None = None) -> MachineResult:
        """Run pixels through the machine (see the module docstring)."""
        self._check_open()
        q = check_words(self._params, words)
        flags = check_line_start(self._params, line_start, q.shape[0])
        source = self._source(numbers)
        with self._in_flight():
            self._new_supply = self._feed.use(source)
            feed = None if source is None else self._feed
            return self._run(q, feed) if flags is None else self._run_feedback(q, feed, flags)

    def _run_feedback(self, words: np.ndarray, feed: NumberFeed | None,
                      line_start: np.ndarray) -> MachineResult:
        raise NotImplementedError

    def _source(self, numbers: np.ndarray | NumberSource | None) -> NumberSource | None:
        p = self._params
        if self._kind.on_chip:
            if numbers is not None:
                raise ValueError(f"random numbers are only taken by an off-chip source; rng = {p.rng!r} "
                                 "generates them on chip")
            return None
        if numbers is None:
            if self._kind.numbers is None:
                raise ValueError(f"rng = {p.rng!r}: pass the random numbers of every compute cycle "
                                 "(numbers=, shape (cycles, operators))")
            if self._device is None:
                self._device = self._kind.numbers(p)
            return self._device
        if not isinstance(numbers, np.ndarray) and hasattr(numbers, "take"):
            return numbers  # a NumberSource: the caller's stream
        return ArrayNumbers(p, np.asarray(numbers))

    def _run(self, words: np.ndarray, feed: NumberFeed | None) -> MachineResult:
        raise NotImplementedError

    def reset(self) -> None:
        """Back to the state after a hardware reset (an off-chip device model starts a fresh stream)."""
        self._check_open()
        self._device = None
        self._feed.use(None)
        super().reset()


def _engine_class(name: str) -> type[EngineBase]:
    if name == "model":
        from bayesmachine.sim.model import MachineModel

        return MachineModel
    if name == "pysim":
        from bayesmachine.sim.pysim import PysimEngine

        return PysimEngine
    if name == "verilator":
        from bayesmachine.sim.verilator import VerilatorEngine

        return VerilatorEngine
    raise ValueError(f"unknown engine {name!r}: choose one of {', '.join(ENGINES)}")


def get_engine(name: str, params: MachineParams, **options: object) -> Engine:
    """A fresh engine (machine state as after reset) by name: one of :data:`ENGINES`.

    ``options`` go to the engine's constructor; one it does not take is a ``ValueError``.
    """
    cls = _engine_class(name)
    unknown = sorted(set(options) - set(cls.OPTIONS))
    if unknown:
        takes = ", ".join(cls.OPTIONS) if cls.OPTIONS else "no options"
        raise ValueError(f"engine {name!r} does not take option(s) {', '.join(unknown)}; it takes {takes}")
    return cls(params, **options)
