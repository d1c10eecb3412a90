"""What a pass's pixels carry on chip, from its columns' lane builders (:mod:`.lanes`): both images'
planes, the output flag and the position flags its columns read (:data:`FLAGS`, computed by the feature
pipeline), and its reference's own flags (:mod:`.reference`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from amaranth.hdl import unsigned
from amaranth.lib import data

from bayesmachine.models import ModelParams, Pass

from .filters import feature_layout
from .lanes import PlaneFilter, lanes_for
from .reference import reference_of

__all__ = ["FLAGS", "declared_passes", "features_layout", "model_filters", "pass_flags", "pass_pixel_layout",
           "pass_terms", "pipeline_flags", "pixel_features_layout"]

# The position flags a lane builder may ask its pixels to carry (computed by the feature pipeline), in
# the order they sit in a pixel: the first output pixel of an output row; a pixel of a frame's first
# output row; a pixel at a map column (>= 0) of an output row.
FLAGS = ("row_start", "first_row", "consult")


def pixel_features_layout(features: data.StructLayout | None = None,
                          flags: Mapping[str, Any] | None = None) -> data.StructLayout:
    """One pixel for a word generator: both images' planes (``left``, ``right``: ``features``, default
    the paper model's 5x5 sums), ``output`` (the pixel is in the output region) and ``flags``."""
    side = features if features is not None else feature_layout()
    return data.StructLayout({"left": side, "right": side, "output": unsigned(1), **(flags or {})})


def pass_terms(p: Pass) -> tuple[Any, ...]:
    """Pass ``p``'s columns, then its no-match rule: every term with a lane builder."""
    return (*p.columns, p.model.nomatch)


def declared_passes(model: ModelParams) -> tuple[Pass, ...]:
    """The passes ``model`` runs before its own (census-lr's right pass), each on a machine of its own
    beside the own pass's."""
    return model.passes[:-1]


def features_layout(model: ModelParams) -> data.StructLayout:
    """One image's planes, every one a pass of ``model`` reads, in the order its terms read them."""
    fields: dict[str, Any] = {}
    for p in model.passes:
        for term in pass_terms(p):
            for name, shape in lanes_for(term).planes(term, model.margin).items():
                fields.setdefault(name, shape)
    return data.StructLayout(fields)


def model_filters(model: ModelParams) -> tuple[PlaneFilter, ...]:
    """The plane filters the terms of every pass of ``model`` read, each once (equal filters are shared),
    in the order the terms read them."""
    out: dict[PlaneFilter, None] = {}
    for p in model.passes:
        for term in pass_terms(p):
            out.update(dict.fromkeys(lanes_for(term).filters(term, model.margin)))
    return tuple(out)


def _column_flags(passes: tuple[Pass, ...]) -> dict[str, Any]:
    wanted = {f for p in passes for c in p.columns for f in lanes_for(c).flags(c)}
    return {f: unsigned(1) for f in FLAGS if f in wanted}


def pipeline_flags(model: ModelParams) -> dict[str, Any]:
    """The position flags the feature pipeline computes: every pass's columns' (:data:`FLAGS` order)."""
    return _column_flags(model.passes)


def pass_flags(model: ModelParams, p: Pass) -> dict[str, Any]:
    """The flags pass ``p``'s pixels carry: its columns' (:data:`FLAGS` order), then its reference's."""
    return _column_flags((p,)) | reference_of(p).flags(model.dmax)


def pass_pixel_layout(model: ModelParams, p: Pass) -> data.StructLayout:
    """One pixel for the word generator of ``model``'s pass ``p``."""
    return pixel_features_layout(features_layout(model), pass_flags(model, p))
