"""The logarithmic integrator's blocks (Turck et al. 2025): energy codes summed per row, the MAP as
the row of the lowest sum, each row's weight from an exp table. The definition (NumPy) is
``sim.log_model``'s rule, its parameters ``bayesmachine.integrators.log``'s; ``RowAdders``,
``ArgminTree`` and ``WeightStage`` are its parts, each a stall pipeline (``pipeline``) at one pixel per
clock, and ``LogIntegrator`` the whole (the parts and the issue between them, with a neighbour prior's
feedback column), which ``machine.LogMachine`` puts behind the machine's ports (``integrator = "log"``).
docs/integrators.md."""

from bayesmachine.integrators.log import LogParams

from .adders import RowAdders
from .argmin import ArgminTree
from .integrator import LogIntegrator
from .layouts import best_layout, codes_layout, log_result_layout, row_sums_layout
from .pipeline import PipelineNets, StallPipeline
from .weights import WeightStage

__all__ = [
    "ArgminTree", "LogIntegrator", "LogParams", "PipelineNets", "RowAdders", "StallPipeline", "WeightStage",
    "best_layout", "codes_layout", "log_result_layout", "row_sums_layout",
]
