"""The lane builder contract: the RTL of one column kind in a word generator, and the registry that
chooses it from the column's class.

A word generator (:class:`~bayesmachine.hdl.frontend.words.WordGenerator`) writes a pass's output
pixels' words; lane L of a beat holds operator column L % C of row b·R + L // C (C loaded columns, R
rows per beat), so each operator column owns R lanes of every beat. A column kind's lane builder, a
subclass of :class:`Lanes` registered for the kind with :func:`register`, says in one place:

- what its words need of the pixels: the planes both images give (``filters``: a FEATURES column's
  :class:`PlaneFilter` of the line buffer's column in the feature pipeline, and the shape of the
  plane it reads) and the position flags it reads (``flags``: ``row_start``, ``first_row``,
  ``consult``, which the feature pipeline computes);
- the ports it adds to the generator (``members``: its own pass's MAPs in for a line of MAPs, another
  pass's MAPs in), each declared here once: the front end takes its ports from them;
- what it needs of the model beyond its column (``check``: a pass column's pass), a ``ParameterError``
  naming the model otherwise;
- on the generator's shared pipeline (a :class:`~.context.LaneContext`: issue, cost
  register, address register, table read, the beat on the stream), per lane row j of the beat on the
  stream its word (``word(j)``, rows 0..Dmax) and its word in the no-match row (``nomatch()``), and
  whether a pixel may be taken (``ready()``).

The generator loops over its pass's columns and asks each for these; nothing outside a lane builder
knows which kinds a model has. The no-match rule (:class:`~bayesmachine.columns.NoMatchFloor`) has a
lane builder too: its word sits in the no-match row of the pass's first FEATURES column.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from amaranth.hdl import Const, ShapeLike, Value, ValueLike
from amaranth.lib import wiring

from bayesmachine.columns import PlaneColumn, Source, Term
from bayesmachine.errors import ParameterError
from bayesmachine.models import ModelParams, Pass
from bayesmachine.params import MachineParams

from .context import LaneContext

__all__ = ["Lanes", "PlaneFilter", "PlaneLanes", "lanes_for", "register"]


@dataclass(frozen=True)
class PlaneFilter:
    """A filter of one image's windows in the feature pipeline: the ``height`` middle lines of the line
    buffer's column in, planes out (``shapes``: name -> shape). Equal filters (one kind, one set of
    parameters) are one filter per image, shared by every column that reads its planes; its submodules
    are ``{name}_left`` and ``{name}_right``."""

    @property
    def name(self) -> str:
        raise NotImplementedError

    @property
    def height(self) -> int:
        raise NotImplementedError

    @property
    def shapes(self) -> dict[str, ShapeLike]:
        raise NotImplementedError

    def build(self) -> wiring.Component:
        """The filter: ``load`` (``In(1)``: take ``column``), ``column`` (``height`` gray levels, the top
        line first) and ``en`` (``In(1)``: shift the column loaded earlier into the window)."""
        raise NotImplementedError

    def outputs(self, filt: wiring.Component) -> dict[str, Value]:
        """The planes of the window last shifted in, from the filter's outputs."""
        raise NotImplementedError


class Lanes:
    """A column kind's lanes in a word generator (a subclass per kind; see the module's text).

    The class methods declare, from the column alone, what the generator's signature and the pixels
    need; an instance builds the lanes on one elaboration's nets (``build``, then ``word``,
    ``nomatch``, ``ready``).

    Parameters
    ----------
    term : Term
        The column (or the no-match rule) whose lanes these are.
    ctx : LaneContext
        The generator's shared pipeline of this elaboration.
    """

    # --- Declarations ---
    @classmethod
    def filters(cls, term: Term, margin: int) -> tuple[PlaneFilter, ...]:
        """The plane filters its words need, for a model of ``margin`` (the windows' centre line)."""
        return ()

    @classmethod
    def planes(cls, term: Term, margin: int) -> dict[str, ShapeLike]:
        """The planes it reads (name -> shape)."""
        return {}

    @classmethod
    def flags(cls, term: Term) -> tuple[str, ...]:
        """The feature pipeline's position flags each pixel must carry for it."""
        return ()

    @classmethod
    def members(cls, term: Term, params: MachineParams) -> dict[str, wiring.Member]:
        """The ports it adds to the generator."""
        return {}

    @classmethod
    def check(cls, term: Term, model: ModelParams, p: Pass) -> None:
        """``ParameterError`` naming the model unless its lanes can run in pass ``p`` of ``model``."""

    @classmethod
    def needs_row(cls, term: Term) -> bool:
        """Whether its lanes need the pass's output pixels per row (the generator's ``output_columns``): an
        ABOVE column's line of MAPs, a semi-global column's memories of the row above."""
        return term.source is Source.ABOVE

    @classmethod
    def dealt(cls, term: Term) -> bool:
        """Whether its lanes can run when the pass's map rows are dealt to several machines (each machine's
        word generator sees every K-th row)."""
        return True

    @classmethod
    def scan_latency(cls, term: Term, n_beats: int) -> int:
        """0, or the cycles from a pixel's last fetch of the delay line's entries to an issue that can read
        what they give, at ``n_beats`` beats per pixel, when its words need every row of the pixel first: the
        word generator then scans the pixel's beats before its words (``LaneContext.fetch``; a fused
        column's smallest sum)."""
        return 0

    # --- One elaboration ---
    def __init__(self, term: Term, ctx: LaneContext) -> None:
        self.term = term
        self.ctx = ctx

    def build(self) -> None:
        """Build the lanes' logic (tables, registers, submodules) in ``ctx.m``."""

    def ready(self) -> Value:
        """High when a pixel may be taken."""
        return Const(1)

    def word(self, j: int) -> ValueLike:
        """The word of lane row j (row ``beat * R + j`` <= Dmax) of the beat on the stream."""
        raise NotImplementedError

    def nomatch(self) -> ValueLike:
        """The word of the no-match row, with the beat on the stream."""
        raise NotImplementedError


class PlaneLanes(Lanes):
    """A FEATURES column's lanes: per lane row the cost (``cost``) of the reference pixel's value of the
    column's plane and the match pixel's (the delay line's entry of the lane), read in the column's
    clamped table; its no-match entry a constant of its table (``Column.nomatch_entry``). A subclass
    names the plane's filter (``filter``) and the cost, and whether the cost is ``symmetric``
    (|cost(a, b)| = |cost(b, a)|: two passes of opposite references then compare a pair alike)."""

    symmetric = False

    @classmethod
    def filter(cls, term: PlaneColumn, margin: int) -> PlaneFilter:
        """The filter giving the plane ``term`` reads, for a model of ``margin``."""
        raise NotImplementedError

    @classmethod
    def filters(cls, term: PlaneColumn, margin: int) -> tuple[PlaneFilter, ...]:
        return (cls.filter(term, margin),)

    @classmethod
    def planes(cls, term: PlaneColumn, margin: int) -> dict[str, ShapeLike]:
        return {term.plane: cls.filter(term, margin).shapes[term.plane]}

    def cost(self, ref: Value, match: Value) -> Value:
        """The cost of the reference pixel's value ``ref`` and the match pixel's ``match`` (its absolute
        value is the table's address)."""
        raise NotImplementedError

    def costs(self) -> list[Value]:
        """Each lane row's cost, of the delay line's entries of the beat being fetched (a fused column
        reads its members' costs here)."""
        n, c = self.ctx, self.term
        return [self.cost(getattr(n.left, c.plane), n.entry(c.plane, j)) for j in range(n.rows_per_beat)]

    def build(self) -> None:
        n, c = self.ctx, self.term
        self._words = n.lookup(c.name, n.tables[c.name], self.costs())

    def word(self, j: int) -> ValueLike:
        return self._words[j]

    def nomatch(self) -> ValueLike:
        form = self.ctx.form
        return form.value(self.term.nomatch_entry(self.term.table(form.table_bits)))


_LANES: dict[type, type[Lanes]] = {}


def register(*kinds: type[Term]) -> Callable[[type[Lanes]], type[Lanes]]:
    """Class decorator: the lane builder of column kinds ``kinds`` (and of their subclasses)."""
    def wrap(cls: type[Lanes]) -> type[Lanes]:
        for kind in kinds:
            _LANES[kind] = cls
        return cls
    return wrap


def lanes_for(term: Term) -> type[Lanes]:
    """The lane builder of ``term``'s kind (its class's or its nearest base's); ``ParameterError`` naming
    the model when the front end has none (a column kind without RTL)."""
    for kind in type(term).__mro__:
        if kind in _LANES:
            return _LANES[kind]
    raise ParameterError(f"model: the on-chip front end has no lane builder for the {term.name} column "
                         f"({type(term).__name__}): add one under hdl/frontend/lanes", "model")
