"""``FrontEnd`` (pixel pairs in, the machine's load beats out) and ``StereoMachine`` (pixels in,
disparity results out): the pipeline from a camera to the MAP, on chip.

Pixel stream: one ``pixel_in_layout()`` beat per pixel pair (``left``, ``right``: 8-bit gray;
``first``: set on the first pixel of a frame), frames in raster order, ``width`` pixels per line,
any number of lines (at least 2k + 1, k = ``model.margin``). The front end's position counters
restart at every ``first`` (and at reset), so a frame may follow another immediately: nothing
computed for a frame depends on pixels of an earlier one. The output region is the host's
(``host.region``: every window of the model inside the image): map rows 0..H-2k-1 (image lines
2k..H-1, a window's bottom line) and map columns Dmax..W-2k-1 (image columns Dmax+2k..W-1, a
window's right column); every other pixel passes in one cycle and starts no machine run.

Pipeline (one pixel per cycle when no output pixel holds it):

1. the pixel is taken and its column read from the line buffer (2k lines);
2. both images' 5-high columns' partial sums enter the feature filters' first registers (the
   census model: and the 7-high columns the census filters' column registers);
3. the columns' sums enter the filters' windows (the census filters' windows too);
4. the word generator takes the features (right ones into the delay line); for an output pixel
   it writes ``beats_per_pixel`` beats into a FIFO in front of the machine's load stream.

The FIFO (``fifo_pixels`` pixels of beats, block RAM) lets the front end run ahead while the
machine's runs are long and the line ends' non-output pixels stream in; when it is full,
back-pressure reaches the pixel input. Its ready toward the word generator is a register (set
while at most all but one entry is used; the FIFO has one entry more than the pixels' beats), so
no path runs from its level through the pixel take. Results leave in raster order of the output region, on
the machine's own result stream. With the census model's neighbour prior each result, as it
leaves, also goes back into the word generator's line of MAPs (the above neighbour's prior).
"""

from __future__ import annotations

import dataclasses

from amaranth.hdl import Module, Mux, Shape, Signal
from amaranth.lib import fifo, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.hdl.signatures import (
    ENTROPY_PORTS,
    StereoSignature,
    load_layout,
    load_stream,
    pixel_in_layout,
    pixel_stream,
    result_layout,
)
from bayesmachine.likelihood import ModelParams, disparity_machine
from bayesmachine.params import MachineParams, ParameterError, stereo_lanes

from . import DEFAULT_FIFO_PIXELS, MAX_WIDTH
from .census import CensusFilter
from .costs import WordGenerator, check_frontend_params, check_frontend_types
from .filters import FeatureFilter
from .linebuffer import WINDOW, LineBuffer
from .lr import feeder_in_layout, lr_split, right_pass_params

__all__ = ["MAX_WIDTH", "FrontEnd", "StereoMachine", "check_stereo_machine", "pixel_in_layout",
           "stereo_machine_params", "stereo_signature"]


def stereo_machine_params(dmax: int = 80, *, model: ModelParams | None = None,
                          **kwargs: object) -> MachineParams:
    """The machine the front end feeds: ``MachineParams.for_disparity`` (the paper model), or with a
    ``model`` (whose Dmax is ``dmax``) ``disparity_machine(model, ...)``, with the front end's lane
    count (:func:`stereo_lanes`) unless ``lanes`` is given."""
    if model is None:
        params = MachineParams.for_disparity(dmax, **kwargs)
    else:
        if model.dmax != dmax:
            raise ParameterError(f"dmax: {dmax} given, the model's is {model.dmax}")
        params = disparity_machine(model, **kwargs)
    return params if "lanes" in kwargs else dataclasses.replace(params, lanes=stereo_lanes(params))


def _check_width(width: object, model: ModelParams) -> int:
    if isinstance(width, bool) or not isinstance(width, int):
        raise ParameterError(f"width must be an integer, not {width!r}")
    size = 2 * model.margin + 1  # the model's windows
    if not model.dmax + size <= width <= MAX_WIDTH:
        raise ParameterError(
            f"width must be in [dmax + {size}, {MAX_WIDTH}] = [{model.dmax + size}, {MAX_WIDTH}] (a line "
            f"needs one output pixel with all {model.dmax + 1} disparities and its {size}x{size} windows), "
            f"got {width}")
    return width


def stereo_signature(params: MachineParams, model: ModelParams) -> wiring.Signature:
    """:class:`StereoMachine`'s ports: ``StereoSignature(params)``, and with census-lr also
    ``right_result``: ``valid`` and ``payload`` (``result_layout(right_pass_params(model, params))``),
    the right pass's results as they leave its machine (observed: no ``ready``, no back-pressure)."""
    if not model.lr:
        return StereoSignature(params)
    rp = right_pass_params(model, params)
    observed = wiring.Signature({"valid": Out(1), "payload": Out(result_layout(rp))})
    return wiring.Signature(dict(StereoSignature(params).members.items()) | {"right_result": Out(observed)})


def check_stereo_machine(params: MachineParams, model: ModelParams, width: int,
                         fifo_pixels: int = DEFAULT_FIFO_PIXELS) -> None:
    """``ParameterError`` naming the parameter unless ``StereoMachine(params=params, model=model,
    width=width, fifo_pixels=fifo_pixels)`` can be built (callers check before building anything: a
    component whose constructor fails would be reported as never elaborated); ``TypeError`` for a
    ``params`` or ``model`` of the wrong type."""
    check_frontend_types(params, model)
    check_frontend_params(params, model)
    _check_width(width, model)
    if isinstance(fifo_pixels, bool) or not isinstance(fifo_pixels, int) or not 1 <= fifo_pixels <= 64:
        raise ParameterError(f"fifo_pixels must be an integer in [1, 64], got {fifo_pixels!r}")


class FrontEnd(wiring.Component):
    """Pixel pairs in, the output pixels' likelihood-memory words out (the machine's load beats).

    Parameters
    ----------
    params : MachineParams
        The machine fed (see :func:`~.costs.check_frontend_params`).
    model : ModelParams
        The disparity model.
    width : int
        Pixels per image line (dmax + 2·margin + 1 .. ``MAX_WIDTH``).

    Attributes
    ----------
    pixels : ``In(pixel_stream())``
        Pixel pairs in raster order.
    beats : ``Out(load_stream(params))``
        The output pixels' load beats.
    result_take, result_map, result_hit : ``In(1)``, ``In(params.map_width)``, ``In(1)``
        With the neighbour prior only: the machine's results as they leave (see
        :class:`~.costs.WordGenerator`), for the above neighbour's prior column.
    right_beats, right_take, right_map, right_hit, right_room
        census-lr only: the right pass's load beats (``Out(load_stream(right_pass_params(model,
        params)))``), and its machine's results as they leave (taken only while ``right_room``: the
        line of right MAPs the left pass reads has room). See :mod:`.lr`.
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int) -> None:
        check_frontend_types(params, model)
        check_frontend_params(params, model)
        self._width = _check_width(width, model)
        self._params = params
        self._model = model
        members = {"pixels": In(pixel_stream()), "beats": Out(load_stream(params))}
        if params.feedback_columns:
            members |= {"result_take": In(1), "result_map": In(params.map_width), "result_hit": In(1)}
        if model.lr:
            rp = right_pass_params(model, params)
            members |= {"right_beats": Out(load_stream(rp)), "right_take": In(1),
                        "right_map": In(rp.map_width), "right_hit": In(1), "right_room": Out(1)}
        super().__init__(members)

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def width(self) -> int:
        return self._width

    def elaborate(self, platform: object) -> Module:
        m = Module()
        width, model = self._width, self._model
        dmax, margin = model.dmax, model.margin
        size = 2 * margin + 1  # the model's windows: line buffer columns of this height
        lag = margin - WINDOW // 2  # 5x5 features a line and a column behind a 7x7 census window
        neighbour = self._params.feedback_columns > 0
        m.submodules.linebuffer = lines = LineBuffer(width=width, height=size)
        m.submodules.filter_left = fl = FeatureFilter(lag=lag)
        m.submodules.filter_right = fr = FeatureFilter(lag=lag)
        if model.census:
            m.submodules.census_left = cl = CensusFilter(window=model.census_window)
            m.submodules.census_right = cr = CensusFilter(window=model.census_window)
        output_columns = width - 2 * margin - dmax if neighbour else None
        m.submodules.generator = gen = WordGenerator(params=self._params, model=model,
                                                     output_columns=output_columns)
        wiring.connect(m, gen.beats, wiring.flipped(self.beats))
        if neighbour:
            m.d.comb += [gen.result_take.eq(self.result_take), gen.result_map.eq(self.result_map),
                         gen.result_hit.eq(self.result_hit)]

        # The pipeline advances as a whole whenever its last stage is empty or taken.
        valid1 = Signal()  # stage 1: the line buffer shows the pixel's column
        valid2 = Signal()  # stage 2: the filters hold the column's partial sums
        valid3 = Signal()  # stage 3: the filters hold the pixel's window
        advance = Signal()

        # Stage 0: position of the incoming pixel (restarts at a frame's first pixel). The line
        # saturates at ``size``: size - 1 is the first line whose windows are complete (the first
        # output row), size any later one.
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
        with m.If(advance):
            m.d.sync += [valid1.eq(self.pixels.valid), col1.eq(cur_col), line1.eq(cur_line)]

        # Stage 1 -> 2: the columns' partial sums into the filters' first registers (the block
        # RAM's slow clock-to-output leaves no room for the whole column sum in one cycle); the
        # census filters take the whole column. The 5x5 filters take the column's middle 5 lines.
        output2, row_start2, first_row2 = Signal(), Signal(), Signal()
        line_end2, consult2 = Signal(), Signal()  # census-lr's
        m.d.comb += [fl.load.eq(advance), fr.load.eq(advance)]
        for i in range(WINDOW):
            m.d.comb += [fl.column[i].eq(lines.column[lag + i].left),
                         fr.column[i].eq(lines.column[lag + i].right)]
        if model.census:
            m.d.comb += [cl.load.eq(advance), cr.load.eq(advance)]
            for i in range(size):
                m.d.comb += [cl.column[i].eq(lines.column[i].left), cr.column[i].eq(lines.column[i].right)]
        first_output_col = dmax + size - 1
        with m.If(advance):
            m.d.sync += [valid2.eq(valid1),
                         output2.eq((line1 >= size - 1) & (col1 >= first_output_col)),
                         row_start2.eq(col1 == first_output_col),
                         first_row2.eq(line1 == size - 1),
                         # census-lr: an output row's last pixel, and a map column (>= 0) of an output row
                         line_end2.eq((line1 >= size - 1) & (col1 == width - 1)),
                         consult2.eq((line1 >= size - 1) & (col1 >= size - 1))]

        # Stage 2 -> 3: the columns' sums enter the filters' windows.
        output3, row_start3, first_row3 = Signal(), Signal(), Signal()
        line_end3, consult3 = Signal(), Signal()
        shift = advance & valid2
        m.d.comb += [fl.en.eq(shift), fr.en.eq(shift)]
        if model.census:
            m.d.comb += [cl.en.eq(shift), cr.en.eq(shift)]
        with m.If(advance):
            m.d.sync += [valid3.eq(valid2), output3.eq(output2), row_start3.eq(row_start2),
                         first_row3.eq(first_row2), line_end3.eq(line_end2), consult3.eq(consult2)]

        # Stage 3 -> the word generator (census-lr: through a FIFO, and to the right pass: lr_split).
        if model.lr:
            px = Signal(feeder_in_layout(model.census_bits))
            m.d.comb += [px.line_end.eq(line_end3), px.consult.eq(consult3)]
            ready3 = lr_split(m, self, gen, px, valid3, width - 2 * margin)
        else:
            px = gen.pixel.payload
            m.d.comb += gen.pixel.valid.eq(valid3)
            ready3 = gen.pixel.ready
        m.d.comb += [advance.eq(~valid3 | ready3), px.output.eq(output3)]
        for side, filt in ((px.left, fl), (px.right, fr)):
            m.d.comb += [side.m25.eq(filt.features.m25), side.gh20.eq(filt.features.gh20),
                         side.gv20.eq(filt.features.gv20)]
        if model.census:
            m.d.comb += [px.left.census.eq(cl.code), px.right.census.eq(cr.code)]
        if neighbour:
            m.d.comb += [px.row_start.eq(row_start3), px.first_row.eq(first_row3)]
        return m


class StereoMachine(wiring.Component):
    """Pixel pairs in, one result per output pixel out: the front end, a FIFO and the machine.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (lanes a multiple of the loaded columns: see
        :func:`stereo_machine_params`).
    model : ModelParams
        The disparity model (Dmax, p0, sigmas, p_nm0, sigma_nm).
    width : int
        Pixels per image line (dmax + 5 .. ``MAX_WIDTH``).
    fifo_pixels : int
        The pixels' worth of load beats the FIFO holds (1 .. 64).

    Attributes
    ----------
    The ports are :class:`~bayesmachine.hdl.signatures.StereoSignature` ``(params)``:

    pixels : ``In(pixel_stream())``
        Pixel pairs in raster order, ``first`` on a frame's first pixel.
    result : ``Out(result_stream(params))``
        The machine's results, in raster order of the output region.
    entropy, entropy_ready
        With an off-chip ``rng`` ("external", "smtj"): the machine's own ports, passed through
        (the numbers of every compute cycle come from outside, as for the machine alone).
    right_result
        census-lr only: the right pass's results, raster order of its columns, ``valid`` and
        ``payload`` (``result_layout(right_pass_params(model, params))``; :func:`stereo_signature`).
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int,
                 fifo_pixels: int = DEFAULT_FIFO_PIXELS) -> None:
        check_stereo_machine(params, model, width, fifo_pixels)
        self._params = params
        self._model = model
        self._width = width
        self._fifo_pixels = fifo_pixels
        super().__init__(stereo_signature(params, model))

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def width(self) -> int:
        return self._width

    @property
    def fifo_pixels(self) -> int:
        return self._fifo_pixels

    def _lr_right_machine(self, m: Module, front: FrontEnd) -> None:
        """census-lr: the right pass's machine beside the left one, fed through its own FIFO; its results
        go to the front end (taken while the front end's line of right MAPs has room) and out."""
        rp = right_pass_params(self._model, self._params)
        m.submodules.right_machine = machine = BayesianMachine(params=rp)
        m.submodules.right_fifo = buf = fifo.SyncFIFOBuffered(
            width=Shape.cast(load_layout(rp)).width, depth=self._fifo_pixels * rp.beats_per_pixel + 1)
        wiring.connect(m, front.right_beats, buf.w_stream)
        wiring.connect(m, buf.r_stream, machine.load)
        res = machine.result
        take = res.valid & front.right_room
        m.d.comb += [res.ready.eq(front.right_room), front.right_take.eq(take),
                     front.right_map.eq(res.payload.map),
                     front.right_hit.eq(~res.payload.nomatch & ~res.payload.timeout),
                     self.right_result.valid.eq(take), self.right_result.payload.eq(res.payload)]

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p = self._params
        m.submodules.frontend = front = FrontEnd(params=p, model=self._model, width=self._width)
        m.submodules.machine = machine = BayesianMachine(params=p)
        if self._model.lr:
            self._lr_right_machine(m, front)
        beat_bits = Shape.cast(load_layout(p)).width
        # One entry more than the pixels' beats: the registered ready below keeps one free.
        depth = self._fifo_pixels * p.beats_per_pixel + 1
        m.submodules.fifo = buf = fifo.SyncFIFOBuffered(width=beat_bits, depth=depth)
        wiring.connect(m, wiring.flipped(self.pixels), front.pixels)
        # The front end sees a registered ready (``room``), so no path runs from the FIFO's
        # level through the pixel take into the front end's thousands of enables. ``used``
        # counts the beats in the FIFO (its level); room is set while at most depth - 2 are in:
        # the inner FIFO (depth - 1 entries, holding at most ``used``) then takes the next
        # beat, and the FIFO fills to depth - 1 = fifo_pixels * beats_per_pixel beats.
        # (Our own count, not ``buf.level``: see "Back-pressure" in docs/frontend.md.)
        used = Signal(range(depth + 1))
        used_next = Signal(range(depth + 1))
        room = Signal()
        write = Signal()
        read = Signal()
        m.d.comb += [
            write.eq(front.beats.valid & room),
            read.eq(buf.r_stream.valid & buf.r_stream.ready),
            used_next.eq(used + write - read),
        ]
        m.d.sync += [used.eq(used_next), room.eq(used_next <= depth - 2)]
        m.d.comb += [
            buf.w_stream.payload.eq(front.beats.payload),
            buf.w_stream.valid.eq(write),
            front.beats.ready.eq(room),
            machine.load.payload.eq(buf.r_stream.payload),
            machine.load.valid.eq(buf.r_stream.valid),
            buf.r_stream.ready.eq(machine.load.ready),
        ]
        wiring.connect(m, machine.result, wiring.flipped(self.result))
        if p.feedback_columns:  # the neighbour prior's line of MAPs: each result as it leaves
            res = machine.result
            m.d.comb += [front.result_take.eq(res.valid & self.result.ready),
                         front.result_map.eq(res.payload.map),
                         front.result_hit.eq(~res.payload.nomatch & ~res.payload.timeout)]
        # An off-chip source's ports: the machine's and this top's come from the same
        # entropy_members(params), so they exist together.
        for name in ENTROPY_PORTS:
            if name in self.signature.members:
                inner, outer = getattr(machine, name), getattr(self, name)
                flow = self.signature.members[name].flow
                m.d.comb += inner.eq(outer) if flow == In else outer.eq(inner)
        return m
