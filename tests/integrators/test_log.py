"""The logarithmic integrator's kind and definition: codes loaded, weights read out, its pixel clocks."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.columns.energy import INFINITE_CODE, log_codes
from bayesmachine.integrators.log import LOG, LogParams, log_params, pixel_clocks, pixel_wall_cycles
from bayesmachine.params import MachineParams


def test_it_loads_codes_and_reads_weights() -> None:
    p = MachineParams.for_disparity(8, integrator="log")
    kind = p.kind
    assert kind is LOG and kind.loads == "codes" and not kind.draws_numbers and kind.fields == ()
    assert kind.load_max(p) == kind.empty(p) == INFINITE_CODE and kind.flat(p) == 0
    assert kind.readout_max(p) == p.word_one
    assert kind.table_bits(p) is None
    factors = np.array([0.0, 0.01, 0.5, 1.0])
    assert np.array_equal(kind.load(factors, p), log_codes(factors))
    assert kind.load(factors, p).dtype == np.uint16


def test_its_pixel_clocks_and_wall_cycles() -> None:
    flat = MachineParams.for_disparity(80, integrator="log")
    assert pixel_clocks(flat) == (1, 1) and LOG.max_clocks(flat) == (1 << 20) - 1  # a 20-bit cycles field
    cycles = np.ones(5, np.int64)
    assert np.array_equal(pixel_wall_cycles(flat, cycles), np.full(5, flat.beats_per_pixel))
    assert np.array_equal(LOG.pixel_wall_cycles(flat, cycles), pixel_wall_cycles(flat, cycles))


def test_its_rule_s_parameters() -> None:
    p = MachineParams.for_disparity(8, integrator="log", tie_break="lowest-index")
    lp = log_params(p)
    assert (lp.rows, lp.codes, lp.code_bits, lp.tie_break) == (10, 3, 9, "lowest-index")
    assert lp.weights[0] == p.word_one and lp.weights[-1] == 0
    assert LogParams(rows=4, codes=2, code_bits=4, weights=(4, 1, 0)).tie_break == "nomatch-first"
    with pytest.raises(TypeError, match="nomatch_row"):
        LogParams(rows=4, codes=2, code_bits=4, weights=(4, 0), nomatch_row=1)  # type: ignore[arg-type]


def test_its_engines_are_the_log_machine_s() -> None:
    from bayesmachine.sim.log_model import LogMachineModel

    assert LOG.engine_class("model") is LogMachineModel
    with pytest.raises(ValueError, match="'board': the log integrator runs on model, pysim, verilator"):
        LOG.engine_class("board")
