"""The integrator registry (``bayesmachine.integrators``): one list of kinds, their names the params'."""

from __future__ import annotations

import subprocess
import sys

import pytest

from bayesmachine.errors import ParameterError
from bayesmachine.integrators import INTEGRATOR_KINDS, IntegratorKind, integrator_kind
from bayesmachine.params import INTEGRATORS, MachineParams


def test_the_params_integrators_are_the_registry_s_names() -> None:
    assert INTEGRATORS == tuple(INTEGRATOR_KINDS) == ("stochastic", "log")
    for name, kind in INTEGRATOR_KINDS.items():
        assert isinstance(kind, IntegratorKind) and kind.name == name and integrator_kind(name) is kind
        assert kind.loads in ("words", "codes") and kind.description
        assert set(kind.defaults) <= set(kind.fields)
        assert "model" in kind.engines and kind.engines["model"] == kind.model


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_machine_s_kind_is_its_integrator_s(integrator: str) -> None:
    params = MachineParams.for_disparity(8, integrator=integrator)
    assert params.kind is INTEGRATOR_KINDS[integrator]
    assert params.load_max == params.kind.load_max(params)
    assert params.readout_max == params.kind.readout_max(params)


def test_an_unknown_integrator_is_named() -> None:
    with pytest.raises(ParameterError, match="integrator must be one of") as e:
        integrator_kind("linear")
    assert e.value.parameter == "integrator"
    with pytest.raises(TypeError, match="integrator must be one of"):
        integrator_kind(3)  # type: ignore[arg-type]


def test_the_registry_imports_without_numpy_or_amaranth() -> None:
    code = ("import sys, bayesmachine.integrators, bayesmachine.integrators.log, "
            "bayesmachine.integrators.stochastic, bayesmachine.params; "
            "assert 'numpy' not in sys.modules and 'amaranth' not in sys.modules, sorted(sys.modules)")
    subprocess.run([sys.executable, "-c", code], check=True)
