"""The pixel engine ``board`` (:class:`~bayesmachine.sim.engines.PixelEngine`): a board running the
StereoMachine (or ``bayesmachine board simulate``) behind its serial link, for
``bayesmachine run --engine board --port PORT``. The engine registry (``sim.engines``) imports it
by name, so that neither ``sim`` nor ``host`` imports this package.

Built, it opens the port and asks the board what it was built for (:meth:`.link.BoardLink.info`):
another width, machine or model is refused at once. Each ``run(left, right)`` is one frame through
:meth:`.link.BoardLink.run_frame` (the board resets its machine at every frame): the own pass's results,
and the declared passes' in ``last_passes`` (by pass name); ``figures`` are the link's (wall time, bytes
and rates each way, attempts) for the run's report.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from bayesmachine.checks import as_int, as_real
from bayesmachine.cliargs import DEFAULT_BAUD
from bayesmachine.errors import ParameterError
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import PixelEngineBase
from bayesmachine.sim.results import MachineResult

from . import link
from . import protocol as pr
from .link import BoardError, BoardLink

__all__ = ["BoardEngine"]


class BoardEngine(PixelEngineBase):
    """Frames through a board over its serial link (see the module text).

    Parameters
    ----------
    params, model : MachineParams, ModelParams
        The machine and the model the board was built for (its fingerprint says so).
    width : int
        Pixels per line of the frames; the board's.
    port : str
        The serial port (``/dev/ttyUSB0``, or the path ``board simulate`` printed).
    baud : int
        The baud rate the board was built for.
    timeout : float
        Seconds of silence before the board is deemed not to answer.
    fields : int or str
        The optional result fields the board sends (:func:`.protocol.fields_from_names`, or its
        ``fields`` byte); without counts, or cycles, the results have None there.
    progress : bool or None
        A progress bar (None: when stderr is a terminal).
    link_port : object or None
        An open port-like object to use instead of opening ``port`` (tests).
    """

    name = "board"
    OPTIONS = ("port", "baud", "timeout", "fields", "progress", "link_port")

    def __init__(self, params: MachineParams, model: ModelParams, width: int, *, port: str,
                 baud: int = DEFAULT_BAUD, timeout: float = 2.0, fields: int | str = pr.FIELDS_ALL,
                 progress: bool | None = None, link_port: object = None) -> None:
        from .core import check_board

        super().__init__(params, model, width)
        self.check_options(port=port, baud=baud, timeout=timeout, fields=fields)
        check_board(params, model, width)
        self._fields = _fields(fields)
        self._progress = sys.stderr.isatty() if progress is None else progress
        self._port, self._baud = port, baud
        self._owns_port = link_port is None
        self._serial = link.open_port(port, baud, timeout) if link_port is None else link_port
        self._seconds = 0.0
        try:
            self._link = BoardLink(self._serial, timeout=timeout, name=f"the board on {port}")
            self._info = self._check_board()
        except BaseException:
            self.close()
            raise

    @property
    def fields(self) -> int:
        return self._fields

    @classmethod
    def check_options(cls, *, port: object = "", baud: object = DEFAULT_BAUD, timeout: object = 2.0,
                      fields: object = pr.FIELDS_ALL, **others: object) -> None:
        if not isinstance(port, str):
            raise TypeError(f"port must be a path (str), not {type(port).__name__}")
        baud = as_int("baud", baud, 1)
        if not as_real("timeout", timeout) > 0:
            raise ParameterError(f"timeout must be positive (seconds), got {timeout}", "timeout")
        _fields(fields)

    def _check_board(self) -> pr.BoardInfo:
        """The board's info, unless it was built for another width, machine or model."""
        port, p, width = self._port, self.params, self.width
        expect = pr.board_fingerprint(p.to_dict(), self.model.to_dict(), width)
        t0 = time.perf_counter()
        info = self._link.info()
        self._seconds += time.perf_counter() - t0
        if info.width != width:
            raise BoardError(
                f"the board on {port} was built for {info.width}-pixel lines, the pair has {width}: "
                f"crop it (--crop X,Y,{info.width},H) or build the board with --width {width}"
            )
        if info.fingerprint != expect:
            raise BoardError(link.fingerprint_message(port, info.fingerprint, expect, p, self.model))
        return info

    def run(self, left: np.ndarray, right: np.ndarray) -> MachineResult:
        """One frame's results (see the module text)."""
        from tqdm import tqdm

        self._check_open()
        region = self._check_frame(left, right)
        with self._in_flight():
            t0 = time.perf_counter()
            with tqdm(total=region.pixels, unit="px", disable=not self._progress, desc="board") as bar:
                got = self._link.run_frame(left, right, self.params, self.model, self._fields, bar.update)
            self._seconds += time.perf_counter() - t0
        results = {name: _result(fields) for name, fields in got.items()}
        own = self.model.passes[-1].name
        self.last_passes = {name: res for name, res in results.items() if name != own}
        return results[own]

    @property
    def figures(self) -> dict[str, object]:
        """The link's figures since the engine was built: for the run's report."""
        st, seconds = self._link.stats, self._seconds

        def rate(count: int) -> float | None:
            return count / seconds if seconds > 0 else None

        return {
            "port": self._port,
            "baud": self._baud,
            "wall_seconds": seconds,
            "bytes_sent": st.bytes_sent,
            "bytes_received": st.bytes_received,
            "link_bytes_per_second": rate(st.bytes_sent + st.bytes_received),
            "sent_bytes_per_second": rate(st.bytes_sent),
            "received_bytes_per_second": rate(st.bytes_received),
            "attempts": st.attempts,
            "failures": st.failures,
            "garbage_bytes": st.garbage_bytes,
            "board_fingerprint": f"{self._info.fingerprint:08x}",
            "fields": ["map", *(n for n in ("counts", "cycles") if self._fields & pr.FIELD_NAMES[n])],
        }

    def _close(self) -> None:
        if self._owns_port:
            self._serial.close()  # type: ignore[attr-defined]


def _result(got: dict[str, np.ndarray]) -> MachineResult:
    """A pass's decoded records (:meth:`.protocol.ResultFormat.decode`) in the contract's dtypes; a field
    not asked for is absent (None), never made up."""
    counts, cycles = got.get("counts"), got.get("cycles")
    return MachineResult(
        counts=None if counts is None else counts.astype(np.uint32), map=got["map"].astype(np.int32),
        nomatch=got["nomatch"], timeout=got["timeout"],
        cycles=None if cycles is None else cycles.astype(np.int64))


def _fields(fields: object) -> int:
    """The ``fields`` byte of a list of names (:func:`.protocol.fields_from_names`) or of the byte
    itself, checked (TypeError, ValueError)."""
    if isinstance(fields, str):
        return pr.fields_from_names(fields)
    try:
        return as_int("fields", fields, 0, pr.FIELDS_ALL)
    except TypeError:
        raise TypeError(f"fields must be an integer or a list of names, not {type(fields).__name__}") \
            from None
