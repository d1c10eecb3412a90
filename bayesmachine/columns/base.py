"""The column contract: options, tables and sources shared by every column kind.

Pure computation (NumPy only): the host, the references, the machine builders and the on-chip front
end read the same tables at elaboration.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping, MutableMapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bayesmachine.checks import as_bool, as_int, as_real, shown
from bayesmachine.errors import ParameterError

from .planes import Plane

if TYPE_CHECKING:
    from .energy import EnergyTable

__all__ = [
    "Source",
    "Option",
    "Table",
    "Term",
    "Column",
    "PlaneColumn",
    "PassContext",
    "likelihood_formula",
    "quantize",
    "check_int",
    "check_bool",
    "check_switch",
    "check_probability",
    "check_sigma",
]


class Source(enum.Enum):
    """Where a column's words come from."""

    FEATURES = "features"  # both images' planes: the reference pixel's and its match's at lane d
    FEEDBACK = "feedback"  # the machine's own previous result, formed by the machine (not loaded)
    ABOVE = "above"  # the same pass's results of the map row above: a loaded column
    PASS = "pass"  # another pass's results (census-lr's right MAPs): a loaded column

    @property
    def loaded(self) -> bool:
        """Whether the host loads the column's words (a FEEDBACK column is formed by the machine)."""
        return self is not Source.FEEDBACK

    @property
    def from_results(self) -> bool:
        """Whether its words depend on results (the machine's own, or another pass's): a pass with such a
        column runs one map row at a time."""
        return self is not Source.FEATURES


# The checks follow bayesmachine.checks: an integer is what operator.index takes (NumPy integers too), a
# yes/no value a bool or a NumPy bool, a number any real but a bool; a huge integer is refused, never
# an OverflowError. ModelParams keeps the plain Python value (bayesmachine.checks.plain).


def check_int(name: str, value: object, low: int, high: int) -> None:
    """TypeError unless ``value`` is an integer (not a bool); ParameterError outside [low, high]."""
    as_int(name, value, low, high)


def check_bool(name: str, value: object) -> None:
    """TypeError unless ``value`` is True or False (a NumPy bool too)."""
    as_bool(name, value)


def check_switch(name: str, value: object, values: Mapping[str, Any]) -> None:
    """A yes/no option's check (``Option.check``): a bool."""
    check_bool(name, value)


def check_probability(name: str, value: object, positive: str = "") -> None:
    """A probability in [0, 1]; with ``positive`` (the reason) also > 0."""
    as_real(name, value)  # the type, and a finite value
    if not 0 <= value <= 1:  # type: ignore[operator]
        raise ParameterError(f"{name} must be a probability in [0, 1], got {shown(value)}", name)
    if positive and not value > 0:  # type: ignore[operator]
        raise ParameterError(f"{name} must be > 0: {positive}", name)


def check_sigma(name: str, value: object) -> None:
    """A finite sigma > 0 whose ``2 sigma^2`` is a finite positive float64 (1e-300 would square to 0)."""
    v = as_real(name, value)  # the type, and a finite value (a huge integer is not)
    if not v > 0:
        raise ParameterError(f"{name} must be a finite number > 0, got {shown(value)}", name)
    two_s2 = 2.0 * v * v
    if not (math.isfinite(two_s2) and two_s2 > 0.0):
        raise ParameterError(f"{name} = {value!r}: 2 sigma^2 = {two_s2!r} is not a finite positive float64 "
                             "(use a sigma between about 1e-150 and 1e150)", name)


@dataclass(frozen=True)
class Option:
    """One model parameter, declared once by the column kind that owns it.

    ``kind`` is ``"int"``, ``"float"`` or ``"bool"`` (a yes/no switch: ``--x/--no-x``); ``default``
    None with ``resolve`` means a default computed from the other values (``resolve(values)``);
    ``optional`` lets None stand (e.g. "the machine's watchdog"); ``default_text`` says what such a
    default is (for a help text). ``check(name, value, values)``
    raises TypeError or :class:`ParameterError` naming the parameter. ``alias``: one more flag that
    sets it (``--sigma`` sets the three feature sigmas).
    """

    name: str
    kind: str
    default: Any
    check: Callable[[str, Any, Mapping[str, Any]], None]
    help: str
    resolve: Callable[[Mapping[str, Any]], Any] | None = None
    optional: bool = False
    alias: str | None = None
    default_text: str | None = None

    @property
    def flag(self) -> str:
        """The command line's spelling."""
        return "--" + self.name.replace("_", "-")

    @property
    def flags(self) -> str:
        """Every spelling, for a message: ``--x/--no-x`` for a switch, ``--x/ALIAS`` with an alias."""
        if self.kind == "bool":
            return f"{self.flag}/--no-{self.flag[2:]}"
        return f"{self.flag}/{self.alias}" if self.alias else self.flag


def likelihood_formula(delta: np.ndarray, scale: int, p0: float, sigma: float) -> np.ndarray:
    """Paper eq. 2 from integer differences of sums: ``p0 + (1-p0) exp(-C / (2 sigma^2))`` with
    ``C = delta^2 / scale^2``, exact in float64 (every table and every plain oracle goes through it)."""
    d = np.asarray(delta, dtype=np.int64)
    cost = (d * d) / float(scale * scale)
    return p0 + (1.0 - p0) * np.exp(-cost / (2.0 * sigma * sigma))


def quantize(p: np.ndarray | float, word_bits: int) -> np.ndarray:
    """Probability -> likelihood-memory word: q = round(p * 2^W), round half up, in [0, 2^W].

    ``p * 2^W`` is exact in float64 (a power-of-two scaling) and so is its fractional part,
    so "half up" is decided exactly (``floor(x + 0.5)`` would not be: 0.5 - 2^-54 + 0.5 rounds
    to 1.0). 0 maps to 0 and 1 to 2^W. Values outside [0, 1] or NaN are errors (they mean a bug
    upstream, not something to clip silently).
    """
    check_int("word_bits", word_bits, 1, 15)  # words up to 2^15 fit uint16
    arr = np.asarray(p, dtype=np.float64)
    bad = ~((arr >= 0.0) & (arr <= 1.0))  # NaN compares false, so it lands here too
    if bad.any():
        first = arr[bad].flat[0]
        raise ValueError(f"probabilities must be in [0, 1] to quantize, got {first!r} ({int(bad.sum())} bad)")
    one = 1 << word_bits
    scaled = arr * one
    q = np.floor(scaled)
    q += (scaled - q) >= 0.5
    return np.clip(q, 0, one).astype(np.uint16)


@dataclass(frozen=True, eq=False)
class Table:
    """A term's values indexed by its cost, and its no-match row's constant entries.

    As probabilities (``word_bits`` None: float64, ``one`` 1.0: what the float64 reference multiplies)
    or as W-bit likelihood-memory words (uint16, ``one`` 2^W: what the machine and the quantized
    reference multiply).
    """

    values: np.ndarray
    nomatch: tuple[Any, ...]
    word_bits: int | None = None

    @property
    def one(self) -> float | int:
        return 1.0 if self.word_bits is None else 1 << self.word_bits

    @property
    def zero(self) -> float | int:
        return 0.0 if self.word_bits is None else 0

    def quantized(self, word_bits: int) -> Table:
        nomatch = tuple(int(quantize(v, word_bits)) for v in self.nomatch)
        return Table(quantize(self.values, word_bits), nomatch, word_bits)

    def last_change(self) -> int:
        """The first cost from which the values no longer change (a table clamped there gives the same)."""
        changes = np.flatnonzero(self.values[1:] != self.values[:-1])
        return int(changes[-1]) + 1 if changes.size else 0


class Term:
    """What every column kind and the no-match rule share: their options and their table.

    A subclass declares ``options`` (its :class:`Option` s, in the order they resolve) and
    ``likelihood(cost)``, the float64 value at a cost, over ``costs()``; ``nomatch_values()`` are its
    no-match row's constant entries. ``table()`` is checked once: every value in [0, 1] and
    nonincreasing in the cost (what makes a cost threshold of a row's words exact), named after
    ``table_parameter``.

    Parameters
    ----------
    values : Mapping[str, Any]
        The resolved values of (at least) its options: a model's (:class:`~bayesmachine.models.ModelParams`
        builds its terms; the values are checked there).
    dmax : int
        The model's largest disparity.

    Attributes
    ----------
    values : dict
        Its options' values.
    dmax : int
    """

    name: ClassVar[str]
    options: ClassVar[tuple[Option, ...]] = ()
    table_parameter: ClassVar[str] = ""

    def __init__(self, *, values: Mapping[str, Any], dmax: int) -> None:
        self.values = {o.name: values[o.name] for o in self.options}
        self.dmax = dmax
        self._tables: dict[int | None, Table] = {}
        self._energy: EnergyTable | None = None

    def __repr__(self) -> str:
        own = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({own})"

    def costs(self) -> np.ndarray:
        raise NotImplementedError

    def likelihood(self, cost: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def nomatch_values(self) -> tuple[float, ...]:
        return ()

    def planes(self) -> dict[str, Plane]:
        """The planes of both images it reads, by name (none: it reads no image)."""
        return {}

    @property
    def margin(self) -> int:
        """Pixels from its largest window's centre to its edge (0: it reads no image)."""
        return max((p.margin for p in self.planes().values()), default=0)

    def table(self, word_bits: int | None = None) -> Table:
        """The float64 table (``word_bits`` None) or its quantization to W-bit words, built once."""
        if word_bits not in self._tables:
            if word_bits is None:
                values = np.asarray(self.likelihood(self.costs()), dtype=np.float64)
                self._check_table(values)
                self._tables[None] = Table(values, tuple(float(v) for v in self.nomatch_values()))
            else:
                self._tables[word_bits] = self.table().quantized(word_bits)
        return self._tables[word_bits]

    def energy(self) -> EnergyTable:
        """Its table in energy form (:mod:`.energy`: codes of −ln of the float64 table, the no-match
        entries too), built once."""
        if self._energy is None:
            from .energy import EnergyTable  # energy.py quantizes with this module's rule

            table = self.table()
            self._energy = EnergyTable.of(table.values, table.nomatch)
        return self._energy

    def _check_table(self, values: np.ndarray) -> None:
        name = self.table_parameter
        if not ((values >= 0.0) & (values <= 1.0)).all():  # NaN fails both comparisons
            raise ParameterError(f"{name} = {self.values.get(name)!r} gives likelihoods outside [0, 1]", name)
        if (values[1:] > values[:-1]).any():
            raise ParameterError(f"{name} = {self.values.get(name)!r} gives likelihoods that grow with the "
                                 "cost", name)

    def check_machine(self, machine: Any) -> None:
        """ParameterError naming the parameter unless this term's words work on ``machine``."""

    def _nonzero_word(self, parameter: str, value: float, machine: Any, why: str, what: str = "") -> None:
        """ParameterError unless ``value`` (``parameter``'s, or ``what`` it gives) is a nonzero word."""
        w = machine.word_bits
        if int(quantize(value, w)) == 0:
            given = self.values.get(parameter, value)
            subject = f"{parameter} = {given!r}" + (f": {what} {value:.3g}" if what else "")
            raise ParameterError(f"{subject} quantizes to 0 with {w}-bit words ({why}); raise it or "
                                 "word_bits", parameter)


class Column(Term):
    """One operator column of a pass: a piece of evidence the AND gates multiply in (paper sec. 3).

    ``source`` says where its words come from (:class:`Source`); ``words(ctx)`` builds them (or their
    float64 factors) for a pass's pixels from a :class:`PassContext`: the host's twin of its lanes on
    chip. A FEATURES column is a :class:`PlaneColumn`; the others build their words from results (the
    row above's MAPs, another pass's MAPs) or are formed by the machine (FEEDBACK: not loaded).
    """

    source: ClassVar[Source]
    feeds_from: ClassVar[str] = ""  # a PASS column: the name of the pass whose results it reads
    # Its words hold the pass's no-match rule themselves (the fused column); otherwise the rule's value is
    # put in its no-match row when it is the pass's first FEATURES column.
    holds_rule: ClassVar[bool] = False

    @classmethod
    def expand(cls, values: Mapping[str, Any]) -> tuple[type[Column], ...]:
        """The column kinds it stands for with a model's ``values`` (itself; a fused kind with
        ``fuse_columns`` off: its members)."""
        return (cls,)

    @classmethod
    def layout_options(cls) -> tuple[Option, ...]:
        """The yes/no options of its own that :meth:`expand` reads."""
        return ()

    @property
    def zeroes_nomatch(self) -> bool:
        """Whether its no-match entry is 0 in every pixel: the pass's no-match row never wins."""
        return False

    def factors(self) -> tuple[Column, ...]:
        """The columns whose float64 factors, multiplied in order, are its own (itself; a fused column:
        its members): what the float64 reference multiplies."""
        return (self,)

    def words(self, ctx: PassContext) -> np.ndarray:
        """Its words (P, Dmax+2) of the pass's P pixels of ``ctx`` (row-major), in the domain of
        ``ctx.word_bits`` (uint16 words, or float64 factors with None)."""
        raise ValueError(f"the {self.name} column's words are formed by the machine, not loaded")

    def codes(self, ctx: PassContext) -> np.ndarray:
        """Its logarithmic integrator's codes (P, Dmax+2): ``log_codes`` of its float64 factors
        (``ctx.word_bits`` None)."""
        from .energy import log_codes  # energy builds on this module

        return log_codes(self.words(ctx))


class PlaneColumn(Column):
    """A FEATURES column: its table at the cost of the reference pixel's and the match pixel's values of
    its plane ``plane`` (declared with its filter and window by :meth:`planes`).

    A subclass defines ``cost(a, b)`` (reference values, match values), ``plain_cost`` (an independent
    computation: the test oracle's), ``hamming`` (the cost is popcount(a xor b), else |a - b|: what the
    reference kernel computes) and its no-match entry ``nomatch_entry(table)`` (1 unless it says
    otherwise)."""

    source = Source.FEATURES
    plane: ClassVar[str]
    hamming: ClassVar[bool] = False

    def cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def plain_cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def nomatch_entry(self, table: Table) -> float | int:
        """Its entry in the no-match row: 1 unless its kind says otherwise."""
        return table.one

    def words(self, ctx: PassContext) -> np.ndarray:
        """Lane d's word: its table at the cost of the two pixels (0 for a lane without a match pixel);
        the no-match row its entry (0 in a pass without a no-match row)."""
        table = self.table(ctx.word_bits)
        a, b = ctx.reference[self.plane], ctx.match[self.plane]
        values = table.values[self.cost(a[:, ctx.columns, None], b[:, ctx.match_columns])]
        if ctx.valid is not None:  # a lane without a match pixel never fires
            values = values * ctx.valid[None]
        n = values.shape[0] * ctx.columns.size
        out = np.empty((n, ctx.match_columns.shape[1] + 1), values.dtype)
        out[:, :-1] = values.reshape(n, -1)
        out[:, -1] = self.nomatch_entry(table) if ctx.nomatch else 0
        return out


@dataclass(frozen=True, kw_only=True)
class PassContext:
    """What a pass's columns build their words from, over a band of ``rows`` map rows.

    Attributes
    ----------
    where : str
        The pass, for messages ("the census-lr model's left pass").
    reference, match : Mapping[str, ndarray]
        The planes of the pass's reference image and of the other image, the band's rows, every map column.
    columns : ndarray
        (W,) the reference map column of each of the pass's pixels in a row.
    match_columns : ndarray
        (W, Dmax+1) the match map column of each lane (clamped inside the map).
    valid : ndarray or None
        (W, Dmax+1) bool: the lanes with a match pixel (None: all).
    nomatch : bool
        Whether the pass has a no-match row.
    word_bits : int or None
        W-bit words, or float64 factors (None).
    above : ndarray or None
        (W,) the pass's own MAPs of the map row above (-1: none), for a one-row band.
    results : Mapping[str, ndarray]
        Other passes' MAPs (rows, width) of the band's rows, by pass name (-1: none).
    grids : Mapping[str, tuple[int, int]]
        Each pass's (first map column, width), by pass name.
    rule : Term or None
        The pass's no-match rule (what a column whose words hold it reads: the fused column).
    nomatch_live : bool
        Whether the pass's no-match row can win: False when a column of the pass zeroes it in every
        pixel (the consistency column without ``lr_nomatch``).
    first_row : int
        The band's first map row (0: the frame's first).
    carry : MutableMapping or None
        What a column carries from one band to the next, by key (the semi-global column's path costs of
        the band's last row); the caller keeps one per pass and frame and gives the bands in order.
    """

    where: str
    reference: Mapping[str, np.ndarray]
    match: Mapping[str, np.ndarray]
    columns: np.ndarray
    match_columns: np.ndarray
    valid: np.ndarray | None
    nomatch: bool
    word_bits: int | None
    above: np.ndarray | None = None
    results: Mapping[str, np.ndarray] = field(default_factory=dict)
    grids: Mapping[str, tuple[int, int]] = field(default_factory=dict)
    rule: Term | None = None
    nomatch_live: bool = True
    first_row: int = 0
    carry: MutableMapping[str, Any] | None = None

    @property
    def rows(self) -> int:
        return int(next(iter(self.reference.values())).shape[0])

    def above_row(self, column: str) -> np.ndarray:
        """The MAP row above (W,) for ``column``'s words: ``ParameterError`` naming ``above`` unless given
        for a one-row band."""
        if self.above is None or self.rows != 1:
            raise ParameterError(f"above: the {column} column's words come from the pass's own MAPs of the "
                                 f"map row above, one map row at a time: pass above= (-1: none), for "
                                 f"{self.where}", "above")
        above = np.asarray(self.above)
        if above.shape != self.columns.shape:
            raise ValueError(f"above must be the MAP row above, shape {self.columns.shape}, got "
                             f"{above.shape}")
        return above

    def results_of(self, name: str, column: str) -> tuple[np.ndarray, int]:
        """The MAPs (rows, width) of pass ``name`` for these rows and its first map column: ``ParameterError``
        naming ``results`` unless given, ValueError unless of that shape."""
        if name not in self.grids:
            raise ValueError(f"the {column} column reads the {name} pass's results, which {self.where}'s "
                             "model does not run")
        first, width = self.grids[name]
        got = self.results.get(name)
        if got is None:
            raise ParameterError(f"results: the {column} column's words come from the {name} pass's MAPs: "
                                 f"pass results={{{name!r}: ...}}, for {self.where}", "results")
        got = np.asarray(got)
        if got.shape != (self.rows, width):
            raise ValueError(f"the {column} column needs the {name} pass's MAPs of its rows, shape "
                             f"{(self.rows, width)}, got {got.shape}")
        return got, first
