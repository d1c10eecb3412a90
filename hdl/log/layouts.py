"""The log blocks' stream payloads, declared once (fields from bit 0 in this order)."""

from __future__ import annotations

from amaranth.hdl import unsigned
from amaranth.lib import data

from bayesmachine.integrators.log import LogParams

__all__ = ["best_layout", "codes_layout", "feedback_sums_layout", "log_result_layout", "row_sums_layout"]


def codes_layout(params: LogParams) -> data.ArrayLayout:
    """A pixel's energy codes: ``rows`` rows of ``codes`` codes of ``code_bits``, row 0 from bit 0."""
    return data.ArrayLayout(data.ArrayLayout(unsigned(params.code_bits), params.codes), params.rows)


def row_sums_layout(params: LogParams) -> data.StructLayout:
    """The row adders' output: each row's sum (``sum_bits``) and its excluded flag (bit r: row r)."""
    return data.StructLayout({"sums": data.ArrayLayout(unsigned(params.sum_bits), params.rows),
                              "excluded": unsigned(params.rows)})


def feedback_sums_layout(params: LogParams) -> data.StructLayout:
    """The feedback argmin's input: each row's sum of its other codes and excluded flag
    (:func:`row_sums_layout`) and its feedback code (``code_bits``), added to the sum in the tree."""
    return data.StructLayout({**row_sums_layout(params).members,
                              "feedback": data.ArrayLayout(unsigned(params.code_bits), params.rows)})


def best_layout(params: LogParams, pass_sums: bool = False) -> data.StructLayout:
    """The argmin tree's output: ``map``, ``nomatch``, ``all_excluded``, ``s_min``, and with
    ``pass_sums`` the input's ``sums`` and ``excluded`` (for the weights stage)."""
    fields = {"map": unsigned(params.map_width), "nomatch": unsigned(1), "all_excluded": unsigned(1),
              "s_min": unsigned(params.sum_bits)}
    if pass_sums:
        fields.update(row_sums_layout(params).members)
    return data.StructLayout(fields)


def log_result_layout(params: LogParams) -> data.StructLayout:
    """A pixel's result: the argmin's fields and each row's weight (``weight_bits``)."""
    return data.StructLayout({**best_layout(params).members,
                              "weights": data.ArrayLayout(unsigned(params.weight_bits), params.rows)})
