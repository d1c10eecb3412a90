"""The logarithmic integrator's blocks (Turck et al. 2025): energy codes summed per row, the MAP as
the row of the lowest sum, each row's weight from an exp table. ``rule`` is the definition (NumPy);
``RowAdders``, ``ArgminTree`` and ``WeightStage`` are its parts and ``LogIntegrator`` the whole, each
a stall pipeline (``pipeline``) at one pixel per clock; ``machine.LogMachine`` puts them behind the
machine's ports (``integrator = "log"``). docs/integrators.md."""

from .adders import RowAdders
from .argmin import ArgminTree
from .integrator import LogIntegrator
from .layouts import best_layout, codes_layout, log_result_layout, row_sums_layout
from .pipeline import PipelineNets, StallPipeline
from .rule import LogParams, LogResult, argmin_rows, log_integrate, row_sums, row_weights
from .weights import WeightStage

__all__ = [
    "ArgminTree", "LogIntegrator", "LogParams", "LogResult", "PipelineNets", "RowAdders", "StallPipeline",
    "WeightStage", "argmin_rows", "best_layout", "codes_layout", "log_integrate",
    "log_result_layout", "row_sums", "row_sums_layout", "row_weights",
]
