"""A pass's reference image on chip: which delay-line entry lane d of its word generator reads, the flags
its pixels carry, and what its feeder (:class:`~.passes.PassFeeder`) does to the feature pipeline's
pixels (``Pass.reference``: "left" or "right").

- the left image (:class:`Reference`): the pixels as the feature pipeline gives them; the match of lane
  d is the right pixel x - d, delay-line entry d;
- the right image (:class:`RightReference`): the feeder swaps the images and delays the reference by
  Dmax pixels, so that at left map column x the pass takes right map column x_r = x - Dmax, whose
  lanes d pair it with left map columns x_r + d (entry Dmax - d); after an output row's last pixel it
  flushes Dmax more right pixels, ``flush`` = k: lanes d > Dmax - k pair them with a left pixel past the
  last output column (word 0 in every FEATURES column). Its pixels cover every right map column of an
  output row (``host.likelihoods.pass_grid``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from amaranth.hdl import ShapeLike, Value, unsigned

from bayesmachine.errors import ParameterError

if TYPE_CHECKING:
    from bayesmachine.models import Pass

    from .lanes.context import LaneContext

__all__ = ["REFERENCES", "Reference", "RightReference", "flush_bits", "reference_of"]


def flush_bits(dmax: int) -> int:
    """Width of a right-reference pass's ``flush`` field (0 .. Dmax)."""
    return max(1, dmax.bit_length())


class Reference:
    """The left image as a pass's reference (the model's own pass's): entry d, no flags of its own, the
    pixels passed on unchanged."""

    name: ClassVar[str] = "left"
    swaps: ClassVar[bool] = False  # the feeder swaps the images (and delays the reference by Dmax)

    @staticmethod
    def entry(d: int, dmax: int) -> int:
        return d

    @staticmethod
    def flags(dmax: int) -> dict[str, ShapeLike]:
        return {}

    @staticmethod
    def row_pixels(map_columns: int, dmax: int) -> int:
        """The pass's pixels (its results) per output row of ``map_columns`` map columns (W - 2k): the
        output pixels, map columns Dmax .."""
        return map_columns - dmax

    def lane_valid(self, ctx: LaneContext, j: int) -> Value | None:
        """Whether lane row j of the beat on the stream has a match pixel (None: always)."""
        return None

    def match_ok(self, ctx: LaneContext, row: Value, scanned: bool = False) -> Value | None:
        """Whether row ``row`` (<= Dmax) of the pixel taken has a match pixel (None: always); ``scanned``:
        of the pixel being scanned instead (``ctx.scan_pixel``, in the cycles of its fetches:
        ``ScanRing``)."""
        return None


class RightReference(Reference):
    """The right image as reference (see the module text): entry Dmax - d, the ``flush`` flag."""

    name = "right"
    swaps = True

    @staticmethod
    def entry(d: int, dmax: int) -> int:
        return dmax - d

    @staticmethod
    def flags(dmax: int) -> dict[str, ShapeLike]:
        return {"flush": unsigned(flush_bits(dmax))}

    @staticmethod
    def row_pixels(map_columns: int, dmax: int) -> int:
        """Every right map column an output pixel reads: 0 .. W - 2k - 1."""
        return map_columns

    def lane_valid(self, ctx: LaneContext, j: int) -> Value | None:
        return ctx.aligned(self.match_ok(ctx, ctx.row(j)), f"lane_ok{j}")

    def match_ok(self, ctx: LaneContext, row: Value, scanned: bool = False) -> Value | None:
        if scanned:
            return row + ctx.scan_pixel.flush <= ctx.dmax
        return row + ctx.taken("flush") <= ctx.dmax


REFERENCES: dict[str, type[Reference]] = {r.name: r for r in (Reference, RightReference)}


def reference_of(p: Pass) -> Reference:
    """The reference of pass ``p``; ``ParameterError`` naming the pass for an image the front end has none
    for."""
    if p.reference not in REFERENCES:
        raise ParameterError(f"model: the on-chip front end takes passes with the {' or '.join(REFERENCES)} "
                             f"image as reference, not the {p.name} pass's {p.reference!r}", "model")
    return REFERENCES[p.reference]()
