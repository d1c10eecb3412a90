"""The semi-global column: a member column's energies aggregated along causal scanline paths.

The streaming semi-global matching of FPGA stereo cores (no frame buffer): the pass's fused image column
(:mod:`.fused`, its members' summed energy codes) is aggregated along the causal paths r of
:data:`PATHS` (left, top, top-left, top-right; ``sgm_paths`` = n takes the first n), in the energy form's
codes (:mod:`.energy`, 1/16 nat). Per pixel p of the pass's grid, row by row, q = p − r:

    E(p, d)   = min(D(p, d), C)          D: the member's sums above the pixel's least (its no-match row
    E_nm(p)   = min(D_nm(p), C)          too where it can win); C = 2^sgm_cost_bits − 1; a lane
                                         without a match pixel: C
    L_r(p, d) = min(C, E(p, d) + min(L_r(q, d), L_r(q, d ± 1) + P1, m_r(q) + P2) − m_r(q))
    L_r(p, d) = E(p, d)                  where q lies outside the grid (the path starts)
    m_r(q)    = min_k L_r(q, k)          over every lane k = 0..Dmax
    S(p, d)   = Σ_r L_r(p, d),  S_nm(p) = n · E_nm(p)
    T         = (A · (S − S_min) + 128) >> 8     S_min over the lanes with a match pixel and the no-match
                                                 row where it can win; A = round(256 · sgm_temperature)
    word      = X[min(T, len(X) − 1)]            X = exp_table(W), as the fused column's
    code      = min(T, INFINITE_CODE − 1)        the logarithmic integrator's

with P1 = round(sgm_p1 / step), P2 = round(sgm_p2 / step) codes. A lane without a match pixel gets word 0
(code INFINITE_CODE), and so does the no-match row of a pass whose no-match row cannot win. Every path
cost lies in [E(p, d), E(p, d) + P2] before saturation, so ``sgm_cost_bits`` bits hold it. The no-match row
is no point of a path: its S_nm is what a hypothesis reached from the previous pixel's best at no cost
would sum. The temperature scales the aggregated energy back to the posterior's (n paths count each
pixel's evidence about n times): the confidence stays calibrated (docs/models.md).

The float64 reference factor is the same recursion on the members' float64 energies −ln L (nats, no
saturation, no rounding) with P1, P2 in nats: exp(−sgm_temperature · (S − S_min)).

The paths run in raster order, so a band of rows continues from the path costs of the row above it:
``PassContext.carry`` holds them from one band to the next (the on-chip twin keeps the upper paths'
previous-row costs in block RAM and the left path's in a register).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numba
import numpy as np

from bayesmachine.checks import as_real
from bayesmachine.errors import ParameterError

from .base import Column, Option, PassContext, Source, Table, check_bool, check_int
from .energy import ENERGY_STEP, INFINITE_CODE, exp_table
from .fused import FUSE_COLUMNS, Fused
from .planes import Plane

__all__ = ["PATHS", "SEMIGLOBAL", "SemiGlobal", "semiglobal", "aggregate"]

# The causal scanline paths (dy, dx) from p to q = p - r, in the order sgm_paths takes them.
PATHS: dict[str, tuple[int, int]] = {"left": (0, -1), "top": (-1, 0), "top-left": (-1, -1),
                                     "top-right": (-1, 1)}
# Fixed-point bits of the temperature's multiplier A.
SCALE_BITS = 8


def _semiglobal(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_bool(name, value)
    if value and not values.get(FUSE_COLUMNS.name, True):
        raise ParameterError(f"{name}: the semi-global column aggregates the fused column's energies: turn "
                             f"{FUSE_COLUMNS.name} on, or {name} off", name)


SEMIGLOBAL = Option("semiglobal", "bool", True, _semiglobal,
                    "aggregate the fused column's energies along causal scanline paths (semi-global "
                    "matching; off: the fused column itself)")


def _paths(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_int(name, value, 1, len(PATHS))


def _penalty(name: str, value: object, values: Mapping[str, Any]) -> None:
    as_real(name, value, 0.0, 64.0, " nats")
    if name == "sgm_p2" and value < values["sgm_p1"]:  # type: ignore[operator]
        raise ParameterError(f"sgm_p2 ({value!r}) must be at least sgm_p1 ({values['sgm_p1']!r})", name)


def _cost_bits(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_int(name, value, 6, 12)
    top = (1 << value) - 1  # type: ignore[operator]
    p2 = _codes(values["sgm_p2"])
    if p2 > top:
        raise ParameterError(f"{name} = {value}: path costs saturate at {top} codes, below P2 = {p2} codes "
                             f"(sgm_p2 = {values['sgm_p2']!r} nats)", name)


def _temperature(name: str, value: object, values: Mapping[str, Any]) -> None:
    as_real(name, value, 1.0 / (1 << SCALE_BITS), 4.0)


def _codes(nats: float) -> int:
    """Nats as energy codes, round half up."""
    return int(np.floor(float(nats) / ENERGY_STEP + 0.5))


OPTIONS = (
    SEMIGLOBAL,
    # Two paths by default: as accurate as four on the bundled and held-out pairs (within 0.003 of bad-2)
    # at a third of the upper paths' block RAM (docs/models.md).
    Option("sgm_paths", "int", 2, _paths, "the semi-global column's causal paths: the first N of left, top, "
           "top-left, top-right (1 .. 4)"),
    Option("sgm_p1", "float", 1.0, _penalty, "the semi-global penalty of a step of one disparity along a "
           "path, in nats"),
    Option("sgm_p2", "float", 6.0, _penalty, "the semi-global penalty of a larger step along a path, in "
           "nats (at least sgm_p1)"),
    Option("sgm_cost_bits", "int", 8, _cost_bits, "the semi-global path costs' width: each saturates at "
           "2^bits - 1 codes (6 .. 12)"),
    Option("sgm_temperature", "float", None, _temperature, "nats of the posterior per nat of aggregated "
           "energy (the words read exp(-t (S - min S))); 1/256 .. 4",
           resolve=lambda values: 1.0 / values["sgm_paths"], default_text="1 / sgm_paths"),
)


@numba.njit(cache=True, inline="always")
def _step(e, q, p1, p2, cap, out):  # pragma: no cover
    """out[d] = min(cap, e[d] + min(q[d], q[d-1] + p1, q[d+1] + p1, min q + p2) - min q)."""
    n = e.shape[0]
    m = q[0]
    for k in range(1, n):
        if q[k] < m:
            m = q[k]
    for d in range(n):
        v = q[d]
        if d > 0 and q[d - 1] + p1 < v:
            v = q[d - 1] + p1
        if d + 1 < n and q[d + 1] + p1 < v:
            v = q[d + 1] + p1
        if m + p2 < v:
            v = m + p2
        v = e[d] + v - m
        out[d] = cap if v > cap else v


@numba.njit(cache=True, boundscheck=False)
def _aggregate(e, prev, has_prev, n_paths, p1, p2, cap, total):  # pragma: no cover
    """total[y] = the sum over the first ``n_paths`` paths of their costs, rows y of ``e`` (R, W, D1) in
    order; ``prev`` (3, W, D1): the upper paths' costs of the row above (``has_prev``), updated in place
    to the last row's."""
    rows, w, d1 = e.shape
    left = np.empty((w, d1), e.dtype)
    new = np.empty_like(prev)
    for y in range(rows):
        above = has_prev or y > 0
        for x in range(w):
            if x == 0:
                left[0] = e[y, 0]
            else:
                _step(e[y, x], left[x - 1], p1, p2, cap, left[x])
        total[y] = left
        for k in range(n_paths - 1):
            dx = (0, -1, 1)[k]
            for x in range(w):
                xq = x + dx
                if above and 0 <= xq < w:
                    _step(e[y, x], prev[k, xq], p1, p2, cap, new[k, x])
                else:
                    new[k, x] = e[y, x]
                for d in range(d1):
                    total[y, x, d] += new[k, x, d]
        prev[:] = new
        has_prev = True


def aggregate(e: np.ndarray, prev: np.ndarray | None, paths: int, p1: Any, p2: Any,
              cap: Any) -> tuple[np.ndarray, np.ndarray]:
    """(S, prev'): the sum over the first ``paths`` of :data:`PATHS` of the path costs of the rows of ``e``
    (R, W, D1; int64 codes or float64 nats), continuing from ``prev`` (3, W, D1: the upper paths' costs of
    the row above; None: ``e``'s first row is the grid's first), and the upper paths' costs of its last
    row. Costs saturate at ``cap`` (``np.inf`` for none)."""
    e = np.ascontiguousarray(e)
    rows, w, d1 = e.shape
    state = np.zeros((3, w, d1), e.dtype) if prev is None else np.array(prev, e.dtype)
    total = np.empty_like(e)
    typ = e.dtype.type
    _aggregate(e, state, prev is not None, int(paths), typ(p1), typ(p2), typ(cap), total)
    return total, state


class SemiGlobal(Column):
    """The semi-global column (module text) over its member, a fused column kind (``member_kind``).

    Attributes
    ----------
    member : Fused
        Its member column, built from the model's values.
    """

    name = "semiglobal"
    source = Source.FEATURES
    holds_rule = True
    member_kind: ClassVar[type[Fused]]

    def __init__(self, *, values: Mapping[str, Any], dmax: int) -> None:
        super().__init__(values=values, dmax=dmax)
        self.member = self.member_kind(values=values, dmax=dmax)

    @classmethod
    def expand(cls, values: Mapping[str, Any]) -> tuple[type[Column], ...]:
        return (cls,) if values[SEMIGLOBAL.name] else cls.member_kind.expand(values)

    @classmethod
    def layout_options(cls) -> tuple[Option, ...]:
        return (*cls.member_kind.layout_options(), SEMIGLOBAL)

    def planes(self) -> dict[str, Plane]:
        return self.member.planes()

    def factors(self) -> tuple[Column, ...]:
        return (self,)

    def table(self, word_bits: int | None = None) -> Table:
        raise ValueError("the semi-global column has no table of one cost: its member's energies, "
                         "aggregated along paths")

    @property
    def paths(self) -> tuple[str, ...]:
        return tuple(PATHS)[: int(self.values["sgm_paths"])]

    @property
    def cap(self) -> int:
        """C: the largest path cost, in codes."""
        return (1 << int(self.values["sgm_cost_bits"])) - 1

    @property
    def penalties(self) -> tuple[int, int]:
        """(P1, P2) in codes."""
        return _codes(self.values["sgm_p1"]), _codes(self.values["sgm_p2"])

    @property
    def scale(self) -> int:
        """A: the temperature's multiplier, in 1/256."""
        return max(1, int(np.floor(float(self.values["sgm_temperature"]) * (1 << SCALE_BITS) + 0.5)))

    def _carried(self, ctx: PassContext, domain: str) -> tuple[str, np.ndarray | None]:
        """The key of this column's path costs in ``ctx.carry`` and those of the row above the band."""
        key = f"{self.name}/{domain}"
        if ctx.first_row == 0:
            return key, None
        state = None if ctx.carry is None else ctx.carry.get(key)
        if state is None or state[0] != ctx.first_row:
            raise ParameterError(f"carry: the {self.name} column's paths continue from the row above the "
                                 f"band (row {ctx.first_row - 1}): give carry= (a dict) and the bands in "
                                 f"order from row 0, for {ctx.where}", "carry")
        return key, state[1]

    def _sums(self, ctx: PassContext, e: np.ndarray, e_nm: np.ndarray, cap: Any, p1: Any, p2: Any,
              domain: str) -> tuple[np.ndarray, np.ndarray]:
        """(S − S_min (n, D1), S_nm − S_min (n,)) of the energies ``e`` (n, D1), ``e_nm`` (n,)."""
        key, prev = self._carried(ctx, domain)
        width = ctx.columns.size
        total, state = aggregate(e.reshape(ctx.rows, width, -1), prev, len(self.paths), p1, p2, cap)
        if ctx.carry is not None:
            ctx.carry[key] = (ctx.first_row + ctx.rows, state)
        s = total.reshape(e.shape)
        s_nm = len(self.paths) * e_nm
        valid = self._valid(ctx, s.shape)
        high = np.iinfo(np.int64).max if s.dtype.kind == "i" else np.inf
        low = np.where(valid, s, high).min(axis=1)
        if ctx.nomatch_live:
            low = np.minimum(low, s_nm)
        return s - low[:, None], s_nm - low

    @staticmethod
    def _valid(ctx: PassContext, shape: tuple[int, ...]) -> np.ndarray:
        if ctx.valid is None:
            return np.ones(shape, bool)
        return np.broadcast_to(ctx.valid[None], (ctx.rows, *ctx.valid.shape)).reshape(shape)

    def energies(self, ctx: PassContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(T (P, Dmax+1), T_nm (P,), valid): the tempered codes of the aggregated sums (module text)."""
        d, d_nm, valid = self.member._relative(ctx)
        cap = self.cap
        e = np.where(valid, np.minimum(d, cap), cap).astype(np.int64)
        p1, p2 = self.penalties
        s, s_nm = self._sums(ctx, e, np.minimum(d_nm, cap).astype(np.int64), cap, p1, p2, "codes")
        a, half = self.scale, 1 << (SCALE_BITS - 1)
        return (a * s + half) >> SCALE_BITS, (a * s_nm + half) >> SCALE_BITS, valid

    def words(self, ctx: PassContext) -> np.ndarray:
        """Its words (module text), or with ``ctx.word_bits`` None its float64 reference factors."""
        if ctx.word_bits is None:
            return self._factors(ctx)
        t, t_nm, valid = self.energies(ctx)
        x = exp_table(ctx.word_bits)
        top = x.size - 1
        out = np.empty((t.shape[0], t.shape[1] + 1), np.uint16)
        out[:, :-1] = np.where(valid, x[np.minimum(t, top)], 0)
        out[:, -1] = x[np.minimum(t_nm, top)] if ctx.nomatch_live else 0
        return out

    def codes(self, ctx: PassContext) -> np.ndarray:
        """Its logarithmic integrator's codes: T, at most ``INFINITE_CODE - 1``; ``INFINITE_CODE`` for a
        lane without a match pixel and for the no-match row where it cannot win."""
        t, t_nm, valid = self.energies(ctx)
        out = np.full((t.shape[0], t.shape[1] + 1), INFINITE_CODE, np.uint16)
        out[:, :-1] = np.where(valid, np.minimum(t, INFINITE_CODE - 1), INFINITE_CODE)
        if ctx.nomatch_live:
            out[:, -1] = np.minimum(t_nm, INFINITE_CODE - 1)
        return out

    def _factors(self, ctx: PassContext) -> np.ndarray:
        """The float64 reference factors: the recursion on the members' energies in nats."""
        f = self.member._factors(ctx)
        with np.errstate(divide="ignore"):
            energy = -np.log(f)  # +inf for a factor of 0: a lane without a match pixel
        valid = self._valid(ctx, energy[:, :-1].shape)
        low = np.where(valid, energy[:, :-1], np.inf).min(axis=1)
        if ctx.nomatch_live:
            low = np.minimum(low, energy[:, -1])
        e = energy[:, :-1] - low[:, None]
        e_nm = energy[:, -1] - low if ctx.nomatch_live else np.zeros(low.shape)
        p1, p2 = float(self.values["sgm_p1"]), float(self.values["sgm_p2"])
        s, s_nm = self._sums(ctx, e, e_nm, np.inf, p1, p2, "nats")
        tau = float(self.values["sgm_temperature"])
        out = np.zeros((s.shape[0], s.shape[1] + 1))
        out[:, :-1] = np.where(valid, np.exp(-tau * np.where(valid, s, 0.0)), 0.0)
        if ctx.nomatch_live:
            out[:, -1] = np.exp(-tau * s_nm)
        return out


_KINDS: dict[type[Fused], type[SemiGlobal]] = {}


def semiglobal(member: type[Fused]) -> type[SemiGlobal]:
    """The semi-global kind over ``member``, a fused column kind (:func:`~.fused.fused`; one kind per
    member): TypeError for anything else."""
    if not (isinstance(member, type) and issubclass(member, Fused)):
        raise TypeError(f"semiglobal: member {member!r} is not a fused column kind (bayesmachine.columns."
                        "fused(...))")
    if member not in _KINDS:
        name = "SemiGlobal_" + member.__name__
        doc = f"The semi-global column over {member.__name__}."
        cls = type(name, (SemiGlobal,), {"member_kind": member, "options": (*member.options, *OPTIONS),
                                         "__module__": __name__, "__doc__": doc})
        globals()[name] = cls  # pickled by name, as any column kind
        _KINDS[member] = cls
    return _KINDS[member]
