"""The row adders: each row's N energy codes summed, and whether one of them is infinite.

Per row a balanced tree of ceil(log2 N) levels of adders (each node also ORs its children's
"infinite" flags), cut into register stages of ``levels_per_stage`` levels
(``pipeline.stage_functions``). Twin: ``rule.row_sums``.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Value

from bayesmachine.checks import as_int

from .layouts import codes_layout, row_sums_layout
from .pipeline import Bank, LogBlock, Stage, Wire, fit, pack, stage_functions
from .rule import LogParams, check_params

__all__ = ["RowAdders", "adder_stages", "tree_levels"]


def tree_levels(leaves: int) -> int:
    """Levels of a balanced binary tree over ``leaves`` leaves: ceil(log2 leaves)."""
    return (leaves - 1).bit_length()


def _add_level(nodes: list[tuple[Value, Value]], wire: Wire, name: str) -> list[tuple[Value, Value]]:
    """One adder-tree level: neighbours added (their infinite flags ORed), an odd node out passed up."""
    pairs = zip(nodes[0::2], nodes[1::2], strict=False)  # an odd node out has no partner
    out = [(wire(a + b, f"{name}_{j}"), xa | xb) for j, ((a, xa), (b, xb)) in enumerate(pairs)]
    return out + ([nodes[-1]] if len(nodes) % 2 else [])


def adder_stages(params: LogParams, levels_per_stage: int) -> tuple[Stage, ...]:
    """The row adders' stage functions: ``codes_layout`` payload in, ``row_sums_layout`` out. A bank
    is a list over rows of each row's nodes ``(sum, infinite)``."""
    p = params
    layout_in, layout_out = codes_layout(p), row_sums_layout(p)

    def first(payload: Bank, wire: Wire) -> Bank:
        codes = layout_in(Value.cast(payload))
        return [[(codes[r][c], codes[r][c] == p.infinite) for c in range(p.codes)] for r in range(p.rows)]

    def level(bank: Bank, wire: Wire) -> Bank:
        return [_add_level(nodes, wire, f"sum{r}") for r, nodes in enumerate(bank)]

    def last(bank: Bank, wire: Wire) -> Bank:
        return pack(layout_out, sums=Cat(*(fit(nodes[0][0], p.sum_bits) for nodes in bank)),
                    excluded=Cat(*(nodes[0][1] for nodes in bank)))

    return stage_functions(first, [level] * tree_levels(p.codes), last, levels_per_stage)


class RowAdders(LogBlock):
    """Each row's codes summed (``rule.row_sums``), one pixel per clock.

    Parameters
    ----------
    params : LogParams
        Rows, codes per row, code width.
    levels_per_stage : int
        Adder-tree levels between two registers (1 ... 64); the tree has ceil(log2 codes) levels.

    Attributes
    ----------
    codes : ``In(stream.Signature(codes_layout(params)))``
        A pixel's codes.
    sums : ``Out(stream.Signature(row_sums_layout(params)))``
        Each row's sum and excluded flag.
    latency : int
        ``max(1, ceil(ceil(log2 codes) / levels_per_stage))`` clocks.
    """

    def __init__(self, *, params: LogParams, levels_per_stage: int = 1) -> None:
        self._levels = as_int("levels_per_stage", levels_per_stage, 1, 64)
        p = check_params(params)
        super().__init__(params=p, sink="codes", source="sums", in_layout=codes_layout(p),
                         out_layout=row_sums_layout(p), stages=adder_stages(p, self._levels))

    @property
    def levels_per_stage(self) -> int:
        return self._levels
