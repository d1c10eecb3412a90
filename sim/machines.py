"""The model twin of ``hdl.machines.ParallelMachines``: pixel i to machine ``i % k``, each its integrator's
model."""

from __future__ import annotations

import numpy as np

from bayesmachine.checks import as_int
from bayesmachine.params import MachineParams, nth_machine

from .results import MachineResult, check_words

__all__ = ["ParallelMachinesModel"]


class ParallelMachinesModel:
    """k machine models of ``nth_machine(params, i)``; the round-robin deal carries over between calls."""

    def __init__(self, params: MachineParams, machines: int) -> None:
        machines = as_int("machines", machines, 1, 256)
        self._params = params
        model = params.kind.engine_class("model")
        self._models = [model(nth_machine(params, i)) for i in range(machines)]
        self._next = 0  # the machine of the next pixel

    @property
    def params(self) -> MachineParams:
        return self._params

    def reset(self) -> None:
        for machine in self._models:
            machine.reset()
        self._next = 0

    def run(self, words: np.ndarray) -> MachineResult:
        q = check_words(self._params, words)
        k, n = len(self._models), q.shape[0]
        machine_of = (self._next + np.arange(n)) % k
        parts = {i: self._models[i].run(q[machine_of == i]) for i in range(k) if (machine_of == i).any()}
        empty = MachineResult.empty(self._params.rows)
        out = MachineResult(*(np.zeros((n, *getattr(empty, f).shape[1:]), getattr(empty, f).dtype)
                              for f in MachineResult.__dataclass_fields__))
        for i, res in parts.items():
            for f in MachineResult.__dataclass_fields__:
                getattr(out, f)[machine_of == i] = getattr(res, f)
        self._next = (self._next + n) % k
        return out
