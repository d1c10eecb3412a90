"""The argmin tree: the row of the lowest sum among the rows not excluded, by the tie rule.

A balanced tree of ceil(log2 M) levels of compare-and-select nodes, cut into register stages of
``levels_per_stage`` levels. A node keeps its left (lower) child unless the left one is excluded
or the right one is not excluded and has a strictly lower key, so equal keys go to the lowest
index. The tie rule is in the keys: a row's key is its sum, and under ``nomatch-first`` it is
``2 * sum + 1`` for every row but the no-match row's ``2 * sum``, one lower than any other row
of the same sum (only the tree's right spine, where the no-match row goes, carries that bit
past the leaves). Like the MAP encoder's tree, a node at level l holds the low l bits of its
winner's index and prepends one bit per level (the right child won). With ``feedback`` the input
also holds a code per row (the log machine's feedback column, formed from the previous pixel's MAP)
that one more level, before the tree's, adds to the row's sum (and an infinite one excludes the row):
so the machine's loop through the previous MAP is this block alone. Twin: ``sim.log_model.argmin_rows``
(of the sums with the feedback codes added).
"""

from __future__ import annotations

from collections.abc import Callable

from amaranth.hdl import Cat, Const, Mux, Value

from bayesmachine.checks import as_int
from bayesmachine.integrators.log import LogParams, check_params, tree_levels

from .layouts import best_layout, feedback_sums_layout, row_sums_layout
from .pipeline import Bank, LogBlock, Stage, Wire, fit, pack, stage_functions

__all__ = ["ArgminTree", "Node", "NodeFunction", "argmin_stages", "better"]

Node = tuple[Value, tuple[Value, ...], Value]  # (key, low index bits from bit 0, excluded)


def better(left: Node, right: Node, wire: Wire, name: str) -> Node:
    """One node: the left candidate unless it is excluded or the right one has a strictly lower key
    (and is not excluded); the index gains one bit, 1 when the right one won."""
    (lk, li, lx), (rk, ri, rx) = left, right
    right_wins = wire(lx | (~rx & (rk < lk)), f"{name}_right")
    low = tuple(Mux(right_wins, r, lo) for lo, r in zip(li, ri, strict=True))
    return wire(Mux(right_wins, rk, lk), f"{name}_key"), (*low, right_wins), lx & rx


NodeFunction = Callable[[Node, Node, Wire, str], Node]


def _level(nodes: list[Node], wire: Wire, name: str, node: NodeFunction) -> list[Node]:
    out = [node(nodes[j], nodes[j + 1], wire, f"{name}_{j // 2}") for j in range(0, len(nodes) - 1, 2)]
    if len(nodes) % 2:  # the odd node out covers the highest rows of its pair: its new bit is 0
        key, low, x = nodes[-1]
        out.append((key, (*low, Const(0, 1)), x))
    return out


def argmin_stages(params: LogParams, levels_per_stage: int, pass_sums: bool,
                  node: NodeFunction = better, feedback: bool = False) -> tuple[Stage, ...]:
    """The argmin tree's stage functions: ``row_sums_layout`` payload in (``feedback_sums_layout`` with
    ``feedback``: the feedback codes' adders are the first level), ``best_layout(pass_sums)`` out. A bank
    is ``(nodes, carried)``: the level's nodes, and the rows' sums and flags when they are passed on.
    ``node``: the tree's node (:func:`better`; a proof's mutants give another)."""
    p = params
    layout_in, layout_out = row_sums_layout(p), best_layout(p, pass_sums)

    def leaves(sums: list[Value], excluded: list[Value], carried: Value) -> Bank:
        nodes = []
        for r in range(p.rows):
            key = sums[r]
            if p.nomatch_first:
                key = Cat(Const(int(r != p.rows - 1), 1), key)
            nodes.append((key, (), excluded[r]))
        return nodes, carried if pass_sums else Cat()

    def first(payload: Bank, wire: Wire) -> Bank:
        if feedback:  # the adders' level reads the payload
            return payload
        rows = layout_in(Value.cast(payload))
        return leaves([rows.sums[r] for r in range(p.rows)], [rows.excluded[r] for r in range(p.rows)],
                      Value.cast(rows))

    def add(payload: Bank, wire: Wire) -> Bank:
        # Each row's feedback code added to its sum of the other codes (which leaves room for it).
        rows = feedback_sums_layout(p)(Value.cast(payload))
        sums = [wire(fit(rows.sums[r] + rows.feedback[r], p.sum_bits), f"total{r}") for r in range(p.rows)]
        excluded = [rows.excluded[r] | (rows.feedback[r] == p.infinite) for r in range(p.rows)]
        return leaves(sums, excluded, pack(layout_in, sums=Cat(*sums), excluded=Cat(*excluded)))

    def level(bank: Bank, wire: Wire) -> Bank:
        nodes, carried = bank
        return _level(nodes, wire, f"node{len(nodes)}", node), carried

    def last(bank: Bank, wire: Wire) -> Bank:
        (key, low, none), carried = bank[0][0], bank[1]
        map_ = Mux(none, Const(p.none_index, p.map_width), fit(Cat(*low), p.map_width))
        s_min = Mux(none, 0, key[1:] if p.nomatch_first else key)
        nomatch = (map_ == p.rows - 1) if p.nomatch_row else Const(0, 1)
        extra = {}
        if pass_sums:
            rows = layout_in(carried)
            extra = {"sums": Value.cast(rows.sums), "excluded": rows.excluded}
        return pack(layout_out, map=map_, nomatch=nomatch, all_excluded=none, s_min=s_min, **extra)

    levels = [add] * feedback + [level] * tree_levels(p.rows)
    return stage_functions(first, levels, last, levels_per_stage)


class ArgminTree(LogBlock):
    """The MAP of the rows' sums (``sim.log_model.argmin_rows``), one pixel per clock.

    Parameters
    ----------
    params : LogParams
        Rows, sum width (``sum_bits``), no-match row, tie rule.
    levels_per_stage : int
        Tree levels between two registers (1 ... 64); the tree has ceil(log2 rows) levels.
    pass_sums : bool
        Whether the output carries the input's sums and excluded flags (delayed with the tree; with
        ``feedback``: the sums with the feedback codes added).
    feedback : bool
        Whether the input holds a feedback code per row, added to the row's sum in a level before the
        tree's (the row's sum of the other codes must leave room for it: the total fits ``sum_bits``).
    latest_copies : int
        Copies of the latest result's ``map``, ``nomatch`` and ``all_excluded`` (``latest``, loaded as a
        pixel reaches the output buffer: ``StallPipeline``), 0 ... 64; 0: none (no ``latest`` port).

    Attributes
    ----------
    sums : ``In(stream.Signature(row_sums_layout(params)))``
        Each row's sum and excluded flag (``feedback_sums_layout(params)`` with ``feedback``: and its
        feedback code).
    best : ``Out(stream.Signature(best_layout(params, pass_sums)))``
        The MAP: ``map``, ``nomatch``, ``all_excluded``, ``s_min`` (and the sums).
    latency : int
        ``max(1, ceil((ceil(log2 rows) + feedback) / levels_per_stage))`` clocks.
    latest, arriving
        With ``latest_copies``: ``StallPipeline``'s (the latest result, a pixel arriving at the output).
    """

    node: NodeFunction = staticmethod(better)  # the tree's node (a proof's mutant overrides it)

    def __init__(self, *, params: LogParams, levels_per_stage: int = 1, pass_sums: bool = False,
                 feedback: bool = False, latest_copies: int = 0) -> None:
        for name, flag in (("pass_sums", pass_sums), ("feedback", feedback)):
            if not isinstance(flag, bool):
                raise TypeError(f"{name} must be a bool, not {type(flag).__name__}")
        self._levels = as_int("levels_per_stage", levels_per_stage, 1, 64)
        self._pass_sums = pass_sums
        self._feedback = feedback
        self._latest_copies = copies = as_int("latest_copies", latest_copies, 0, 64)
        p = check_params(params)
        latest = {"latest_fields": ("map", "nomatch", "all_excluded"), "latest_copies": copies}
        super().__init__(params=p, sink="sums", source="best",
                         in_layout=feedback_sums_layout(p) if feedback else row_sums_layout(p),
                         out_layout=best_layout(p, pass_sums),
                         stages=argmin_stages(p, self._levels, pass_sums, type(self).node, feedback),
                         **(latest if copies else {}))

    @property
    def levels_per_stage(self) -> int:
        return self._levels

    @property
    def pass_sums(self) -> bool:
        return self._pass_sums

    @property
    def feedback(self) -> bool:
        return self._feedback

    @property
    def latest_copies(self) -> int:
        return self._latest_copies
