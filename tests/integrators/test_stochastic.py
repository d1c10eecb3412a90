"""The stochastic integrator's kind: words loaded, counts read out, its engines and its top."""

from __future__ import annotations

import numpy as np

from bayesmachine.columns.base import quantize
from bayesmachine.integrators.stochastic import STOCHASTIC, pixel_wall_cycles
from bayesmachine.params import MachineParams


def test_it_loads_words_and_reads_counts() -> None:
    p = MachineParams.for_disparity(8, counter_max=12, word_bits=9)
    kind = p.kind
    assert kind is STOCHASTIC and kind.loads == "words"
    assert kind.load_max(p) == kind.flat(p) == 512 and kind.empty(p) == 0
    assert kind.readout_max(p) == 12
    assert kind.table_bits(p) == 9
    factors = np.array([0.0, 0.01, 0.5, 1.0])
    assert np.array_equal(kind.load(factors, p), quantize(factors, 9))
    assert np.array_equal(kind.entries(np.array([3, 512]), p), [3, 512])
    assert kind.max_clocks(p) == p.max_cycles


def test_the_wall_cycles_are_the_timing_rule_s() -> None:
    p = MachineParams.for_disparity(8, rng="lfsr")
    cycles = np.array([17, 30, 200])
    assert np.array_equal(p.kind.pixel_wall_cycles(p, cycles), pixel_wall_cycles(p, cycles))
    # A bubble after each run, the loads' beats the floor.
    assert np.array_equal(pixel_wall_cycles(p, cycles), np.maximum(cycles, p.beats_per_pixel + 1) + 1)


def test_its_engines_and_top_are_named() -> None:
    from bayesmachine.hdl.machine import BayesianMachine
    from bayesmachine.sim.model import MachineModel

    p = MachineParams.for_disparity(4)
    assert p.kind.engine_class("model") is MachineModel
    assert isinstance(p.kind.machine_top(p), BayesianMachine)
    assert p.kind.samples_per_pixel(p, 20.0) == 20.0
