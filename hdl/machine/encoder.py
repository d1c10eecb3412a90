"""The MAP encoder: which overflowing row wins.

Several overflow counters can overflow in the same cycle; the encoder picks one:

- ``lowest-index``: the lowest overflowing row;
- ``nomatch-first``: the no-match row (the last one) if it overflowed, else the lowest
  overflowing row (a pixel that cannot be told apart from "no match" is reported as such).

The lowest-index choice is a balanced binary tree (depth ceil(log2 M)), not a priority chain
whose depth grows with M: each node keeps its left child's index if the left child has an
overflowing row, else its right child's, and prepends one index bit saying which side won.
The no-match preference is one 2:1 multiplexer after the tree.
"""

from __future__ import annotations

from collections.abc import Sequence

from amaranth.hdl import Cat, Const, Module, Mux, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_bool, as_int
from bayesmachine.params import TIE_BREAKS, ParameterError

__all__ = ["MAPEncoder", "map_encoder", "map_encoder_twin"]


def _index_width(rows: int) -> int:
    return max(1, (rows - 1).bit_length())


def map_encoder(over: Value, nomatch_row: bool, tie_break: str) -> tuple[Value, Value]:
    """The encoder's logic on an M-bit vector ``over``: returns ``(valid, index)``.

    ``valid`` is 1 when any row overflowed; ``index`` (``max(1, bit_length(M - 1))`` bits) is
    the winning row, meaningless when ``valid`` is 0.
    """
    rows = len(over)
    width = _index_width(rows)
    if rows == 1:
        return over[0], Const(0, width)
    # Each level pairs up neighbours and halves the list; node j of level l covers rows
    # j * 2**l ... (j + 1) * 2**l - 1, and its index holds the low l bits of the winner.
    nodes: list[tuple[Value, Value]] = [(over[i], Cat()) for i in range(rows)]
    while len(nodes) > 1:
        nxt = []
        for j in range(0, len(nodes) - 1, 2):
            (lv, li), (rv, ri) = nodes[j], nodes[j + 1]
            low = Mux(lv, li, ri) if len(li) else Cat()
            # The new top bit is 1 when the right (higher) half won.
            nxt.append((lv | rv, Cat(low, ~lv)))
        if len(nodes) % 2:  # an odd node out has no right neighbour: it wins its pair if valid
            v, i = nodes[-1]
            nxt.append((v, Cat(i, Const(0, 1))))
        nodes = nxt
    valid, index = nodes[0]
    assert len(index) == width
    if nomatch_row and tie_break == "nomatch-first":
        index = Mux(over[rows - 1], Const(rows - 1, width), index)
    return valid, index


def map_encoder_twin(over: Sequence[int | bool], nomatch_row: bool, tie_break: str) -> int | None:
    """Python twin of the MAP encoder: the winning row, or None if no row overflowed."""
    if not any(over):
        return None
    if nomatch_row and tie_break == "nomatch-first" and over[-1]:
        return len(over) - 1
    return next(i for i, v in enumerate(over) if v)


class MAPEncoder(wiring.Component):
    """The MAP encoder: the machine's submodule, driven alone by ``tests/hdl/machine/test_encoder.py``.

    Parameters
    ----------
    rows : int
        M, the overflow counters' rows (>= 1; >= 2 with a no-match row).
    nomatch_row : bool
        Whether the last row is the no-match row.
    tie_break : str
        One of ``TIE_BREAKS``: ``"lowest-index"`` or ``"nomatch-first"`` (see the module docstring).

    Attributes
    ----------
    over : ``In(rows)``
        The rows that overflowed.
    valid : ``Out(1)``
        Some row overflowed.
    index : ``Out(max(1, bit_length(rows - 1)))``
        The winning row (meaningless when ``valid`` is 0).
    """

    def __init__(self, *, rows: int, nomatch_row: bool = False, tie_break: str = "nomatch-first") -> None:
        rows = as_int("rows", rows, 1)
        nomatch_row = as_bool("nomatch_row", nomatch_row)
        if not isinstance(tie_break, str):
            raise TypeError(f"tie_break must be a str, not {type(tie_break).__name__}")
        if tie_break not in TIE_BREAKS:
            raise ParameterError(f"tie_break must be one of {TIE_BREAKS}, got {tie_break!r}", "tie_break")
        if nomatch_row and rows < 2:
            raise ParameterError("an encoder with a no-match row needs at least 2 rows")
        self._rows = rows
        self._nomatch_row = nomatch_row
        self._tie_break = tie_break
        super().__init__({"over": In(rows), "valid": Out(1), "index": Out(_index_width(rows))})

    @property
    def rows(self) -> int:
        return self._rows

    @property
    def nomatch_row(self) -> bool:
        return self._nomatch_row

    @property
    def tie_break(self) -> str:
        return self._tie_break

    def elaborate(self, platform: object) -> Module:
        m = Module()
        valid, index = map_encoder(self.over, self._nomatch_row, self._tie_break)
        m.d.comb += [self.valid.eq(valid), self.index.eq(index)]
        return m
