"""A register at every port of a component: for counting a block's cells with Yosys.

Synthesizing a block alone leaves its ports as the design's ports; on some blocks (the log
integrator, ``hdl.log``) Yosys 0.70's ``synth_ecp5`` then fails an assertion in its ABC9 step
(``GetSize(conn.first) == GetSize(conn.second)``). ``PortRegisters`` puts one flip-flop on every
bit of every port, in and out, and nothing else: the block's flip-flops are the design's minus
:attr:`PortRegisters.boundary_bits`, its logic the design's (a register adds no LUT). The ports
are the block's own, so nothing is trimmed. Unlike ``PinWrapper`` it saves no pins: it is for
synthesis counts, not for place and route.
"""

from __future__ import annotations

from amaranth.hdl import Module, Shape
from amaranth.lib import wiring
from amaranth.lib.wiring import In

__all__ = ["PortRegisters"]


class PortRegisters(wiring.Component):
    """``core`` with a register on every port bit (module docstring).

    Parameters
    ----------
    core : wiring.Component
        The block; its signature is this component's.

    Attributes
    ----------
    boundary_bits : int
        The flip-flops this wrapper adds: the width of every port, in and out.
    """

    def __init__(self, core: wiring.Component) -> None:
        if not isinstance(core, wiring.Component):
            raise TypeError(f"core must be a wiring.Component, not {type(core).__name__}")
        self._core = core
        super().__init__(core.signature)

    @property
    def boundary_bits(self) -> int:
        return sum(Shape.cast(member.shape).width for _, member in self.signature.members.flatten()
                   if member.is_port)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.core = core = self._core
        for path, member in self.signature.members.flatten():
            if not member.is_port:
                continue
            outer, inner = self, core
            for step in path:
                outer, inner = _step(outer, step), _step(inner, step)
            m.d.sync += inner.eq(outer) if member.flow == In else outer.eq(inner)
        return m


def _step(obj: object, step: str | int) -> object:
    return getattr(obj, step) if isinstance(step, str) else obj[step]  # type: ignore[index]
