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
- ``pysim``: the RTL in Amaranth's Python simulator (about 100 clock cycles per CPU second for the
  Dmax = 80 machine, a few thousand for a Dmax = 8 one: ``benchmarks/bench_pysim.py``; crops).
- ``verilator``: the emitted Verilog compiled with Verilator (whole frames, cycle-accurate RTL).

**Pixel engines** (:class:`PixelEngine`, through :class:`PixelEngineBase`) take the rectified pair
itself: the front end on chip computes the words (``--feed pixels``).

- ``run(left, right) -> MachineResult``: one frame ((H, width) uint8 each, H >= 2k + 1 for the
  model's margin k); the results of its output region (:class:`~bayesmachine.region.OutputRegion`),
  row-major, bit for bit the model's on the host's words of the frame. ``last_passes``: the results
  of the model's declared passes (census-lr's right pass) of the last frame, by pass name (empty
  without one). ``reset()``, ``close()``, ``wall_cycles`` and the
  errors as above; ``figures``: what the engine says of its runs beyond the results (None).
- ``verilator``: the ``StereoMachine`` compiled with Verilator; frames run back to back (the
  machine's random sources carry over).
- ``board``: a board running the ``StereoMachine`` (or ``bayesmachine board simulate``) over its
  serial link; it resets the machine at every frame. Its ``figures`` are the link's.

The registry maps each name to its class's import path, imported when asked for: ``sim`` imports
neither ``fpga`` (the board's engine) nor an engine's tools before they are needed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING, ClassVar, Protocol, TypeVar

import numpy as np

from bayesmachine.integrators import INTEGRATOR_KINDS, load_named
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.region import OutputRegion
from bayesmachine.sim.results import (
    ArrayNumbers,
    EngineClosedError,
    EngineStateError,
    MachineResult,
    NumberFeed,
    check_line_start,
    check_words,
)

if TYPE_CHECKING:
    from bayesmachine.sources import NumberSource

__all__ = ["ENGINES", "PIXEL_ENGINES", "Engine", "EngineBase", "EngineClosedError", "EngineLifecycle",
           "EngineStateError", "PixelEngine", "PixelEngineBase", "check_engine_options",
           "check_pixel_engine_options", "get_engine", "get_pixel_engine"]

# The registry: each engine's class, as "module:Class" (imported when asked for); the engines of a
# machine are its integrator kind's (bayesmachine.integrators), the pixel engines these.
_PIXEL_ENGINES = {
    "verilator": "bayesmachine.sim.stereo_engine:StereoVerilatorEngine",
    "board": "bayesmachine.fpga.boards.engine:BoardEngine",
}
ENGINES = tuple(dict.fromkeys(name for kind in INTEGRATOR_KINDS.values() for name in kind.engines))
PIXEL_ENGINES = tuple(_PIXEL_ENGINES)

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
        self._kind = params.source  # None: the machine draws no random numbers
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
        if self._kind is None or self._kind.on_chip:
            if numbers is not None:
                raise ValueError(f"random numbers are only taken by an off-chip source; rng = {p.rng!r} "
                                 "generates them on chip" if self._kind is not None else
                                 f"integrator = {p.integrator!r} draws no random numbers: pass none")
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


class PixelEngine(Protocol):
    @property
    def params(self) -> MachineParams: ...

    @property
    def model(self) -> ModelParams: ...

    @property
    def width(self) -> int: ...

    def run(self, left: np.ndarray, right: np.ndarray) -> MachineResult: ...

    @property
    def last_passes(self) -> dict[str, MachineResult]: ...

    @property
    def figures(self) -> dict[str, object] | None: ...

    def reset(self) -> None: ...

    def close(self) -> None: ...

    @property
    def wall_cycles(self) -> int | None: ...


class PixelEngineBase(EngineLifecycle):
    """What the pixel engines share: the machine, the model and the line width they were built for,
    and the one check of a frame (:meth:`_check_frame`, the same errors in every engine).

    A subclass's ``run(left, right)`` calls :meth:`_check_open` and :meth:`_check_frame`, then runs
    inside ``with self._in_flight():``.
    """

    name: ClassVar[str] = ""
    OPTIONS: ClassVar[tuple[str, ...]] = ()  # the constructor's keyword options (get_pixel_engine checks)

    def __init__(self, params: MachineParams, model: ModelParams, width: int) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"an engine takes a MachineParams, not {type(params).__name__}")
        if not isinstance(model, ModelParams):
            raise TypeError(f"a pixel engine takes a ModelParams, not {type(model).__name__}")
        super().__init__()
        self._params, self._model, self._width = params, model, width
        self.last_passes: dict[str, MachineResult] = {}

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def width(self) -> int:
        return self._width

    @property
    def figures(self) -> dict[str, object] | None:
        """What the engine reports of its runs beyond the results (the board: its link's figures)."""
        return None

    @classmethod
    def check_options(cls, **options: object) -> None:
        """TypeError/ValueError naming a bad constructor option, before any work (the constructor
        checks them again)."""

    def _check_frame(self, left: np.ndarray, right: np.ndarray) -> OutputRegion:
        """ValueError naming the problem unless ``left``, ``right`` are a frame this engine takes; the
        frame's output region."""
        for name, image in (("left", left), ("right", right)):
            image = np.asarray(image)
            if image.ndim != 2 or image.dtype != np.uint8:
                raise ValueError(f"{name} image must be 2-D uint8 gray, got {image.dtype} {image.shape}")
        if left.shape != right.shape:
            raise ValueError(f"left and right images differ in shape: {left.shape} vs {right.shape}")
        height, width = left.shape
        if width != self._width:
            raise ValueError(f"this stereo machine was built for {self._width}-pixel lines, the frame has "
                             f"{width}")
        k = self._model.margin  # the output region's: every window inside the frame
        if height < 2 * k + 1:
            raise ValueError(f"a frame needs at least {2 * k + 1} lines for the model's "
                             f"{2 * k + 1}x{2 * k + 1} windows, got {height}")
        return OutputRegion.of_model(left.shape, self._model)


def _load(registry: dict[str, str], name: str, kind: str) -> type:
    if name not in registry:
        raise ValueError(f"unknown {kind} {name!r}: choose one of {', '.join(registry)}")
    return load_named(registry[name])


def check_engine_options(cls: type, name: str, options: dict[str, object]) -> None:
    """ValueError unless ``cls`` (an engine class of the registry) takes every keyword of ``options``."""
    unknown = sorted(set(options) - set(cls.OPTIONS))  # type: ignore[attr-defined]
    if unknown:
        takes = ", ".join(cls.OPTIONS) if cls.OPTIONS else "no options"  # type: ignore[attr-defined]
        raise ValueError(f"engine {name!r} does not take option(s) {', '.join(unknown)}; it takes {takes}")


def get_engine(name: str, params: MachineParams, **options: object) -> Engine:
    """A fresh engine (machine state as after reset) by name: one of the engines of the machine's
    integrator kind (``params.kind.engines``: e.g. the model of a log machine is
    ``sim.log_model.LogMachineModel``, its pysim and verilator run ``hdl.log.machine``).

    ``options`` go to the engine's constructor; one it does not take is a ``ValueError``.
    """
    if not isinstance(params, MachineParams):
        raise TypeError(f"an engine takes a MachineParams, not {type(params).__name__}")
    cls = params.kind.engine_class(name)
    check_engine_options(cls, name, options)
    return cls(params, **options)


def check_pixel_engine_options(name: str, **options: object) -> None:
    """ValueError (or TypeError) unless the pixel engine ``name`` takes ``options``: for a command
    line to refuse a bad option before any work."""
    cls = _load(_PIXEL_ENGINES, name, "pixel engine")
    check_engine_options(cls, name, options)
    cls.check_options(**options)


def get_pixel_engine(name: str, params: MachineParams, model: ModelParams, width: int,
                     **options: object) -> PixelEngine:
    """A fresh pixel engine by name, one of :data:`PIXEL_ENGINES`, for frames of ``width``-pixel
    lines; ``options`` go to its constructor (one it does not take is a ``ValueError``)."""
    cls = _load(_PIXEL_ENGINES, name, "pixel engine")
    check_engine_options(cls, name, options)
    return cls(params, model, width, **options)
