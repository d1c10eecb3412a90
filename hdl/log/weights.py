"""The weights stage: each row's weight from the exp table, at its sum's distance from the least.

Three register stages: (1) the argmin's ``s_min`` and ``s_min + len(X) - 1`` copied into one
register per group of ``ROWS_PER_COPY`` rows (named ``*_rep*``: the FPGA flow keeps such copies
apart), so that no net fans out to every row; (2) per row ``d = sums[r] - s_min`` clamped to
[0, len(X) - 1] (the compare with ``s_min + len(X) - 1`` beside the subtraction, not after it), an
excluded row's index set to ``len(X) - 1`` (whose entry is 0, so no mux follows the table), and
the table X read at that index, registered as a block RAM's read (``pipeline.Lookup``: two rows per
block RAM; as a ROM in logic each row's table took more logic than the rest of the stage); (3) the
result packed. The argmin's fields ride along. Twin:
``sim.log_model.row_weights``.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Mux, Value

from bayesmachine.integrators.log import LogParams, check_params

from .layouts import best_layout, log_result_layout
from .pipeline import Bank, LogBlock, Lookup, Stage, Wire, fit, pack

__all__ = ["ROWS_PER_COPY", "WEIGHT_STAGES", "WeightStage", "weight_stages"]

WEIGHT_STAGES = 3
ROWS_PER_COPY = 8  # rows served by one register copy of s_min


def weight_stages(params: LogParams) -> tuple[Stage, ...]:
    """The weights stage's functions: ``best_layout(params, pass_sums=True)`` in,
    ``log_result_layout(params)`` out. Between them: ``{"rows", "fields", "s_min_rep<g>",
    "far_rep<g>"}`` (the rows' sums and flags, the argmin's fields, the copies), then
    ``(indices, fields)``."""
    p = params
    layout_in, layout_best, layout_out = best_layout(p, True), best_layout(p), log_result_layout(p)
    last = len(p.weights) - 1
    width = last.bit_length()
    copies = -(-p.rows // ROWS_PER_COPY)

    def spread(payload: Bank, wire: Wire) -> Bank:
        best = layout_in(Value.cast(payload))
        bank = {"rows": Cat(best.sums.as_value(), best.excluded),
                "fields": pack(layout_best, map=best.map, nomatch=best.nomatch,
                               all_excluded=best.all_excluded, s_min=best.s_min)}
        for g in range(copies):
            bank[f"s_min_rep{g}"] = best.s_min
            bank[f"far_rep{g}"] = best.s_min + last  # a row at or beyond it reads X[last]
        return bank

    def distances(bank: Bank, wire: Wire) -> Bank:
        sums_bits = p.rows * p.sum_bits
        rows, indices = bank["rows"], []
        for r in range(p.rows):
            s = rows[r * p.sum_bits:(r + 1) * p.sum_bits]
            s_min, far = bank[f"s_min_rep{r // ROWS_PER_COPY}"], bank[f"far_rep{r // ROWS_PER_COPY}"]
            d = s - s_min  # signed: below 0 only for a row the argmin did not weigh
            index = Mux(rows[sums_bits + r] | (s >= far), last, Mux(d < 0, 0, d[:width]))
            indices.append(fit(index, width))
        # Padded with 0s (= X[last]) to every index the index's bits can hold.
        table = p.weights + (0,) * ((1 << width) - len(p.weights))
        return Lookup(table, tuple(indices)), bank["fields"]

    def lookup(bank: Bank, wire: Wire) -> Bank:
        weights, fields = bank
        best = layout_best(Value.cast(fields))
        return pack(layout_out, map=best.map, nomatch=best.nomatch, all_excluded=best.all_excluded,
                    s_min=best.s_min, weights=Cat(*weights))

    return spread, distances, lookup


class WeightStage(LogBlock):
    """Each row's weight (``sim.log_model.row_weights``), one pixel per clock, latency ``WEIGHT_STAGES`` (3).

    Parameters
    ----------
    params : LogParams
        Rows, sum width, the exp table ``weights``.

    Attributes
    ----------
    best : ``In(stream.Signature(best_layout(params, pass_sums=True)))``
        The argmin's fields with the rows' sums and excluded flags.
    result : ``Out(stream.Signature(log_result_layout(params)))``
        The argmin's fields and each row's weight.
    latency : int
        3 clocks.
    """

    def __init__(self, *, params: LogParams) -> None:
        p = check_params(params)
        super().__init__(params=p, sink="best", source="result", in_layout=best_layout(p, True),
                         out_layout=log_result_layout(p), stages=weight_stages(p))
