"""``FrontEnd`` (pixel pairs in, the machine's load beats out) and ``StereoMachine`` (pixels in,
disparity results out): the pipeline from a camera to the MAP, on chip.

Pixel stream: one ``pixel_in_layout()`` beat per pixel pair (``left``, ``right``: 8-bit gray;
``first``: set on the first pixel of a frame), frames in raster order, ``width`` pixels per line,
any number of lines (at least 2k + 1, k = ``model.margin``). The front end's position counters
restart at every ``first`` (and at reset), so a frame may follow another immediately: nothing
computed for a frame depends on pixels of an earlier one. The output region is the host's
(``bayesmachine.region``: every window of the model inside the image): map rows 0..H-2k-1 (image lines
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
from dataclasses import dataclass

from amaranth.hdl import Array, Cat, Module, Mux, Shape, Signal, Value, unsigned
from amaranth.lib import data, fifo, stream, wiring
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
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import MachineParams, ParameterError, stereo_words_per_beat
from bayesmachine.region import OutputRegion
from bayesmachine.sources import source_kind

from . import DEFAULT_FIFO_PIXELS, MAX_MACHINES, MAX_WIDTH
from .linebuffer import LineBuffer
from .lr import feeder_in_layout, lr_split, pass_params
from .words import (
    FLAGS,
    WordGenerator,
    check_frontend_params,
    check_frontend_types,
    declared_passes,
    features_layout,
    model_filters,
    pass_pixel_layout,
)

__all__ = ["MAX_MACHINES", "MAX_WIDTH", "FeaturePipeline", "FrontEnd", "PipelineNets", "RoomFifo",
           "StereoMachine", "StereoNets", "check_machines",
           "check_stereo_machine", "pipeline_layout", "pixel_in_layout", "stereo_machine_params",
           "stereo_signature"]


def stereo_machine_params(dmax: int = 80, *, model: ModelParams | None = None,
                          **kwargs: object) -> MachineParams:
    """The machine the front end feeds: ``MachineParams.for_disparity`` (the paper model), or with a
    ``model`` (whose Dmax is ``dmax``) ``disparity_machine(model, ...)``, with the front end's lane
    count (:func:`stereo_words_per_beat`) unless ``words_per_beat`` is given."""
    if model is None:
        params = MachineParams.for_disparity(dmax, **kwargs)
    else:
        if model.dmax != dmax:
            raise ParameterError(f"dmax: {dmax} given, the model's is {model.dmax}")
        params = disparity_machine(model, **kwargs)
    return params if "words_per_beat" in kwargs else dataclasses.replace(params,
                                                                         words_per_beat=stereo_words_per_beat(params))


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


def _line_region(model: ModelParams, width: int) -> OutputRegion:
    """The host's output region of frames of ``width``-pixel lines: its columns (a frame here has any
    number of lines, so it is the region of the shortest frame, 2·margin + 1 lines; only its columns
    are read)."""
    return OutputRegion.of_model((2 * model.margin + 1, width), model)


def check_machines(machines: object, params: MachineParams, model: ModelParams) -> int:
    """``machines`` if a ``StereoMachine`` can have that many machines: an integer (``TypeError``
    otherwise) in [1, MAX_MACHINES], more than one only for an on-chip random source (off chip,
    each machine would need its own number port and device stream) and not for census-lr (its
    right pass is not dealt to several), else ``ParameterError`` naming the parameter."""
    if isinstance(machines, bool) or not isinstance(machines, int):
        raise TypeError(f"machines must be an integer, not {type(machines).__name__}")
    if not 1 <= machines <= MAX_MACHINES:
        raise ParameterError(f"machines must be in [1, {MAX_MACHINES}], got {machines}")
    if machines > 1:
        if not source_kind(params.rng).on_chip:
            raise ParameterError(f"machines = {machines}: rng {params.rng!r} is off chip (one number port, "
                                 "one device stream); several machines need an on-chip source "
                                 "(sobol, lfsr, lfsr-shared)")
        for p in declared_passes(model):
            raise ParameterError(f"machines = {machines}: --model {model.name} runs with one machine "
                                 f"(its {p.name} pass is not dealt to several)")
    return machines


def stereo_signature(params: MachineParams, model: ModelParams) -> wiring.Signature:
    """:class:`StereoMachine`'s ports: ``StereoSignature(params)``, and per declared pass (census-lr's
    right pass) ``<pass>_result``: ``valid`` and ``payload`` (``result_layout(pass_params(model, params,
    name))``), its results as they leave its machine (observed: no ``ready``, no back-pressure)."""
    members = dict(StereoSignature(params).members.items())
    for p in declared_passes(model):
        observed = wiring.Signature({"valid": Out(1),
                                     "payload": Out(result_layout(pass_params(model, params, p.name)))})
        members[f"{p.name}_result"] = Out(observed)
    return wiring.Signature(members) if declared_passes(model) else StereoSignature(params)


def check_stereo_machine(params: MachineParams, model: ModelParams, width: int,
                         fifo_pixels: int = DEFAULT_FIFO_PIXELS, machines: int = 1) -> None:
    """``ParameterError`` naming the parameter unless ``StereoMachine(params=params, model=model,
    width=width, fifo_pixels=fifo_pixels, machines=machines)`` can be built (callers check before
    building anything: a component whose constructor fails would be reported as never elaborated);
    ``TypeError`` for a ``params``, ``model`` or ``machines`` of the wrong type."""
    check_frontend_types(params, model)
    check_machines(machines, params, model)
    check_frontend_params(params, model)
    _check_width(width, model)
    if isinstance(fifo_pixels, bool) or not isinstance(fifo_pixels, int) or not 1 <= fifo_pixels <= 64:
        raise ParameterError(f"fifo_pixels must be an integer in [1, 64], got {fifo_pixels!r}")


RESULT_FIFO_MAX = 511  # results buffered per machine of several (one DP16KD deep at 36 bits wide)


def pipeline_layout(model: ModelParams) -> data.StructLayout:
    """One pixel out of :class:`FeaturePipeline`: the model's own pass's word generator's pixel
    (``pixel``, :func:`~.words.pass_pixel_layout`) and where it is: ``line_begin`` (an image line's first
    pixel), ``output_line`` (a line with output pixels: a map row's), ``first_line`` (the frame's first
    such line) and ``frame_begin`` (the frame's first pixel); with declared passes ``line_end`` (an
    output row's last pixel), for :func:`~.lr.lr_split`."""
    fields = {"pixel": pass_pixel_layout(model, model.passes[-1]), "line_begin": unsigned(1),
              "output_line": unsigned(1), "first_line": unsigned(1), "frame_begin": unsigned(1)}
    if declared_passes(model):
        fields |= {"line_end": unsigned(1)}
    return data.StructLayout(fields)


@dataclass(frozen=True)
class PipelineNets:
    """The position counters of :class:`FeaturePipeline` (``FeaturePipeline.nets``: the formal wrappers of
    ``hdl.formal`` and their mutants read them, never Amaranth's internals)."""

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
    nets : PipelineNets
        After elaboration: the position counters, for the formal wrappers (read-only).
    """

    def __init__(self, *, model: ModelParams, width: int) -> None:
        if not isinstance(model, ModelParams):
            raise TypeError(f"model must be a bayesmachine.models.ModelParams, not {type(model).__name__}")
        self._width = _check_width(width, model)
        self._model = model
        self._nets: PipelineNets | None = None
        super().__init__({"pixels": In(pixel_stream()),
                          "features": Out(stream.Signature(pipeline_layout(model)))})

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def width(self) -> int:
        return self._width

    @property
    def nets(self) -> PipelineNets:
        """The :class:`PipelineNets` of the last :meth:`elaborate`; elaborate first."""
        if self._nets is None:
            raise RuntimeError("FeaturePipeline.nets: elaborate the pipeline first (Fragment.get)")
        return self._nets

    def elaborate(self, platform: object) -> Module:
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
        col1, line1, first1 = self._positions(m, lines, advance, valid1)

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
        return m

    def _positions(self, m: Module, lines: LineBuffer, advance: Value, valid1: Signal) -> tuple[Signal, ...]:
        """Stage 0: the incoming pixel's column and line (restarting at a frame's first pixel; the line
        saturates at ``size``: size - 1 is the first line whose windows are complete, the first output
        row, size any later one) into the line buffer; returns them at stage 1 (column, line, first)."""
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
        self._nets = PipelineNets(col=col, line=line, cur_col=cur_col, cur_line=cur_line)
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
        return col1, line1, first1


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
        Per declared pass (census-lr's ``right``), ``<pass>_beats``, ...: its load beats
        (``Out(load_stream(pass_params(model, params, name)))``), and its machine's results as they
        leave (taken only while ``<pass>_room``: the line of its MAPs the own pass reads has room).
        See :mod:`.lr`.
    feature_pipeline : type
        Class attribute: the :class:`FeaturePipeline` class :meth:`elaborate` builds (a subclass may
        name another with the same constructor: a formal mutant's).
    """

    feature_pipeline: type[FeaturePipeline] = FeaturePipeline

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int) -> None:
        check_frontend_types(params, model)
        check_frontend_params(params, model)
        self._width = _check_width(width, model)
        self._params = params
        self._model = model
        members = {"pixels": In(pixel_stream()), "beats": Out(load_stream(params))}
        if params.feedback_columns:
            members |= {"result_take": In(1), "result_map": In(params.map_width), "result_hit": In(1)}
        for p in declared_passes(model):
            pp, n = pass_params(model, params, p.name), p.name
            members |= {f"{n}_beats": Out(load_stream(pp)), f"{n}_take": In(1),
                        f"{n}_map": In(pp.map_width), f"{n}_hit": In(1), f"{n}_room": Out(1)}
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
        model = self._model
        neighbour = self._params.feedback_columns > 0
        m.submodules.pipeline = pipe = self.feature_pipeline(model=model, width=self._width)
        region = _line_region(model, self._width)
        output_columns = region.shape[1] if neighbour else None
        m.submodules.generator = gen = WordGenerator(params=self._params, model=model,
                                                     output_columns=output_columns)
        wiring.connect(m, wiring.flipped(self.pixels), pipe.pixels)
        features = pipe.features
        if declared_passes(model):  # through a FIFO, and to the right pass (lr_split)
            pix, px = features.payload.pixel, Signal(feeder_in_layout(features_layout(model)))
            m.d.comb += [px.left.eq(pix.left), px.right.eq(pix.right), px.output.eq(pix.output),
                         px.consult.eq(pix.consult), px.line_end.eq(features.payload.line_end)]
            if neighbour:
                m.d.comb += [px.row_start.eq(pix.row_start), px.first_row.eq(pix.first_row)]
            ready = lr_split(m, self, gen, px, features.valid, region.feature_shape[1])
            m.d.comb += features.ready.eq(ready)
        else:
            m.d.comb += [gen.pixel.valid.eq(features.valid), gen.pixel.payload.eq(features.payload.pixel),
                         features.ready.eq(gen.pixel.ready)]
        wiring.connect(m, gen.beats, wiring.flipped(self.beats))
        if neighbour:
            m.d.comb += [gen.result_take.eq(self.result_take), gen.result_map.eq(self.result_map),
                         gen.result_hit.eq(self.result_hit)]
        return m


@dataclass(frozen=True)
class RoomFifo:
    """A FIFO whose writer sees a registered ``room`` (:func:`_room_fifo`), and its count nets."""

    buffer: fifo.SyncFIFOBuffered
    room: Signal  # registered: at most capacity - 1 entries in, a write may follow
    write: Signal  # driven by the caller, only while room: an entry written this cycle
    read: Signal  # an entry read this cycle
    used: Signal  # registered: the entries in the FIFO, counted beside it (write - read)


@dataclass(frozen=True)
class StereoNets:
    """The blocks of :class:`StereoMachine` a proof watches (``StereoMachine.nets``: the formal wrappers
    of ``hdl.formal`` and their mutants read them, never Amaranth's internals)."""

    frontend: FrontEnd | FeaturePipeline  # one machine: the front end; several: the one feature pipeline
    machines: list[BayesianMachine]  # the own pass's machines (machine j runs map rows j mod K)
    loads: list[RoomFifo]  # machine j's load FIFO: its word generator's beats


class StereoMachine(wiring.Component):
    """Pixel pairs in, one result per output pixel out: the front end, a FIFO and the machine.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (``words_per_beat`` a multiple of the loaded columns: see
        :func:`stereo_machine_params`).
    model : ModelParams
        The disparity model (Dmax, p0, sigmas, p_nm0, sigma_nm).
    width : int
        Pixels per image line (dmax + 2·margin + 1 .. ``MAX_WIDTH``).
    fifo_pixels : int
        The pixels' worth of load beats the FIFO holds (1 .. 64), per machine.
    machines : int
        Machines behind the one feature pipeline (1 .. ``MAX_MACHINES``; more than one: an on-chip
        ``rng``, see :func:`check_machines`). Map row r of a frame runs on machine r mod K, with
        its own word generator (see "Several machines" in docs/frontend.md).

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
        ``payload`` (:func:`stereo_signature`).
    nets : StereoNets
        After elaboration: the front end, the machines and their load FIFOs, for the formal wrappers
        (read-only).
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int,
                 fifo_pixels: int = DEFAULT_FIFO_PIXELS, machines: int = 1) -> None:
        check_stereo_machine(params, model, width, fifo_pixels, machines)
        self._params = params
        self._model = model
        self._width = width
        self._fifo_pixels = fifo_pixels
        self._machines = machines
        self._nets: StereoNets | None = None
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

    @property
    def machines(self) -> int:
        return self._machines

    @property
    def nets(self) -> StereoNets:
        """The :class:`StereoNets` of the last :meth:`elaborate`; elaborate first."""
        if self._nets is None:
            raise RuntimeError("StereoMachine.nets: elaborate the machine first (Fragment.get)")
        return self._nets

    def _pass_machine(self, m: Module, front: FrontEnd, name: str) -> None:
        """A declared pass's machine (census-lr's right pass) beside the own one, fed through its own
        FIFO; its results go to the front end (taken while the front end's line of its MAPs has room)
        and out on ``<name>_result``."""
        rp = pass_params(self._model, self._params, name)
        m.submodules[f"{name}_machine"] = machine = BayesianMachine(params=rp)
        m.submodules[f"{name}_fifo"] = buf = fifo.SyncFIFOBuffered(
            width=Shape.cast(load_layout(rp)).width, depth=self._fifo_pixels * rp.beats_per_pixel + 1)
        port = {k: getattr(front, f"{name}_{k}") for k in ("beats", "take", "map", "hit", "room")}
        out = getattr(self, f"{name}_result")
        wiring.connect(m, port["beats"], buf.w_stream)
        wiring.connect(m, buf.r_stream, machine.load)
        res = machine.result
        take = res.valid & port["room"]
        m.d.comb += [res.ready.eq(port["room"]), port["take"].eq(take), port["map"].eq(res.payload.map),
                     port["hit"].eq(~res.payload.nomatch & ~res.payload.timeout),
                     out.valid.eq(take), out.payload.eq(res.payload)]

    def elaborate(self, platform: object) -> Module:
        if self._machines > 1:
            return self._elaborate_machines()
        m = Module()
        p = self._params
        m.submodules.frontend = front = FrontEnd(params=p, model=self._model, width=self._width)
        m.submodules.machine = machine = BayesianMachine(params=p)
        for declared in declared_passes(self._model):
            self._pass_machine(m, front, declared.name)
        wiring.connect(m, wiring.flipped(self.pixels), front.pixels)
        # The front end sees the FIFO's registered room, so no path runs from the FIFO's level through
        # the pixel take into the front end's thousands of enables (see "Back-pressure" in
        # docs/frontend.md).
        beats = self._fifo_pixels * p.beats_per_pixel
        load = _load_fifo(m, "fifo", front.beats, machine.load, beats, prefix="")
        self._nets = StereoNets(frontend=front, machines=[machine], loads=[load])
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

    def _elaborate_machines(self) -> Module:
        """K machines: one feature pipeline; a dealer sends the pixels of map row r to lane r mod K
        (a line FIFO, a word generator, a beats FIFO, a machine, a result FIFO); the results leave
        lane by lane, a map row at a time, in the order the rows were dealt."""
        m = Module()
        p, model, width, k = self._params, self._model, self._width, self._machines
        neighbour = p.feedback_columns > 0
        wo = _line_region(model, width).shape[1]  # output pixels per map row
        m.submodules.frontend = pipe = FeaturePipeline(model=model, width=width)
        wiring.connect(m, wiring.flipped(self.pixels), pipe.pixels)
        fx, w = pipe.features, pipe.features.payload

        # Rows in flight, in dealing order: the lane of each map row dealt and not yet out.
        dealt = _room_fifo(m, "rows", Shape.cast(range(k)).width, 4 * k + 4)
        rows, row_room, row_write = dealt.buffer, dealt.room, dealt.write
        rows_open = Signal(range(4 * k + 6))
        idle = Signal(init=1)  # registered: no row in flight

        # The dealer: a map row's pixels go to its lane's line FIFO (a line's worth: the filters
        # move on to the next rows while a machine works through this one); other lines' pixels
        # (the first 2k, the frame's top) are dropped.
        lane = Signal(range(k))  # the lane of the current map row
        new_row = w.output_line & w.line_begin
        following = Mux(w.first_line | (lane == k - 1), 0, lane + 1)
        target = Mux(w.line_begin, following, lane)
        pixel_bits = Shape.cast(w.pixel.shape()).width
        lines = [_room_fifo(m, f"line{j}", pixel_bits, width) for j in range(k)]
        fits = Array(f.room for f in lines)[target] & (~new_row | row_room)
        # Neighbour prior: a frame's first pixel waits until every machine is idle, then the word
        # generators' counts of results above restart (rows of two frames never share a line of MAPs).
        hold = w.frame_begin & ~idle if neighbour else Value.cast(0)
        m.d.comb += fx.ready.eq(~hold & (~w.output_line | fits))
        take = fx.valid & fx.ready
        frame_reset = take & w.frame_begin
        for j, f in enumerate(lines):
            m.d.comb += [f.write.eq(take & w.output_line & (target == j)),
                         f.buffer.w_stream.payload.eq(w.pixel.as_value())]
        m.d.comb += [row_write.eq(take & new_row), rows.w_stream.payload.eq(target)]
        with m.If(take & new_row):
            m.d.sync += lane.eq(following)

        # The machines.
        res_bits = Shape.cast(result_layout(p)).width
        gens, machines, loads, results = [], [], [], []
        for j in range(k):
            gen = WordGenerator(params=p, model=model, output_columns=wo if neighbour else None,
                                leads=j == 0)
            machine = BayesianMachine(params=p)
            m.submodules[f"generator{j}"] = gen
            m.submodules[f"machine{j}"] = machine
            line = lines[j].buffer
            m.d.comb += [gen.pixel.valid.eq(line.r_stream.valid),
                         gen.pixel.payload.as_value().eq(line.r_stream.payload),
                         line.r_stream.ready.eq(gen.pixel.ready)]
            beats = self._fifo_pixels * p.beats_per_pixel
            loads.append(_load_fifo(m, f"beats{j}", gen.beats, machine.load, beats))
            # A map row's results wait here while the rows dealt before it leave (a row's worth, at
            # most 511: one block RAM deep in its 36-bit-wide mode; a longer row's machine may wait
            # for the row before it to leave).
            results.append(_room_fifo(m, f"results{j}", res_bits, min(wo, RESULT_FIFO_MAX)))
            gens.append(gen)
            machines.append(machine)
        for j, machine in enumerate(machines):
            buf, room, write = results[j].buffer, results[j].room, results[j].write
            below = gens[(j + 1) % k]  # the generator of the map rows below this machine's
            res = machine.result
            accept = room & below.result_room if neighbour else room
            m.d.comb += [write.eq(res.valid & accept), res.ready.eq(accept),
                         buf.w_stream.payload.eq(res.payload.as_value())]
            if neighbour:  # the line of MAPs of the rows below: each result as it leaves
                m.d.comb += [below.result_take.eq(write), below.result_map.eq(res.payload.map),
                             below.result_hit.eq(~res.payload.nomatch & ~res.payload.timeout),
                             below.frame_reset.eq(frame_reset)]

        # The merge: a map row's wo results from its lane, rows in dealing order (raster order).
        col = Signal(range(wo))
        src = rows.r_stream.payload
        out = self.result
        m.d.comb += [out.valid.eq(rows.r_stream.valid & Array(f.buffer.r_stream.valid for f in results)[src]),
                     out.payload.as_value().eq(Array(f.buffer.r_stream.payload for f in results)[src])]
        sent = out.valid & out.ready
        for j, f in enumerate(results):
            m.d.comb += f.buffer.r_stream.ready.eq(rows.r_stream.valid & (src == j) & out.ready)
        row_done = sent & (col == wo - 1)
        m.d.comb += rows.r_stream.ready.eq(row_done)
        with m.If(sent):
            m.d.sync += col.eq(Mux(col == wo - 1, 0, col + 1))
        open_next = Signal.like(rows_open)
        m.d.comb += open_next.eq(rows_open + row_write - row_done)
        m.d.sync += [rows_open.eq(open_next), idle.eq(open_next == 0)]
        self._nets = StereoNets(frontend=pipe, machines=machines, loads=loads)
        return m


def _room_fifo(m: Module, name: str, width: int, capacity: int, prefix: str | None = None) -> RoomFifo:
    """A FIFO of ``capacity`` entries whose writer sees a registered ``room`` (no path from the
    FIFO's level into the writer's enables); the caller drives ``write`` (only while ``room``) and the
    write stream's payload. Its count signals are ``{prefix}used``, ``{prefix}room``, ... (``prefix``
    default ``name_``; the one machine's load FIFO has none)."""
    prefix = f"{name}_" if prefix is None else prefix
    depth = capacity + 1  # one entry more: room is set while at most capacity - 1 are in
    m.submodules[name] = buf = fifo.SyncFIFOBuffered(width=width, depth=depth)
    used = Signal(range(depth + 1), name=f"{prefix}used")
    used_next = Signal(range(depth + 1), name=f"{prefix}used_next")
    room = Signal(name=f"{prefix}room")
    write = Signal(name=f"{prefix}write")
    read = Signal(name=f"{prefix}read")
    m.d.comb += [read.eq(buf.r_stream.valid & buf.r_stream.ready), used_next.eq(used + write - read),
                 buf.w_stream.valid.eq(write)]
    m.d.sync += [used.eq(used_next), room.eq(used_next <= depth - 2)]
    return RoomFifo(buffer=buf, room=room, write=write, read=read, used=used)


def _load_fifo(m: Module, name: str, beats: stream.Interface, load: stream.Interface, capacity: int,
               prefix: str | None = None) -> RoomFifo:
    """A word generator's load ``beats`` into a machine's ``load`` stream through a :func:`_room_fifo` of
    ``capacity`` beats (the generator sees its registered room as ``ready``); returns the FIFO."""
    f = _room_fifo(m, name, Shape.cast(load.payload.shape()).width, capacity, prefix)
    buf, room, write = f.buffer, f.room, f.write
    m.d.comb += [write.eq(beats.valid & room),
                 buf.w_stream.payload.eq(beats.payload.as_value()),
                 beats.ready.eq(room),
                 load.payload.as_value().eq(buf.r_stream.payload),
                 load.valid.eq(buf.r_stream.valid),
                 buf.r_stream.ready.eq(load.ready)]
    return f
