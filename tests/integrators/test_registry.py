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


def test_either_kind_s_model_runs_without_amaranth() -> None:
    """The definitions and the host need no RTL package: the model engine of each kind on a crop of the
    bundled pair, with Amaranth's import refused."""
    code = """
import sys
class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "amaranth":
            raise ImportError(name)
sys.meta_path.insert(0, Refuse())
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine
left, right, _ = bundled_pair()
model = ModelParams(name="census", dmax=8)
prep = prepare(left[200:210, 250:290], right[200:210, 250:290], model, reference=False)
for integrator in ("stochastic", "log"):
    machine = disparity_machine(model, integrator=integrator)
    run = run_machine(prep, machine, "model", progress=False)
    assert run.map.size and machine.kind.pixel_wall_cycles(machine, run.cycles, run.timeout).size
assert "amaranth" not in sys.modules
"""
    subprocess.run([sys.executable, "-c", code], check=True)
