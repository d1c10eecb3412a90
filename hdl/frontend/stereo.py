"""``FrontEnd`` (pixel pairs in, every pass's load beats out) and ``StereoMachine`` (pixels in, disparity
results out): the pipeline from a camera to the MAP, on chip.

Pixel stream: one ``pixel_in_layout()`` beat per pixel pair (``left``, ``right``: 8-bit gray;
``first``: set on the first pixel of a frame), frames in raster order, ``width`` pixels per line,
any number of lines (at least 2k + 1, k = ``model.margin``). The front end's position counters
restart at every ``first`` (and at reset), so a frame may follow another immediately: nothing
computed for a frame depends on pixels of an earlier one. The output region is the host's
(``bayesmachine.region``: every window of the model inside the image): map rows 0..H-2k-1 (image lines
2k..H-1, a window's bottom line) and map columns Dmax..W-2k-1 (image columns Dmax+2k..W-1, a
window's right column); every other pixel passes in one cycle and starts no machine run.

Pipeline (one pixel per cycle when no output pixel holds it): the feature pipeline
(:mod:`.pipeline`: stages 0 to 3), then each pass's word generator (:mod:`.words`; a declared pass's
through its feeder, :mod:`.passes`), which for an output pixel writes ``beats_per_pixel`` beats into a
FIFO in front of its machine's load stream.

The FIFO (``fifo_pixels`` pixels of beats, block RAM) lets the front end run ahead while the
machine's runs are long and the line ends' non-output pixels stream in; when it is full,
back-pressure reaches the pixel input. The own pass's FIFO's ready toward the word generator is a
register (set while at most all but one entry is used; the FIFO has one entry more than the pixels'
beats), so no path runs from its level through the pixel take. Results leave in raster order of the
output region, on the machine's own result stream, and each declared pass's on ``<pass>_result``. A
pass whose MAPs something on chip reads (its above neighbour's line of MAPs, another pass's column)
hands each result, as it leaves, back to the front end (``maps``, ``<pass>_maps``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

from amaranth.hdl import Array, Module, Mux, Shape, Signal, Value
from amaranth.lib import data, fifo, stream, wiring
from amaranth.lib.wiring import In

from bayesmachine.checks import as_int
from bayesmachine.columns import Source
from bayesmachine.hdl.machines import machine_top
from bayesmachine.hdl.signatures import (
    ENTROPY_PORTS,
    StereoSignature,
    load_layout,
    map_layout,
    pixel_in_layout,
    result_layout,
)
from bayesmachine.models import DEFAULT_MODEL, ModelParams, disparity_machine
from bayesmachine.params import DEFAULT_DMAX, MachineParams, ParameterError, stereo_words_per_beat

from . import DEFAULT_FIFO_PIXELS, MAX_MACHINES, MAX_WIDTH
from .lanes import lanes_for
from .layouts import declared_passes
from .passes import (
    all_of,
    copy_fields,
    fork,
    frontend_signature,
    fused_shares,
    map_readers,
    pass_port,
    pass_row_pixels,
    share_fused_sums,
    split_pixels,
    watch_passes,
)
from .pipeline import FeaturePipeline, PipelineNets, check_width, pipeline_layout
from .words import WordGenerator, check_frontend_params, check_frontend_types, pass_params

__all__ = ["MAX_MACHINES", "MAX_WIDTH", "FeaturePipeline", "FrontEnd", "PipelineNets", "RoomFifo",
           "StereoMachine", "StereoNets", "check_machines", "pass_generators",
           "check_stereo_machine", "pipeline_layout", "pixel_in_layout", "stereo_machine_params",
           "stereo_signature"]


def stereo_machine_params(dmax: int = DEFAULT_DMAX, *, model: ModelParams | None = None,
                          **kwargs: object) -> MachineParams:
    """The machine the front end feeds: ``disparity_machine(model, ...)`` (``model``'s Dmax is ``dmax``;
    without one, :data:`~bayesmachine.models.DEFAULT_MODEL` at ``dmax``, as every command), with the
    front end's lane count (:func:`stereo_words_per_beat`) unless ``words_per_beat`` is given."""
    if model is None:
        model = ModelParams(name=DEFAULT_MODEL, dmax=dmax)
    elif model.dmax != dmax:
        raise ParameterError(f"dmax: {dmax} given, the model's is {model.dmax}", "dmax")
    params = disparity_machine(model, **kwargs)
    return params if "words_per_beat" in kwargs else dataclasses.replace(params,
                                                                         words_per_beat=stereo_words_per_beat(params))


def check_machines(machines: object, params: MachineParams, model: ModelParams) -> int:
    """``machines`` if a ``StereoMachine`` can have that many machines (per pass): an integer (``TypeError``
    otherwise) in [1, MAX_MACHINES], more than one only for an on-chip random source (off chip, each
    machine would need its own number port and device stream), else ``ParameterError`` naming the
    parameter."""
    machines = as_int("machines", machines)
    if not 1 <= machines <= MAX_MACHINES:
        raise ParameterError(f"machines must be in [1, {MAX_MACHINES}], got {machines}", "machines")
    undealt = [c.name for p in model.passes for c in p.columns if not lanes_for(c).dealt(c)]
    if machines > 1 and undealt:
        raise ParameterError(f"machines = {machines}: the {model.name} model's {undealt[0]} column continues "
                             "from the row above on one machine (its paths' costs); it runs on 1 machine a "
                             "pass (census-lr's rows are dealt to several)", "machines")
    if machines > 1 and params.takes_numbers:
        raise ParameterError(f"machines = {machines}: rng {params.rng!r} is off chip (one number port, "
                             "one device stream); several machines need an on-chip source "
                             "(sobol, lfsr, lfsr-shared)", "machines")
    return machines


def stereo_signature(params: MachineParams, model: ModelParams) -> StereoSignature:
    """:class:`StereoMachine`'s ports: :class:`~bayesmachine.hdl.signatures.StereoSignature` of ``params``
    and of each declared pass's machine (:func:`~.words.pass_params`): its results on ``<pass>_result``."""
    return StereoSignature(params, {p.name: pass_params(model, params, p.name)
                                    for p in declared_passes(model)})


def check_stereo_machine(params: MachineParams, model: ModelParams, width: int,
                         fifo_pixels: int = DEFAULT_FIFO_PIXELS, machines: int = 1) -> None:
    """``ParameterError`` naming the parameter unless ``StereoMachine(params=params, model=model,
    width=width, fifo_pixels=fifo_pixels, machines=machines)`` can be built (callers check before
    building anything: a component whose constructor fails would be reported as never elaborated);
    ``TypeError`` for a parameter of the wrong type."""
    check_frontend_types(params, model)
    check_machines(machines, params, model)
    check_frontend_params(params, model)
    check_width(width, model)
    as_int("fifo_pixels", fifo_pixels, 1, 64)


RESULT_FIFO_MAX = 511  # results buffered per machine of several (one DP16KD deep at 36 bits wide)


class FrontEnd(wiring.Component):
    """Pixel pairs in, every pass's output pixels' likelihood-memory words out (its machine's load beats).

    Parameters
    ----------
    params : MachineParams
        The own pass's machine (see :func:`~.words.check_frontend_params`).
    model : ModelParams
        The disparity model.
    width : int
        Pixels per image line (dmax + 2·margin + 1 .. ``MAX_WIDTH``).

    Attributes
    ----------
    pixels : ``In(pixel_stream())``
        Pixel pairs in raster order.
    beats : ``Out(load_stream(params))``
        The own pass's output pixels' load beats.
    maps : ``In(map_stream(params))``
        With an above neighbour's column only: the own machine's MAPs as its results leave, into the
        word generator's line of MAPs (``ready``: the line has room).
    <pass>_beats, <pass>_maps
        Per declared pass (census-lr's ``right``): its load beats, and its machine's MAPs as they leave
        (``ready`` while its line of MAPs and the FIFO of its MAPs the own pass reads have room).
        See :mod:`.passes`; the ports are the word generators' (:func:`~.passes.frontend_signature`).
    feature_pipeline : type
        Class attribute: the :class:`FeaturePipeline` class :meth:`elaborate` builds (a subclass may
        name another with the same constructor: a formal mutant's).
    """

    feature_pipeline: type[FeaturePipeline] = FeaturePipeline

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int) -> None:
        check_frontend_types(params, model)
        check_frontend_params(params, model)
        self._width = check_width(width, model)
        self._params = params
        self._model = model
        super().__init__(frontend_signature(params, model))

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
        m.submodules.pipeline = pipe = self.feature_pipeline(model=model, width=self._width)
        wiring.connect(m, wiring.flipped(self.pixels), pipe.pixels)
        gens = pass_generators(m, model, self._params, self._width)
        for p in model.passes:
            wiring.connect(m, gens[p.name].beats, wiring.flipped(getattr(self, pass_port(model, p, "beats"))))
        split_pixels(m, model, pipe.features, gens)
        watch_passes(m, self, gens)
        return m


def pass_generators(m: Module, model: ModelParams, params: MachineParams, width: int, leads: bool = True,
                    suffix: str = "") -> dict[str, WordGenerator]:
    """Every pass's word generator (submodule ``<generator port><suffix>``: ``generator``,
    ``right_generator``), by pass name, for ``width``-pixel lines (``leads``: their machines run a frame's
    first map row, see ``WordGenerator``), and the fused sums they share
    (:func:`~.passes.share_fused_sums`)."""
    gens = {}
    shares = fused_shares(model, params)
    for p in model.passes:
        row = pass_row_pixels(model, p.name, width)  # the length of its line of MAPs
        gens[p.name] = m.submodules[f"{pass_port(model, p, 'generator')}{suffix}"] = WordGenerator(
            params=pass_params(model, params, p.name), model=model,
            pass_name=None if p is model.passes[-1] else p.name, leads=leads,
            output_columns=row if _needs_row(p) else None, fused_share=shares.get(p.name))
    share_fused_sums(m, gens)
    return gens


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
    """The blocks of :class:`StereoMachine` a proof watches (what ``StereoMachine.build`` returns beside
    its module: the formal wrappers of ``hdl.formal`` and their mutants read them, never Amaranth's
    internals)."""

    frontend: FrontEnd | FeaturePipeline  # one machine: the front end; several: the one feature pipeline
    machines: list[wiring.Component]  # the own pass's machines (BayesianMachine or LogMachine: the
    # integrator's; machine j runs map rows j mod K)
    loads: list[RoomFifo]  # machine j's load FIFO: its word generator's beats


def _needs_row(p: Any) -> bool:
    """Whether pass ``p``'s word generator needs its output pixels per row (``Lanes.needs_row``)."""
    return any(lanes_for(c).needs_row(c) for c in p.columns)


def _has_line(p: Any) -> bool:
    """Whether pass ``p`` has a line of its own MAPs (an above neighbour's column)."""
    return any(c.source is Source.ABOVE for c in p.columns)


def _watched(m: Module, maps: Any, result: Any) -> None:
    """A result's MAP as the front end reads it (``map_layout``): its row, and whether it is a disparity."""
    m.d.comb += [maps.map.eq(result.map), maps.hit.eq(~result.nomatch & ~result.timeout)]


class StereoMachine(wiring.Component):
    """Pixel pairs in, one result per output pixel out: the front end, a FIFO and the machine (and one of
    each per declared pass).

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (``words_per_beat`` a multiple of the loaded columns: see
        :func:`stereo_machine_params`); its ``integrator`` picks every machine
        (:func:`~bayesmachine.hdl.machines.machine_top`: a ``BayesianMachine``, or a ``LogMachine`` fed
        its columns' energy codes).
    model : ModelParams
        The disparity model (its columns, its passes).
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
    The ports are :func:`stereo_signature` (:class:`~bayesmachine.hdl.signatures.StereoSignature`):

    pixels : ``In(pixel_stream())``
        Pixel pairs in raster order, ``first`` on a frame's first pixel.
    result : ``Out(result_stream(params))``
        The machine's results, in raster order of the output region.
    entropy, entropy_ready
        With an off-chip ``rng`` ("external", "smtj"): the machine's own ports, passed through
        (the numbers of every compute cycle come from outside, as for the machine alone).
    <pass>_result : ``Out(result_stream(pass_params(model, params, pass)))``
        Each declared pass's results (census-lr: ``right_result``), raster order of its columns; a
        stalled one stalls its machine (and, through the MAPs it hands the front end, the own pass).
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int,
                 fifo_pixels: int = DEFAULT_FIFO_PIXELS, machines: int = 1) -> None:
        check_stereo_machine(params, model, width, fifo_pixels, machines)
        self._params = params
        self._model = model
        # Plain ints (a NumPy integer is taken as everywhere), their values checked above.
        self._width, self._fifo_pixels, self._machines = (as_int(name, value) for name, value in (
            ("width", width), ("fifo_pixels", fifo_pixels), ("machines", machines)))
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

    def elaborate(self, platform: object) -> Module:
        return self.build(platform)[0]

    def build(self, platform: object) -> tuple[Module, StereoNets]:
        """The top's module (what :meth:`elaborate` gives) and the blocks a proof watches."""
        if self._machines > 1:
            return self._build_machines()
        m = Module()
        model = self._model
        m.submodules.frontend = front = FrontEnd(params=self._params, model=model, width=self._width)
        wiring.connect(m, wiring.flipped(self.pixels), front.pixels)
        for p in model.passes:
            pp = pass_params(model, self._params, p.name)
            machine = machine_top(pp)  # the integrator's machine
            m.submodules[pass_port(model, p, "machine")] = machine
            beats = getattr(front, pass_port(model, p, "beats"))
            capacity = self._fifo_pixels * pp.beats_per_pixel
            if p is model.passes[-1]:
                # The front end sees the FIFO's registered room, so no path runs from the FIFO's level
                # through the pixel take into the front end's thousands of enables (see "Back-pressure"
                # in docs/frontend.md).
                load = _load_fifo(m, "fifo", beats, machine.load, capacity, prefix="")
                nets = StereoNets(frontend=front, machines=[machine], loads=[load])
                self._entropy(m, machine)
            else:
                m.submodules[f"{p.name}_fifo"] = buf = fifo.SyncFIFOBuffered(
                    width=Shape.cast(load_layout(pp)).width, depth=capacity + 1)
                wiring.connect(m, beats, buf.w_stream)
                wiring.connect(m, buf.r_stream, machine.load)
            self._results(m, front, p, machine.result)
        return m, nets

    def _results(self, m: Module, front: FrontEnd, p: Any, res: Any) -> None:
        """Pass ``p``'s results out on its port and, when the front end reads its MAPs, into the front end
        too (each result leaves when both take it)."""
        out = getattr(self, pass_port(self._model, p, "result"))
        name = pass_port(self._model, p, "maps")
        if name not in front.signature.members:
            wiring.connect(m, res, wiring.flipped(out))
            return
        maps = getattr(front, name)
        m.d.comb += out.payload.eq(res.payload)
        _watched(m, maps.payload, res.payload)
        fork(m, res, [out, maps])

    def _entropy(self, m: Module, machine: wiring.Component) -> None:
        """An off-chip source's ports: the machine's and this top's come from the same
        ``entropy_members(params)``, so they exist together."""
        for name in ENTROPY_PORTS:
            if name in self.signature.members:
                inner, outer = getattr(machine, name), getattr(self, name)
                flow = self.signature.members[name].flow
                m.d.comb += inner.eq(outer) if flow == In else outer.eq(inner)

    def _build_machines(self) -> tuple[Module, StereoNets]:
        """K machines per pass: one feature pipeline; a dealer sends the pixels of map row r to lane r mod
        K (a line FIFO, then every pass's word generator, beats FIFO, machine and result FIFO); each
        pass's results leave lane by lane, a map row at a time, in the order the rows were dealt."""
        m = Module()
        m.submodules.frontend = pipe = FeaturePipeline(model=self._model, width=self._width)
        wiring.connect(m, wiring.flipped(self.pixels), pipe.pixels)
        idle = Signal(init=1)  # registered: no row in flight in any pass
        rows, lines, frame_reset = self._deal(m, pipe.features, idle)
        lanes = [self._lane(m, j, lines[j], frame_reset) for j in range(self._machines)]
        self._neighbours(m, lanes)
        self._merge(m, rows, [lane.results for lane in lanes], idle)
        own = self._model.passes[-1].name
        return m, StereoNets(frontend=pipe, machines=[lane.machines[own] for lane in lanes],
                             loads=[lane.loads[own] for lane in lanes])

    def _deal(self, m: Module, fx: Any, idle: Value) -> tuple[dict[str, RoomFifo], list[RoomFifo], Value]:
        """The dealer: a map row's pixels go to its lane's line FIFO (a line's worth: the filters move on
        to the next rows while the machines work through this one); other lines' pixels (the first 2k, the
        frame's top) are dropped. Returns, per pass, the FIFO of the rows in flight (each dealt row's lane,
        in dealing order), the line FIFOs and the frame reset (a frame's first pixel taken)."""
        k, w = self._machines, fx.payload
        rows = {p.name: _room_fifo(m, pass_port(self._model, p, "rows"), Shape.cast(range(k)).width,
                                   4 * k + 4) for p in self._model.passes}
        lane = Signal(range(k))  # the lane of the current map row
        new_row = w.output_line & w.line_begin
        following = Mux(w.first_line | (lane == k - 1), 0, lane + 1)
        target = Mux(w.line_begin, following, lane)
        lines = [_room_fifo(m, f"line{j}", Shape.cast(_lane_layout(self._model)).width, self._width)
                 for j in range(k)]
        fits = Array(f.room for f in lines)[target] & (~new_row | all_of(r.room for r in rows.values()))
        # Neighbour prior: a frame's first pixel waits until every machine is idle, then the word
        # generators' counts of results above restart (rows of two frames never share a line of MAPs).
        hold = w.frame_begin & ~idle if any(map(_has_line, self._model.passes)) else Value.cast(0)
        m.d.comb += fx.ready.eq(~hold & (~w.output_line | fits))
        take = fx.valid & fx.ready
        staged = Signal(_lane_layout(self._model))
        copy_fields(m, staged, w)
        for j, f in enumerate(lines):
            m.d.comb += [f.write.eq(take & w.output_line & (target == j)),
                         f.buffer.w_stream.payload.eq(staged)]
        for r in rows.values():
            m.d.comb += [r.write.eq(take & new_row), r.buffer.w_stream.payload.eq(target)]
        with m.If(take & new_row):
            m.d.sync += lane.eq(following)
        return rows, lines, take & w.frame_begin

    def _lane(self, m: Module, j: int, line: RoomFifo, frame_reset: Value) -> _Lane:
        """Lane j (submodule ``lane<j>``): from its line FIFO, every pass's word generator (a declared
        pass's through its feeder, as in :class:`FrontEnd`), beats FIFO, machine and result FIFO (a map
        row's results wait there while the rows dealt before it leave: a row's worth, at most 511, one
        block RAM deep in its 36-bit-wide mode; a longer row's machine may wait for the row before it);
        each pass's MAPs to the generators of this lane that read them."""
        model = self._model
        m.submodules[f"lane{j}"] = lm = Module()
        lane = _Lane(gens=pass_generators(lm, model, self._params, self._width, leads=j == 0, suffix=str(j)))
        for p in model.passes:
            if _has_line(p):
                lm.d.comb += lane.gens[p.name].frame_reset.eq(frame_reset)
        features = stream.Signature(_lane_layout(model)).create()
        buf = line.buffer.r_stream
        lm.d.comb += [features.valid.eq(buf.valid), features.payload.eq(buf.payload),
                      buf.ready.eq(features.ready)]
        split_pixels(lm, model, features, lane.gens)
        for p in model.passes:
            pp, name = pass_params(model, self._params, p.name), _prefix(model, p)
            lm.submodules[f"{pass_port(model, p, 'machine')}{j}"] = machine = machine_top(pp)
            lane.machines[p.name] = machine
            lane.loads[p.name] = _load_fifo(lm, f"{name}beats{j}", lane.gens[p.name].beats, machine.load,
                                            self._fifo_pixels * pp.beats_per_pixel)
            row = pass_row_pixels(model, p.name, self._width)
            lane.results[p.name] = _room_fifo(lm, f"{name}results{j}", Shape.cast(result_layout(pp)).width,
                                              min(row, RESULT_FIFO_MAX))
            lane.maps[p.name] = watched = Signal(map_layout(pp.map_width), name=f"{name}watched{j}")
            _watched(lm, watched, machine.result.payload)
            lane.readers[p.name] = map_readers(lm, model, p, lane.gens, watched)
        return lane

    def _neighbours(self, m: Module, lanes: list[_Lane]) -> None:
        """Each pass's results as they leave machine j: into its result FIFO, into the line of MAPs of lane
        (j + 1) mod K's generator of the pass (the rows below its own) when the pass has an above
        neighbour's column, and into the FIFOs of lane j's generators that read them."""
        k = self._machines
        for j, lane in enumerate(lanes):
            for p in self._model.passes:
                res, f = lane.machines[p.name].result, lane.results[p.name]
                into = SimpleNamespace(valid=Signal(name=f"{_prefix(self._model, p)}results{j}_valid"),
                                       ready=f.room)
                m.d.comb += [f.write.eq(into.valid & f.room),
                             f.buffer.w_stream.payload.eq(res.payload.as_value())]
                sinks = [into]
                if _has_line(p):
                    below = lanes[(j + 1) % k].gens[p.name]
                    m.d.comb += below.maps.payload.eq(lane.maps[p.name])
                    sinks.append(below.maps)
                fork(m, res, sinks + lane.readers[p.name])

    def _merge(self, m: Module, rows: dict[str, RoomFifo], results: list[dict[str, RoomFifo]],
               idle: Signal) -> None:
        """The merge, per pass: a map row's results from its lane, rows in dealing order (raster order) on
        the pass's result port; ``idle`` (registered): no row in flight in any pass."""
        opens = []
        for p in self._model.passes:
            wo = pass_row_pixels(self._model, p.name, self._width)
            name = _prefix(self._model, p)
            col = Signal(range(wo), name=f"{name}merge_col")
            rows_open = Signal(range(4 * self._machines + 6), name=f"{name}rows_open")
            head = rows[p.name].buffer.r_stream  # the lane of the row leaving
            out = getattr(self, pass_port(self._model, p, "result"))
            lane = [r[p.name].buffer.r_stream for r in results]
            m.d.comb += [out.valid.eq(head.valid & Array(r.valid for r in lane)[head.payload]),
                         out.payload.as_value().eq(Array(r.payload for r in lane)[head.payload])]
            sent = out.valid & out.ready
            for j, r in enumerate(lane):
                m.d.comb += r.ready.eq(head.valid & (head.payload == j) & out.ready)
            row_done = sent & (col == wo - 1)
            m.d.comb += head.ready.eq(row_done)
            with m.If(sent):
                m.d.sync += col.eq(Mux(col == wo - 1, 0, col + 1))
            open_next = Signal.like(rows_open, name=f"{name}rows_open_next")
            m.d.comb += open_next.eq(rows_open + rows[p.name].write - row_done)
            m.d.sync += rows_open.eq(open_next)
            opens.append(open_next == 0)
        m.d.sync += idle.eq(all_of(opens))


@dataclass
class _Lane:
    """One lane of several machines (:meth:`StereoMachine._lane`), its blocks by pass name."""

    gens: dict[str, WordGenerator] = field(default_factory=dict)
    machines: dict[str, wiring.Component] = field(default_factory=dict)
    loads: dict[str, RoomFifo] = field(default_factory=dict)
    results: dict[str, RoomFifo] = field(default_factory=dict)
    maps: dict[str, Signal] = field(default_factory=dict)  # each result's MAP as its readers see it
    readers: dict[str, list[Any]] = field(default_factory=dict)  # the FIFOs into this lane's readers


def _prefix(model: ModelParams, p: Any) -> str:
    """The prefix of pass ``p``'s blocks' names among several machines: none for the own pass (``beats0``),
    ``<pass>_`` for a declared one (``right_beats0``), as :func:`~.passes.pass_port`."""
    return pass_port(model, p, "")


def _lane_layout(model: ModelParams) -> data.StructLayout:
    """What a lane's line FIFO holds of a pipeline pixel (:func:`~.pipeline.pipeline_layout`): its
    ``pixel`` and, with declared passes, ``line_end`` (for their feeders: :func:`~.passes.split_pixels`)."""
    fields = pipeline_layout(model).members
    return data.StructLayout({f: fields[f] for f in ("pixel", "line_end") if f in fields})


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
