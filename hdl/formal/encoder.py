"""Properties of the MAP encoder (``hdl.machine.encoder.MAPEncoder``, the machine's submodule), for every
subset of simultaneous overflows: the encoder is combinational, so its ``over`` input is free and
one step covers every subset (``prove`` closes at once)."""

from __future__ import annotations

from collections.abc import Callable

from amaranth.hdl import Assert, Cover, Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.machine.encoder import MAPEncoder
from bayesmachine.params import TIE_BREAKS

__all__ = ["EncoderFactory", "EncoderProperties"]

EncoderFactory = Callable[..., wiring.Component]


class EncoderProperties(wiring.Component):
    """A formal-only wrapper: a MAP encoder and the tie rule it must implement.

    Parameters
    ----------
    rows : int
        M (>= 1; >= 2 with a no-match row).
    nomatch_row : bool
        Whether the last row is the no-match row.
    tie_break : str
        The rule the properties check, one of ``TIE_BREAKS``.
    encoder : callable
        Builds the encoder under check from ``rows``, ``nomatch_row`` and ``tie_break`` keywords;
        ``MAPEncoder`` (the machine's) unless a mutant is being checked.

    Attributes
    ----------
    over : ``In(rows)``
        The rows that overflowed in the stop cycle (free).
    valid, index : ``Out(1)``, ``Out(index width)``
        The encoder's outputs, for the trace.
    """

    def __init__(self, *, rows: int, nomatch_row: bool, tie_break: str,
                 encoder: EncoderFactory = MAPEncoder) -> None:
        if tie_break not in TIE_BREAKS:
            raise ValueError(f"tie_break must be one of {TIE_BREAKS}, got {tie_break!r}")
        self._dut = encoder(rows=rows, nomatch_row=nomatch_row, tie_break=tie_break)
        self._rows = rows
        self._nomatch_row = nomatch_row
        self._tie_break = tie_break
        width = len(self._dut.index)
        super().__init__({"over": In(rows), "valid": Out(1), "index": Out(width)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.dut = dut = self._dut
        rows, over, index = self._rows, self.over, self.index
        m.d.comb += [dut.over.eq(over), self.valid.eq(dut.valid), self.index.eq(dut.index)]
        last = rows - 1
        nomatch_first = self._nomatch_row and self._tie_break == "nomatch-first"
        # ``valid`` says exactly that some row overflowed (else the run timed out).
        m.d.comb += Assert(self.valid == over.any(), "valid iff some row overflowed")
        with m.If(self.valid):
            # The reported row is a row of the matrix and one that overflowed.
            m.d.comb += Assert(index < rows, "index names a row")
            m.d.comb += Assert(over.bit_select(index, 1), "the reported row overflowed")
            # No lower-priority choice: with nomatch-first the no-match row wins any tie it is in;
            # otherwise (and always with lowest-index) no row below the reported one overflowed.
            if nomatch_first:
                m.d.comb += Assert(~over[last] | (index == last), "the no-match row wins its ties")
            for i in range(rows):
                exempt = over[last] if nomatch_first else 0
                m.d.comb += Assert(exempt | (index <= i) | ~over[i],
                                   f"no overflowing row below the reported one ({i})")
        # Not vacuous: a tie of the no-match (last) row with a disparity row, and a tie of two
        # rows below it, each seen by the encoder.
        if rows >= 2:
            m.d.comb += Cover(over[last] & over[:last].any())
        if rows >= 3:
            m.d.comb += Cover(~over[last] & (over[:last] & (over[:last] - 1)).any())
        return m
