"""The row adders: each row's N energy codes summed, and whether one of them is infinite.

Per row a balanced tree of ceil(log2 N) levels of adders (each node also ORs its children's
"infinite" flags), cut into register stages of ``levels_per_stage`` levels
(``pipeline.stage_functions``). Twin: ``sim.log_model.row_sums``. ``carried`` bits ride along with a pixel's
codes, unchanged (the log machine's ``line_start``).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Value, unsigned
from amaranth.lib import data

from bayesmachine.checks import as_int
from bayesmachine.integrators.log import LogParams, check_params, tree_levels

from .layouts import codes_layout, row_sums_layout
from .pipeline import Bank, LogBlock, Stage, Wire, fit, pack, stage_functions

__all__ = ["RowAdders", "adder_stages", "carried_layouts"]


def _add_level(nodes: list[tuple[Value, Value]], wire: Wire, name: str) -> list[tuple[Value, Value]]:
    """One adder-tree level: neighbours added (their infinite flags ORed), an odd node out passed up."""
    pairs = zip(nodes[0::2], nodes[1::2], strict=False)  # an odd node out has no partner
    out = [(wire(a + b, f"{name}_{j}"), xa | xb) for j, ((a, xa), (b, xb)) in enumerate(pairs)]
    return out + ([nodes[-1]] if len(nodes) % 2 else [])


def carried_layouts(params: LogParams, carried: int) -> tuple[data.Layout, data.Layout]:
    """The row adders' payloads: ``codes_layout`` in, ``row_sums_layout`` out, each with a ``carried``
    field of ``carried`` bits on top when there are any."""
    if not carried:
        return codes_layout(params), row_sums_layout(params)
    return (data.StructLayout({"codes": codes_layout(params), "carried": unsigned(carried)}),
            data.StructLayout({**row_sums_layout(params).members, "carried": unsigned(carried)}))


def adder_stages(params: LogParams, levels_per_stage: int, carried: int = 0) -> tuple[Stage, ...]:
    """The row adders' stage functions: :func:`carried_layouts` payloads in and out. A bank is
    ``(rows, carried bits)``, ``rows`` a list over rows of each row's nodes ``(sum, infinite)``."""
    p = params
    layout_in, layout_out = codes_layout(p), carried_layouts(p, carried)[1]
    width = layout_in.size

    def first(payload: Bank, wire: Wire) -> Bank:
        flat = Value.cast(payload)
        codes = layout_in(flat[:width])
        return ([[(codes[r][c], codes[r][c] == p.infinite) for c in range(p.codes)] for r in range(p.rows)],
                flat[width:])

    def level(bank: Bank, wire: Wire) -> Bank:
        return [_add_level(nodes, wire, f"sum{r}") for r, nodes in enumerate(bank[0])], bank[1]

    def last(bank: Bank, wire: Wire) -> Bank:
        rows, tag = bank
        fields = {"carried": tag} if carried else {}
        return pack(layout_out, sums=Cat(*(fit(nodes[0][0], p.sum_bits) for nodes in rows)),
                    excluded=Cat(*(nodes[0][1] for nodes in rows)), **fields)

    return stage_functions(first, [level] * tree_levels(p.codes), last, levels_per_stage)


class RowAdders(LogBlock):
    """Each row's codes summed (``sim.log_model.row_sums``), one pixel per clock.

    Parameters
    ----------
    params : LogParams
        Rows, codes per row, code width.
    levels_per_stage : int
        Adder-tree levels between two registers (1 ... 64); the tree has ceil(log2 codes) levels.
    carried : int
        Bits carried along with each pixel, unchanged (0 ... 64).

    Attributes
    ----------
    codes : ``In(stream.Signature(carried_layouts(params, carried)[0]))``
        A pixel's codes (``codes_layout(params)``; with carried bits, its ``codes`` and ``carried``).
    sums : ``Out(stream.Signature(carried_layouts(params, carried)[1]))``
        Each row's sum and excluded flag (``row_sums_layout(params)``; with carried bits, and
        ``carried``).
    latency : int
        ``max(1, ceil(ceil(log2 codes) / levels_per_stage))`` clocks.
    """

    def __init__(self, *, params: LogParams, levels_per_stage: int = 1, carried: int = 0) -> None:
        self._levels = as_int("levels_per_stage", levels_per_stage, 1, 64)
        self._carried = as_int("carried", carried, 0, 64)
        p = check_params(params)
        layout_in, layout_out = carried_layouts(p, self._carried)
        super().__init__(params=p, sink="codes", source="sums", in_layout=layout_in, out_layout=layout_out,
                         stages=adder_stages(p, self._levels, self._carried))

    @property
    def levels_per_stage(self) -> int:
        return self._levels

    @property
    def carried(self) -> int:
        return self._carried
