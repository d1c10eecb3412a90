"""What a lane builder gets of its word generator: a :class:`LaneContext`, the generator's shared pipeline of
one elaboration seen through a few small protocols, one per concern.

- :class:`PassShape`: the pass and its machine (what the lanes compute, fixed before any hardware);
- :class:`PixelTake`: the pixel the lanes take (``take``, its reference features ``left``, a value of it
  registered at the take, each lane row's match features from the delay line: ``entry``);
- :class:`BeatIssue`: the beats issued (the beat counter, the stall of the look-up pipeline, a value
  carried with its beat to the stream, a table read at a lane's cost: ``lookup``);
- :class:`PixelScan`: a pass that scans an output pixel's beats before its words (a fused column's
  smallest sum: the ring of pixels waiting, the fetches, ``hold_scan``);
- :class:`GeneratorPorts`: the generator's ports a lane builder declared (``Lanes.members``) and the
  generator's arguments it reads.

The word generator's pipeline (:class:`~bayesmachine.hdl.frontend.wordpipe.WordPipeline`) is the one
implementation; a lane builder names only these.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from amaranth.hdl import Module, Signal, Value
from amaranth.lib import data, stream, wiring

if TYPE_CHECKING:
    import numpy as np

    from bayesmachine.models import Pass
    from bayesmachine.params import MachineParams

    from ..shared import FusedShare
    from ..tables import FrontEndTables, LoadForm

__all__ = ["BeatIssue", "GeneratorPorts", "LaneContext", "PassReference", "PassShape", "PixelScan",
           "PixelTake"]


class PassReference(Protocol):
    """The pass's reference image on chip (:mod:`~bayesmachine.hdl.frontend.reference`)."""

    def entry(self, d: int, dmax: int) -> int:
        """The delay-line entry lane d reads."""

    def lane_valid(self, ctx: LaneContext, j: int) -> Value | None:
        """Whether lane row j of the beat on the stream has a match pixel (None: always)."""

    def match_ok(self, ctx: LaneContext, row: Value, scanned: bool = False) -> Value | None:
        """Whether row ``row`` of the pixel taken (or being scanned) has a match pixel (None: always)."""


class PassShape(Protocol):
    """The pass, its machine and the module the lanes are built in."""

    @property
    def m(self) -> Module: ...
    @property
    def params(self) -> MachineParams: ...
    @property
    def pass_(self) -> Pass: ...
    @property
    def reference(self) -> PassReference: ...
    @property
    def tables(self) -> FrontEndTables: ...
    @property
    def form(self) -> LoadForm:
        """What the machine loads (its integrator's: words or energy codes)."""
    @property
    def dmax(self) -> int: ...
    @property
    def rows_per_beat(self) -> int:
        """R: the lane rows of a beat (each loaded column's lanes)."""
    @property
    def n_beats(self) -> int:
        """Beats per output pixel."""
    @property
    def one(self) -> int:
        """The loaded value of a factor 1.0."""
    @property
    def zero(self) -> int:
        """The loaded value of a factor 0."""


class PixelTake(Protocol):
    """The pixel the lanes take."""

    @property
    def pixel(self) -> data.View:
        """The pixel the lanes take (:func:`~..layouts.pass_pixel_layout`)."""
    @property
    def take(self) -> Value:
        """The lanes take ``pixel`` this cycle."""
    @property
    def left(self) -> Signal:
        """The reference features of the pixel taken (its ``left`` field), registered."""

    def taken(self, field: str) -> Signal:
        """The pixel's flag ``field`` (``row_start``, ``flush``, ...), registered at the take (one register
        per field)."""

    def entry(self, plane: str, j: int) -> Signal:
        """The ``plane`` value of lane row j's match pixel for the beat being issued (or fetched)."""


class BeatIssue(Protocol):
    """The beats of an output pixel, issued one a cycle into a look-up pipeline that stalls with the
    stream: the issue, the cost register, the address register, the table read, the beat on the stream."""

    @property
    def beats(self) -> data.View:
        """The load stream's payload (the beat on the stream)."""
    @property
    def beat(self) -> Signal:
        """The beat being issued."""
    @property
    def advance(self) -> Value:
        """The look-up pipeline moves (the stream is free)."""

    def row(self, j: int) -> Value:
        """The row of lane row j of the beat being issued."""

    def aligned(self, value: Value, name: str) -> Signal:
        """``value`` of the issue's cycle, with its beat on the stream."""

    def lookup(self, name: str, words: np.ndarray, costs: list[Value], en: Value | None = None,
               bits: int | None = None) -> list[Value]:
        """Each lane row's read of table ``words`` at its cost ``costs[j]``, with the beat on the stream
        (``en``: the registers' enable, default ``advance``; ``bits``: a table of ``bits``-bit codes)."""


class PixelScan(Protocol):
    """A pass that scans: the pixels from the stream wait in a ring of slots for their scans (one fetch of
    a beat's delay-line entries a cycle) and then for the lanes."""

    @property
    def fed(self) -> data.View:
        """The pixel stream's payload (the pixel taken from the stream, ``pixel`` unless the pass scans)."""
    @property
    def fed_take(self) -> Value:
        """A pixel is taken from the stream this cycle."""
    @property
    def scan_pixel(self) -> Signal:
        """The pixel being scanned."""
    @property
    def fetch(self) -> Value:
        """A fetch this cycle (the beat ``fetch_beat`` of the slot ``fetch_slot``)."""
    @property
    def fetch_beat(self) -> Signal: ...
    @property
    def fetch_slot(self) -> Signal: ...
    @property
    def slots(self) -> int:
        """The ring's slots."""
    @property
    def take_slot(self) -> Signal:
        """The slot of the pixel the lanes take next."""
    @property
    def issue_slot(self) -> Signal:
        """The slot of the pixel whose beats issue."""

    def hold_scan(self, may: Value) -> None:
        """An output pixel is taken from the stream (its scan starts) only while ``may`` too."""


class GeneratorPorts(Protocol):
    """The generator's ports of the lane builders (each declared once, by its lane builder's
    ``members``) and the generator's arguments the lanes read."""

    @property
    def output_columns(self) -> int | None: ...
    @property
    def leads(self) -> bool: ...
    @property
    def fused_share(self) -> FusedShare | None: ...

    def map_stream(self, name: str) -> stream.Interface:
        """The stream of MAPs in named ``name`` (``maps``, ``<pass>_maps``)."""

    def signal_port(self, name: str) -> Signal:
        """The one-bit port ``name`` (``frame_reset``)."""

    def shared_port(self, name: str) -> wiring.PureInterface:
        """The interface port ``name`` (``fused_sums``: to the shared sums' writer or reader)."""


class LaneContext(PassShape, PixelTake, BeatIssue, PixelScan, GeneratorPorts, Protocol):
    """A lane builder's view of the word generator's shared pipeline (see the module text)."""
