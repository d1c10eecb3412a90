"""The logarithmic integrator's kind and definition: codes loaded, weights read out, its pixel clocks."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.columns import LeftPrior
from bayesmachine.columns.energy import INFINITE_CODE, log_codes
from bayesmachine.errors import ParameterError
from bayesmachine.integrators.log import LOG, LogParams, log_params, pixel_clocks, pixel_wall_cycles
from bayesmachine.models import ModelParams, disparity_machine, pass_machine
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
    assert pixel_clocks(flat) == (1, 1) and LOG.max_clocks(flat) == 1 and flat.cycle_width == 1
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


def test_integrator_parameter() -> None:
    stochastic = MachineParams.for_disparity(8)
    log = MachineParams.for_disparity(8, integrator="log")
    assert stochastic.integrator == "stochastic" and "integrator" not in stochastic.to_dict()
    assert log.to_dict()["integrator"] == "log" and log.fingerprint() != stochastic.fingerprint()
    assert stochastic.to_dict(complete=True)["integrator"] == "stochastic"
    assert (stochastic.load_max, stochastic.readout_max) == (1024, 16)
    assert (log.load_max, log.readout_max) == (INFINITE_CODE, 1024)
    with pytest.raises(ParameterError, match="integrator") as err:
        MachineParams.for_disparity(8, integrator="logarithmic")
    assert err.value.parameter == "integrator"
    with pytest.raises(TypeError, match="integrator"):
        MachineParams.for_disparity(8, integrator=1)


def test_feedback_table_in_codes() -> None:
    model = ModelParams(name="census-lr")
    log = disparity_machine(model, integrator="log")
    # Measured: the census-lr prior (eps 0.05, s 4, no-match 0.1) in 1/16-nat codes, clamped at 48.
    assert log.feedback_words == (0, 0, 2, 4, 7, 12, 16, 22, 28, 33, 38, 42, 45, 46, 47, 48)
    assert log.feedback_nomatch_word == 37
    left = model.column(LeftPrior)
    energy = left.energy()
    assert log.feedback_words == tuple(int(c) for c in energy.values[: len(log.feedback_words)])
    assert (energy.values[len(log.feedback_words):] == 48).all()
    assert pass_machine(model, log, "right").integrator == "log"
    stochastic = disparity_machine(model)
    with pytest.raises(ParameterError, match="feedback"):
        disparity_machine(model, integrator="log", feedback_words=stochastic.feedback_words)


@pytest.mark.parametrize(("field", "value"), [("counter_max", 2), ("rng", "lfsr"), ("samples_per_clock", 8),
                                              ("seed", 3), ("max_cycles", 40), ("normalize", False),
                                              ("timeout_answer", "leading"), ("smtj_dwell", 2.0)])
def test_a_log_machine_refuses_the_stochastic_fields(field: str, value: object) -> None:
    """None for a log machine, refused naming the field when given, absent from its dict."""
    with pytest.raises(ParameterError, match=f"^{field}: the stochastic integrator's") as err:
        MachineParams.for_disparity(8, integrator="log", **{field: value})
    assert err.value.parameter == field
    log = MachineParams.for_disparity(8, integrator="log")
    assert getattr(log, field) is None
    assert field not in log.to_dict(complete=True) and field not in log.to_dict()


def test_the_stochastic_machine_fills_its_defaults() -> None:
    p = MachineParams.for_disparity(8)
    assert {f: getattr(p, f) for f in p.kind.defaults} == dict(p.kind.defaults)
    # Its dict, hence its fingerprint, is the one it had before the kinds (the build caches key on it).
    assert p.fingerprint() == MachineParams.for_disparity(8, counter_max=16, rng="sobol").fingerprint()
    assert MachineParams.for_disparity(80).fingerprint() == "24c0655939c1f9ce"
