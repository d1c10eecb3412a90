"""Shared helpers for the RTL tests."""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.sim import Simulator

from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineResult


def run_sim(dut: object, testbench: object, *, clock: bool = True) -> None:
    """Run one async testbench against ``dut`` (with a sync clock unless ``clock=False``)."""
    sim = Simulator(dut)
    if clock:
        sim.add_clock(1e-8)
    sim.add_testbench(testbench)
    sim.run()


def assert_same_results(got: MachineResult, want: MachineResult) -> None:
    """Field by field, naming the first differing pixel."""
    assert len(got) == len(want), f"{len(got)} results, expected {len(want)}"
    for field in MachineResult.__dataclass_fields__:
        a, b = getattr(got, field), getattr(want, field)
        if not np.array_equal(a, b):
            bad = np.flatnonzero((a != b).reshape(len(a), -1).any(axis=1))
            i = int(bad[0])
            pytest.fail(f"{field} differs at pixels {bad[:10].tolist()}: pixel {i}: got {a[i]}, model {b[i]}")


def small_params(**kwargs: object) -> MachineParams:
    """A small machine (5 rows x 2 columns, W = 4, L = 12) that runs fast in the simulator."""
    base: dict[str, object] = dict(
        rows=5, columns=2, word_bits=4, lfsr_bits=12, counter_max=3, max_cycles=60, lanes=3,
        nomatch_row=True,
    )
    base.update(kwargs)
    return MachineParams(**base)  # type: ignore[arg-type]
