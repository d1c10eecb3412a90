"""The logarithmic integrator: a pixel's energy codes in, its MAP and each row's weight out.

One stall pipeline (``pipeline.StallPipeline``) made of the three blocks' stages in a row: the
row adders (``adders.adder_stages``), the argmin tree carrying the sums (``argmin.argmin_stages``)
and the weights stage (``weights.weight_stages``). One pipeline rather than three components
connected by streams: one ``go`` (and its copies) for every register and one output buffer, and
a stage boundary between blocks costs nothing more than a boundary inside one. One pixel per clock; latency
``RowAdders.latency + ArgminTree.latency + WEIGHT_STAGES`` (3). The definition:
``sim.log_model.log_integrate``.
"""

from __future__ import annotations

from bayesmachine.checks import as_int
from bayesmachine.integrators.log import LogParams, check_params

from .adders import adder_stages
from .argmin import argmin_stages
from .layouts import codes_layout, log_result_layout
from .pipeline import LogBlock
from .weights import weight_stages

__all__ = ["LogIntegrator"]


class LogIntegrator(LogBlock):
    """The log integrator (``sim.log_model.log_integrate``), one pixel per clock.

    Parameters
    ----------
    params : LogParams
        The rule's parameters.
    levels_per_stage : int
        Argmin-tree levels between two registers (1 ... 64; the tree has ceil(log2 rows) levels).
    adder_levels_per_stage : int
        Adder-tree levels between two registers (1 ... 64; ceil(log2 codes) levels).

    Attributes
    ----------
    codes : ``In(stream.Signature(codes_layout(params)))``
        A pixel's energy codes.
    result : ``Out(stream.Signature(log_result_layout(params)))``
        ``map``, ``nomatch``, ``all_excluded``, ``s_min`` and each row's ``weights``.
    latency : int
        Clocks from a pixel taken to its result offered: the adders' stages, the tree's and 3.
    """

    def __init__(self, *, params: LogParams, levels_per_stage: int = 1,
                 adder_levels_per_stage: int = 1) -> None:
        self._levels = as_int("levels_per_stage", levels_per_stage, 1, 64)
        self._adder_levels = as_int("adder_levels_per_stage", adder_levels_per_stage, 1, 64)
        p = check_params(params)
        stages = (*adder_stages(p, self._adder_levels), *argmin_stages(p, self._levels, True),
                  *weight_stages(p))
        super().__init__(params=p, sink="codes", source="result", in_layout=codes_layout(p),
                         out_layout=log_result_layout(p), stages=stages)

    @property
    def levels_per_stage(self) -> int:
        return self._levels

    @property
    def adder_levels_per_stage(self) -> int:
        return self._adder_levels
