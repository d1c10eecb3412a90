"""Engines: interchangeable ways to run the machine on pixels' likelihood memories.

Every engine takes a :class:`~bayesmachine.params.MachineParams` and offers
``run(words) -> MachineResult`` with the same meaning as :class:`MachineModel.run`: pixels
are processed in order, and the machine's state (the LFSRs) carries over from one call to
the next, so a frame can be run in chunks. The RTL engines also count ``wall_cycles`` (clock
cycles including loading, which the model does not time) and hold resources until ``close()``.

- ``model``: the NumPy/numba machine model (the definition; whole frames in seconds).
- ``pysim``: the RTL in Amaranth's Python simulator (hundreds of cycles per second: crops).
- ``verilator``: the emitted Verilog compiled with Verilator (whole frames, cycle-accurate RTL).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineModel, MachineResult

__all__ = ["ENGINES", "Engine", "get_engine"]

ENGINES = ("model", "pysim", "verilator")


class Engine(Protocol):
    params: MachineParams

    def run(self, words: np.ndarray) -> MachineResult: ...


def get_engine(name: str, params: MachineParams, **options: object) -> Engine:
    """A fresh engine (machine state as after reset) by name: one of :data:`ENGINES`."""
    if name == "model":
        return MachineModel(params)
    if name == "pysim":
        from bayesmachine.sim.pysim import PysimEngine

        return PysimEngine(params, **options)
    if name == "verilator":
        from bayesmachine.sim.verilator import VerilatorEngine

        return VerilatorEngine(params, **options)
    raise ValueError(f"unknown engine {name!r}: choose one of {', '.join(ENGINES)}")
