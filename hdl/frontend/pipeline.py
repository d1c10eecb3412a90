"""``FeaturePipeline``: pixel pairs in, every pixel's features out, stages 0 to 3 of the front end
(docs/frontend.md, "Pipeline"): the line buffer and the plane filters every pass of the model reads
(:func:`~.layouts.model_filters`), with the position counters and the flags each pixel carries.

Stage 0: the pixel is taken and its column read from the line buffer (2k lines); stage 1: both images'
columns' partial sums enter the filters' first registers; stage 2: the columns' sums enter the filters'
windows; stage 3: the pixel's features leave, with where it is (:func:`pipeline_layout`). The position
counters restart at every ``first`` (and at reset).
"""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Cat, Module, Mux, Signal, Value, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.hdl.signatures import pixel_stream
from bayesmachine.models import ModelParams
from bayesmachine.params import ParameterError
from bayesmachine.region import OutputRegion

from . import MAX_WIDTH
from .layouts import (
    FLAGS,
    declared_passes,
    features_layout,
    model_filters,
    pipeline_flags,
    pixel_features_layout,
)
from .linebuffer import LineBuffer

__all__ = ["FeaturePipeline", "PipelineNets", "check_width", "line_region", "pipeline_layout"]


def check_width(width: object, model: ModelParams) -> int:
    """``width`` (a plain int) if a line of that many pixels has an output pixel with all its disparities
    and windows; ``TypeError`` unless an integer, ``ParameterError`` naming it otherwise."""
    width = as_int("width", width)
    size = 2 * model.margin + 1  # the model's windows
    if not model.dmax + size <= width <= MAX_WIDTH:
        raise ParameterError(
            f"width must be in [dmax + {size}, {MAX_WIDTH}] = [{model.dmax + size}, {MAX_WIDTH}] (a line "
            f"needs one output pixel with all {model.dmax + 1} disparities and its {size}x{size} windows), "
            f"got {width}", "width")
    return width



def line_region(model: ModelParams, width: int) -> OutputRegion:
    """The host's output region of frames of ``width``-pixel lines: its columns (a frame here has any
    number of lines, so it is the region of the shortest frame, 2·margin + 1 lines; only its columns
    are read)."""
    return OutputRegion.of_model((2 * model.margin + 1, width), model)



def pipeline_layout(model: ModelParams) -> data.StructLayout:
    """One pixel out of :class:`FeaturePipeline`: both images' planes, ``output`` and every pass's
    columns' position flags (``pixel``, :func:`~.layouts.pipeline_flags`: without declared passes the own
    pass's word generator's pixel), and where it is: ``line_begin`` (an image line's first pixel),
    ``output_line`` (a line with output pixels: a map row's), ``first_line`` (the frame's first such
    line) and ``frame_begin`` (the frame's first pixel); with declared passes ``line_end`` (an output
    row's last pixel), for their feeders (:func:`~.passes.split_pixels`)."""
    pixel = pixel_features_layout(features_layout(model), pipeline_flags(model))
    fields = {"pixel": pixel, "line_begin": unsigned(1),
              "output_line": unsigned(1), "first_line": unsigned(1), "frame_begin": unsigned(1)}
    if declared_passes(model):
        fields |= {"line_end": unsigned(1)}
    return data.StructLayout(fields)


@dataclass(frozen=True)
class PipelineNets:
    """The position counters of :class:`FeaturePipeline` (what ``FeaturePipeline.build`` returns beside its
    module: the mutants of ``hdl.formal`` read them, never Amaranth's internals)."""

    col: Signal  # registered: the next pixel's column (unless it starts a frame)
    line: Signal  # registered: the next pixel's line (saturating at the window's height)
    cur_col: Signal  # the incoming pixel's column: 0 on a frame's first pixel, else col
    cur_line: Signal  # the incoming pixel's line: 0 on a frame's first pixel, else line


class FeaturePipeline(wiring.Component):
    """Pixel pairs in, every pixel's features out (the line buffer and the plane filters the model's
    columns read, :func:`~.words.model_filters`: stages 0 to 3 of the module's pipeline).

    Parameters
    ----------
    model : ModelParams
        The disparity model.
    width : int
        Pixels per image line (dmax + 2·margin + 1 .. ``MAX_WIDTH``).

    Attributes
    ----------
    pixels : ``In(pixel_stream())``
        Pixel pairs in raster order.
    features : ``Out(stream.Signature(pipeline_layout(model)))``
        Every pixel, in raster order, its features three cycles after its take.
    """

    def __init__(self, *, model: ModelParams, width: int) -> None:
        if not isinstance(model, ModelParams):
            raise TypeError(f"model must be a bayesmachine.models.ModelParams, not {type(model).__name__}")
        self._width = check_width(width, model)
        self._model = model
        super().__init__({"pixels": In(pixel_stream()),
                          "features": Out(stream.Signature(pipeline_layout(model)))})

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def width(self) -> int:
        return self._width

    def elaborate(self, platform: object) -> Module:
        return self.build(platform)[0]

    def build(self, platform: object) -> tuple[Module, PipelineNets]:
        """The pipeline's module (what :meth:`elaborate` gives) and its position counters."""
        m = Module()
        width, model = self._width, self._model
        size = 2 * model.margin + 1  # the model's windows: line buffer columns of this height
        m.submodules.linebuffer = lines = LineBuffer(width=width, height=size)
        filters = []
        for planes in model_filters(model):
            pair = (planes.build(), planes.build())
            m.submodules[f"{planes.name}_left"], m.submodules[f"{planes.name}_right"] = pair
            filters.append((planes, pair))
        out = self.features

        # The pipeline advances as a whole whenever its last stage is empty or taken.
        valid1 = Signal()  # stage 1: the line buffer shows the pixel's column
        valid2 = Signal()  # stage 2: the filters hold the column's partial sums
        valid3 = Signal()  # stage 3: the filters hold the pixel's window
        advance = Signal()
        m.d.comb += advance.eq(~valid3 | out.ready)
        col1, line1, first1, nets = self._positions(m, lines, advance, valid1)

        # Stage 1 -> 2: the columns into the filters' first registers (the block RAM's slow
        # clock-to-output leaves no room for the whole column sum in one cycle): each filter takes the
        # column's middle ``height`` lines.
        for planes, (fl, fr) in filters:
            top = (size - planes.height) // 2
            m.d.comb += [fl.load.eq(advance), fr.load.eq(advance)]
            for i in range(planes.height):
                m.d.comb += [fl.column[i].eq(lines.column[top + i].left),
                             fr.column[i].eq(lines.column[top + i].right)]
        # Where the pixel is, carried along with it (the flags its pixel layout has).
        first_output_col = model.dmax + size - 1
        output_row = line1 >= size - 1
        where = {"row_start": col1 == first_output_col,  # the first output pixel of an output row
                 "first_row": line1 == size - 1,  # a pixel of a frame's first output row
                 "consult": output_row & (col1 >= size - 1)}  # a map column (>= 0) of an output row
        px, pay = out.payload.pixel, out.payload
        pairs = [(px.output, output_row & (col1 >= first_output_col)), (pay.line_begin, col1 == 0),
                 (pay.output_line, output_row), (pay.first_line, line1 == size - 1),
                 (pay.frame_begin, first1)]
        pairs += [(getattr(px, f), where[f]) for f in FLAGS if f in px.shape().members]
        if "line_end" in pay.shape().members:  # an output row's last pixel
            pairs.append((pay.line_end, output_row & (col1 == width - 1)))
        stage2 = Signal(len(pairs))
        stage3 = Signal(len(pairs))
        with m.If(advance):
            m.d.sync += [valid2.eq(valid1), stage2.eq(Cat(*(v for _, v in pairs)))]

        # Stage 2 -> 3: the columns enter the filters' windows.
        shift = advance & valid2
        for _, (fl, fr) in filters:
            m.d.comb += [fl.en.eq(shift), fr.en.eq(shift)]
        with m.If(advance):
            m.d.sync += [valid3.eq(valid2), stage3.eq(stage2)]

        # Stage 3 -> out.
        m.d.comb += [out.valid.eq(valid3), Cat(*(t for t, _ in pairs)).eq(stage3)]
        for planes, (fl, fr) in filters:
            for side, filt in ((px.left, fl), (px.right, fr)):
                m.d.comb += [getattr(side, name).eq(v) for name, v in planes.outputs(filt).items()]
        return m, nets

    def _positions(self, m: Module, lines: LineBuffer, advance: Value,
                   valid1: Signal) -> tuple[Signal, Signal, Signal, PipelineNets]:
        """Stage 0: the incoming pixel's column and line (restarting at a frame's first pixel; the line
        saturates at ``size``: size - 1 is the first line whose windows are complete, the first output
        row, size any later one) into the line buffer; returns them at stage 1 (column, line, first) and
        the counters."""
        width, size = self._width, 2 * self._model.margin + 1
        col = Signal(range(width))
        line = Signal(range(size + 1))
        pin = self.pixels.payload
        cur_col = Signal(range(width))
        cur_line = Signal(range(size + 1))
        with m.If(pin.first):
            m.d.comb += [cur_col.eq(0), cur_line.eq(0)]
        with m.Else():
            m.d.comb += [cur_col.eq(col), cur_line.eq(line)]
        take = self.pixels.valid & advance
        m.d.comb += [
            self.pixels.ready.eq(advance),
            lines.en.eq(take),
            lines.col.eq(cur_col),
            lines.pixel.left.eq(pin.left),
            lines.pixel.right.eq(pin.right),
        ]
        col1 = Signal(range(width))
        line1 = Signal(range(size + 1))
        with m.If(take):
            with m.If(cur_col == width - 1):
                m.d.sync += [col.eq(0), line.eq(Mux(cur_line == size, cur_line, cur_line + 1))]
            with m.Else():
                m.d.sync += [col.eq(cur_col + 1), line.eq(cur_line)]
        first1 = Signal()
        with m.If(advance):
            m.d.sync += [valid1.eq(self.pixels.valid), col1.eq(cur_col), line1.eq(cur_line),
                         first1.eq(pin.first)]
        return col1, line1, first1, PipelineNets(col=col, line=line, cur_col=cur_col, cur_line=cur_line)
