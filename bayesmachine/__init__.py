"""bayesmachine: a stochastic Bayesian machine in Amaranth HDL, its model and its host."""
from .params import MachineParams, ParameterError

__all__ = ["MachineParams", "ParameterError"]
__version__ = "0.1.0"
