"""bayesmachine: a stochastic Bayesian machine in Amaranth HDL, its model and its host."""
from typing import Any

from .params import MachineParams, ParameterError

__all__ = ["BayesianMachineClassifier", "MachineParams", "ParameterError"]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    # The classifier needs scikit-learn: imported when asked for, so `import bayesmachine` stays light.
    if name == "BayesianMachineClassifier":
        from .classify.estimator import BayesianMachineClassifier

        return BayesianMachineClassifier
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
