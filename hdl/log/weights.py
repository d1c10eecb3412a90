"""The weights stage: each row's weight from the exp table, at its sum's distance from the least.

Two register stages: (1) per row ``d = sums[r] - s_min`` clamped to [0, len(X) - 1], an excluded
row's index set to ``len(X) - 1`` (whose entry is 0, so no mux follows the table); (2) per row
the table X read at that index (a ROM in logic). The argmin's fields ride along. Twin:
``rule.row_weights``.
"""

from __future__ import annotations

from amaranth.hdl import Array, Cat, Const, Mux, Value

from .layouts import best_layout, log_result_layout
from .pipeline import Bank, LogBlock, Stage, Wire, fit, pack
from .rule import LogParams, check_params

__all__ = ["WEIGHT_STAGES", "WeightStage", "weight_stages"]

WEIGHT_STAGES = 2


def weight_stages(params: LogParams) -> tuple[Stage, ...]:
    """The weights stage's functions: ``best_layout(params, pass_sums=True)`` in,
    ``log_result_layout(params)`` out. The bank between them is ``(indices, best)``: each row's
    table index and the argmin's fields (flat, ``best_layout(params)``)."""
    p = params
    layout_in, layout_best, layout_out = best_layout(p, True), best_layout(p), log_result_layout(p)
    last = len(p.weights) - 1
    width = last.bit_length()

    def distances(payload: Bank, wire: Wire) -> Bank:
        best = layout_in(Value.cast(payload))
        indices = []
        for r in range(p.rows):
            d = best.sums[r] - best.s_min  # signed: below 0 only for a row the argmin did not weigh
            index = Mux(best.excluded[r] | (d >= last), last, Mux(d < 0, 0, d[:width]))
            indices.append(fit(index, width))
        fields = pack(layout_best, map=best.map, nomatch=best.nomatch, all_excluded=best.all_excluded,
                      s_min=best.s_min)
        return indices, fields

    def lookup(bank: Bank, wire: Wire) -> Bank:
        indices, fields = bank
        # Padded with 0s (= X[last]) to every index the index's bits can hold: a full case.
        table = Array(Const(w, p.weight_bits) for w in p.weights + (0,) * ((1 << width) - len(p.weights)))
        best = layout_best(Value.cast(fields))
        return pack(layout_out, map=best.map, nomatch=best.nomatch, all_excluded=best.all_excluded,
                    s_min=best.s_min, weights=Cat(*(table[i] for i in indices)))

    return distances, lookup


class WeightStage(LogBlock):
    """Each row's weight (``rule.row_weights``), one pixel per clock, latency ``WEIGHT_STAGES`` (2).

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
        2 clocks.
    """

    def __init__(self, *, params: LogParams) -> None:
        p = check_params(params)
        super().__init__(params=p, sink="best", source="result", in_layout=best_layout(p, True),
                         out_layout=log_result_layout(p), stages=weight_stages(p))
