"""The fused column: a pass's image columns as one operator column, summed in the energy form.

A pass's FEATURES columns (m, gH, gV, census, ...) depend on the two images only, so each row's product
of them is known before the run. The fused column forms that product in the energy form
(:mod:`.energy`: integer codes of −ln L) and hands the machine one word per row, its members' product
up to a factor common to the pixel's rows:

    S_r    = Σ_k E_k[cost_k(r)]                  member k's code at the row's cost
    S_nm   = E_rule[cost] + Σ_{k ≥ 1} E_k(nm)    the no-match row: the pass's no-match rule in the place
                                                 of the first member's entry, as the per-column machine
    S_min  = min of S over the pixel's rows with a match pixel, S_nm too when the pass's no-match row
             can win (``PassContext.nomatch_live``: not zeroed by another column, as census-lr's
             consistency column without ``lr_nomatch``)
    word_r = X[min(S_r − S_min, len(X) − 1)]     X = exp_table(W)

so the best row's word is 2^W and fires every cycle. A lane without a match pixel gets 0; a pass without
a no-match row has 0 there (as every FEATURES column of the per-column machine), and so has a pass whose
no-match row cannot win. What is dynamic (the
neighbour prior, the left-right column) stays in operator columns of its own: the machine fuses it
stochastically and its counters keep the distribution.

A model lists a fused kind, ``fused(Mean, GradH, GradV, Census)``, in place of its image columns: the
kind owns its members' options and the yes/no option :data:`FUSE_COLUMNS` (``--fuse-columns``; off: the
members are the model's columns, one operator column each, the paper's picture). The float64 reference
multiplies the members' float64 factors (:meth:`Fused.factors`): the posterior the words approximate.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from .base import Column, Option, PassContext, PlaneColumn, Source, Table, Term, check_switch
from .energy import INFINITE_CODE, EnergyTable, exp_table
from .planes import Plane

__all__ = ["FUSE_COLUMNS", "Fused", "fused"]


FUSE_COLUMNS = Option("fuse_columns", "bool", True, check_switch,
                      "fuse the image columns into one operator column in the energy form (off: one operator "
                      "column per piece of evidence)")


class Fused(Column):
    """A fused column (module text): its members, FEATURES columns of one plane each, as one column.

    A kind is made by :func:`fused` (one kind per list of members); ``member_kinds`` are its members in
    order. Its words read the energy form of :mod:`.energy` (``Term.energy()``), the package's one.

    Attributes
    ----------
    members : tuple of PlaneColumn
        Its member columns, built from the model's values.
    """

    name = "fused"
    source = Source.FEATURES
    holds_rule = True
    member_kinds: ClassVar[tuple[type[PlaneColumn], ...]] = ()

    def __init__(self, *, values: Mapping[str, Any], dmax: int) -> None:
        super().__init__(values=values, dmax=dmax)
        self.members = tuple(kind(values=values, dmax=dmax) for kind in self.member_kinds)

    @classmethod
    def expand(cls, values: Mapping[str, Any]) -> tuple[type[Column], ...]:
        return (cls,) if values[FUSE_COLUMNS.name] else cls.member_kinds

    @classmethod
    def layout_options(cls) -> tuple[Option, ...]:
        return (FUSE_COLUMNS,)

    def planes(self) -> dict[str, Plane]:
        out: dict[str, Plane] = {}
        for m in self.members:
            out.update(m.planes())
        return out

    def factors(self) -> tuple[Column, ...]:
        return self.members

    def table(self, word_bits: int | None = None) -> Table:
        raise ValueError(f"the fused column ({', '.join(m.name for m in self.members)}) has no table of one "
                         "cost: its members' tables, in energy form (energies())")

    def energies(self) -> tuple[EnergyTable, ...]:
        """Its members' tables in energy form, in order."""
        return tuple(m.energy() for m in self.members)

    def rule_energy(self, rule: Term) -> EnergyTable:
        """The pass's no-match rule's table in energy form."""
        return rule.energy()

    def exp_table(self, word_bits: int) -> np.ndarray:
        """X, the way back from a code difference to a ``word_bits``-bit word."""
        return exp_table(word_bits)

    def sums(self, ctx: PassContext) -> tuple[np.ndarray, np.ndarray]:
        """(S, S_nm): each lane's sum of codes (P, Dmax+1) and the no-match row's (P,), int64, of the pass's
        P pixels of ``ctx`` (row-major); S_nm needs the pass's rule (``ctx.rule``)."""
        total: Any = 0
        for m, e in zip(self.members, self.energies(), strict=True):
            a, b = ctx.reference[m.plane], ctx.match[m.plane]
            codes = e.values[m.cost(a[:, ctx.columns, None], b[:, ctx.match_columns])]
            total = total + codes.astype(np.int64)
        n = ctx.rows * ctx.columns.size
        rule = _rule(ctx)
        nm = self.rule_energy(rule).values[rule.cost(ctx.reference[rule.plane][:, ctx.columns])]
        nm = nm.reshape(n).astype(np.int64)
        for m, e in zip(self.members[1:], self.energies()[1:], strict=True):
            nm += int(m.nomatch_entry(e))  # type: ignore[arg-type]
        return total.reshape(n, -1), nm

    def _relative(self, ctx: PassContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(D, D_nm, valid): each lane's and the no-match row's sum above the pixel's least (the lanes with
        a match pixel, and the no-match row where it can win), and which lanes have a match pixel."""
        s, nm = self.sums(ctx)
        valid = (np.ones(s.shape, bool) if ctx.valid is None
                 else np.broadcast_to(ctx.valid[None], (ctx.rows, *ctx.valid.shape)).reshape(s.shape))
        low = np.where(valid, s, np.iinfo(np.int64).max).min(axis=1)
        if ctx.nomatch_live:
            low = np.minimum(low, nm)
        return s - low[:, None], nm - low, valid

    def words(self, ctx: PassContext) -> np.ndarray:
        """Its words (module text), or with ``ctx.word_bits`` None its float64 factors: the members'
        product (((m * gH) * gV) * census) * ..., the no-match row the rule's times the others' entries."""
        if ctx.word_bits is None:
            return self._factors(ctx)
        d, d_nm, valid = self._relative(ctx)
        x = self.exp_table(ctx.word_bits)
        top = x.size - 1
        out = np.empty((d.shape[0], d.shape[1] + 1), np.uint16)
        out[:, :-1] = np.where(valid, x[np.clip(d, 0, top)], 0)
        out[:, -1] = x[np.minimum(d_nm, top)] if ctx.nomatch_live else 0
        return out

    def codes(self, ctx: PassContext) -> np.ndarray:
        """Its logarithmic integrator's codes: the summed codes above the pixel's least (what the
        integrator's argmin and weights see of its members' codes, less a per-pixel constant), at most
        ``INFINITE_CODE - 1``; ``INFINITE_CODE`` for a lane without a match pixel and for the no-match
        row where it cannot win (its word 0)."""
        d, d_nm, valid = self._relative(ctx)
        out = np.full((d.shape[0], d.shape[1] + 1), INFINITE_CODE, np.uint16)
        out[:, :-1] = np.where(valid, np.minimum(d, INFINITE_CODE - 1), INFINITE_CODE)
        if ctx.nomatch_live:
            out[:, -1] = np.minimum(d_nm, INFINITE_CODE - 1)
        return out

    def _factors(self, ctx: PassContext) -> np.ndarray:
        n = ctx.rows * ctx.columns.size
        values: Any = None
        for m in self.members:
            a, b = ctx.reference[m.plane], ctx.match[m.plane]
            f = m.table().values[m.cost(a[:, ctx.columns, None], b[:, ctx.match_columns])]
            values = f if values is None else values * f
        if ctx.valid is not None:
            values = values * ctx.valid[None]
        out = np.empty((n, values.shape[-1] + 1))
        out[:, :-1] = values.reshape(n, -1)
        if ctx.nomatch:
            rule = _rule(ctx)
            nm = rule.table().values[rule.cost(ctx.reference[rule.plane][:, ctx.columns])].reshape(n)
            for m in self.members[1:]:
                nm = nm * m.nomatch_entry(m.table())
            out[:, -1] = nm
        else:
            out[:, -1] = 0.0
        return out


def _rule(ctx: PassContext) -> Any:
    if ctx.rule is None:
        raise ValueError(f"the fused column's no-match row holds the pass's no-match rule: {ctx.where}'s "
                         "context has none (PassContext(rule=...))")
    return ctx.rule


_KINDS: dict[tuple[type[PlaneColumn], ...], type[Fused]] = {}


def _kind(members: tuple[type[PlaneColumn], ...]) -> type[Fused]:
    key = members
    if key not in _KINDS:
        options: dict[str, Option] = {}
        for kind in members:
            for o in kind.options:
                options.setdefault(o.name, o)
        name = "Fused_" + "_".join(k.__name__ for k in members)
        doc = f"The fused column of {', '.join(k.__name__ for k in members)}."
        cls = type(name, (Fused,), {"member_kinds": members, "options": (*options.values(), FUSE_COLUMNS),
                                    "__module__": __name__, "__doc__": doc})
        globals()[name] = cls  # pickled by name, as any column kind
        _KINDS[key] = cls
    return _KINDS[key]


def fused(*members: type[PlaneColumn]) -> type[Fused]:
    """The fused kind of ``members`` (FEATURES column kinds of one plane each, in operator order; one kind
    per list): TypeError for a member that is not such a kind, ValueError for none or one listed twice."""
    for i, kind in enumerate(members):
        if not (isinstance(kind, type) and issubclass(kind, PlaneColumn)) or issubclass(kind, Fused):
            raise TypeError(f"fused: member {i} = {kind!r} is not a FEATURES column kind (a subclass of "
                            "bayesmachine.columns.PlaneColumn)")
    if not members:
        raise ValueError("fused: a fused column needs members")
    names = [k.name for k in members]
    twice = [n for n in names if names.count(n) > 1]
    if twice:
        raise ValueError(f"fused: member {twice[0]} is listed twice")
    return _kind(tuple(members))
