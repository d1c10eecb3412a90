"""census-lr on chip: the right pass's pixel stream and the consistency column's test.

The census-lr model runs a right pass (``model.pass_named("right").model``, the
census model with the right image as reference: lane d pairs right map column x_r with left map column
x_r + d) on a second machine, and the left pass multiplies in one more column, the left-right
consistency column of the right MAPs (:func:`~bayesmachine.columns.lr_consistent`,
:meth:`~bayesmachine.columns.Consistency.values_of`). Two blocks here, each with its twin in
``bayesmachine.columns.consistency``:

- :class:`RightPassFeeder`: the front end's pixel features in, the right pass's pixels out, for a
  :class:`~.words.WordGenerator` of the right pass (``pass_name="right"``). The reference (the right
  features) is delayed by Dmax pixels, so that when left map column x arrives the right pixel x_r = x -
  Dmax has every left pixel it pairs with (x_r .. x_r + Dmax: the word generator's delay line, read
  backwards). After a line's last pixel the feeder holds its input for Dmax more right pixels (x_r = W4
  - Dmax .. W4 - 1), each with ``flush`` = k: its lanes d > Dmax - k pair it with a left pixel past the
  last output column (:func:`~bayesmachine.columns.right_lanes_valid`: word 0). So the right pass covers
  right map columns 0 .. W4 - 1 of every output row, in raster order, as the host's
  (``host.likelihoods.pass_grid``).
- :class:`ConsistencyTest`: the right MAPs of one map row, shifted in column by column (column x when
  the left pass takes map column x), the last Dmax + 1 of them in a shift register, entry d =
  d_R(x - d); lane d is consistent when entry d is a MAP and ``|d_R(x - d) - d| <= tolerance`` (a
  window test against constants).
"""

from __future__ import annotations

import dataclasses

from amaranth.hdl import Cat, Const, Module, Mux, Shape, Signal, Value, unsigned
from amaranth.lib import data, fifo, memory, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.columns import RIGHT_PASS
from bayesmachine.models import ModelParams, pass_machine
from bayesmachine.params import MachineParams, stereo_words_per_beat

from .words import WordGenerator, features_layout, flush_bits, pass_pixel_layout, pixel_features_layout

__all__ = ["ConsistencyTest", "RightPassFeeder", "feeder_in_layout", "flush_bits", "lr_split",
           "pass_params", "right_map_layout", "right_pass_params"]


def _check_int(name: str, value: object, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{name} must be an integer, not {type(value).__name__}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    return value


def right_map_layout(map_width: int) -> data.StructLayout:
    """One right MAP: its row (``map``) and whether it is a disparity (``hit``: not a timeout)."""
    return data.StructLayout({"map": unsigned(map_width), "hit": unsigned(1)})


def feeder_in_layout(features: data.StructLayout) -> data.StructLayout:
    """A pixel into :class:`RightPassFeeder`: both images' ``features``, ``output`` (left map column >= Dmax
    on an output row: the right pass takes right map column x - Dmax), ``row_start`` (left map column
    Dmax: right map column 0), ``first_row`` (a frame's first output row) and ``line_end`` (the last map
    column of an output row); ``consult`` (for the left pass: a map column >= 0 of an output row)."""
    return data.StructLayout({"left": features, "right": features, "output": unsigned(1),
                              "row_start": unsigned(1), "first_row": unsigned(1), "consult": unsigned(1),
                              "line_end": unsigned(1)})


def pass_params(model: ModelParams, params: MachineParams, name: str) -> MachineParams:
    """The machine on chip of ``model``'s declared pass ``name``: :func:`~bayesmachine.models.pass_machine`
    of the own pass's ``params``, with the front end's words per beat
    (:func:`~bayesmachine.params.stereo_words_per_beat`; they change no result)."""
    machine = pass_machine(model, params, name)
    return dataclasses.replace(machine, words_per_beat=stereo_words_per_beat(machine))


def right_pass_params(model: ModelParams, params: MachineParams) -> MachineParams:
    """:func:`pass_params` of the right pass (census-lr's second machine)."""
    return pass_params(model, params, RIGHT_PASS)


def lr_split(m: Module, front: wiring.Component, gen: WordGenerator, px: Value, valid: Value,
             map_columns: int) -> Value:
    """census-lr in the :class:`~.stereo.FrontEnd`: the stage-3 pixel ``px`` (``feeder_in_layout``),
    ``valid``, goes both to the left pass's word generator ``gen``, through a FIFO of Dmax + 4 pixels
    (its pixel at map column x waits for the right MAP of x, which needs the left pixels up to x + Dmax:
    the FIFO lets them pass), and to the right pass (:class:`RightPassFeeder`, a
    ``WordGenerator(pass_name="right")`` writing ``front.right_beats``); the right results
    (``front.right_take``...) go to that generator's line of MAPs (its above prior) and into a FIFO of
    right MAPs (Dmax + 8: never full while the left pass waits, it holds at most the pixel FIFO's
    pixels' MAPs) that ``gen`` reads. Returns the ready of the stage (both take the pixel together)."""
    model, params = front.model, front.params
    rp = right_pass_params(model, params)
    left_layout = pass_pixel_layout(model, model.passes[-1])
    m.submodules.lr_pixels = pix = fifo.SyncFIFOBuffered(width=Shape.cast(left_layout).width,
                                                         depth=model.dmax + 4)
    m.submodules.lr_feeder = feeder = RightPassFeeder(dmax=model.dmax, features=features_layout(model))
    m.submodules.lr_right_generator = rgen = WordGenerator(params=rp, model=model, pass_name=RIGHT_PASS,
                                                           output_columns=map_columns)
    m.submodules.lr_right_maps = maps = fifo.SyncFIFOBuffered(width=rp.map_width + 1, depth=model.dmax + 8)
    lp = Signal(left_layout)
    m.d.comb += [getattr(lp, f).eq(getattr(px, f)) for f in left_layout.members]
    m.d.comb += [
        pix.w_stream.payload.eq(lp),
        pix.w_stream.valid.eq(valid & feeder.i.ready),
        feeder.i.valid.eq(valid & pix.w_stream.ready),
        feeder.i.payload.eq(px),
        gen.pixel.valid.eq(pix.r_stream.valid),
        gen.pixel.payload.eq(pix.r_stream.payload),
        pix.r_stream.ready.eq(gen.pixel.ready),
    ]
    wiring.connect(m, feeder.o, rgen.pixel)
    wiring.connect(m, rgen.beats, wiring.flipped(front.right_beats))
    entry = Signal(right_map_layout(rp.map_width))
    m.d.comb += [
        rgen.result_take.eq(front.right_take), rgen.result_map.eq(front.right_map),
        rgen.result_hit.eq(front.right_hit),
        entry.map.eq(front.right_map), entry.hit.eq(front.right_hit),
        maps.w_stream.payload.eq(entry), maps.w_stream.valid.eq(front.right_take),
        front.right_room.eq(maps.w_stream.ready),
        gen.right_map.valid.eq(maps.r_stream.valid), gen.right_map.payload.eq(maps.r_stream.payload),
        maps.r_stream.ready.eq(gen.right_map.ready),
    ]
    return feeder.i.ready & pix.w_stream.ready


class RightPassFeeder(wiring.Component):
    """The front end's pixel features in, the census-lr right pass's pixels out (one per input pixel,
    and Dmax more after each output row's last pixel).

    Output pixel for an input pixel at left map column x: ``left`` (the word generator's reference) =
    the right features of x - Dmax (a delay line of Dmax pixels: a circular buffer in block RAM),
    ``right`` (its delay line's input) = the left features of x, ``output``/``row_start``/``first_row``
    passed on, ``flush`` 0. After an input pixel with ``output`` and ``line_end``, Dmax flush pixels k =
    1 .. Dmax (the input is not ready meanwhile): the right features of the next delay-line entries,
    left features 0 (they fill lanes past the last output column), ``output`` 1, ``flush`` k. The
    handshake passes through (no register on the valid path): ``i.ready`` is ``o.ready`` while no flush
    is pending.

    Parameters
    ----------
    dmax : int
        The largest disparity (0 .. 4094).
    features : StructLayout
        One image's planes (:func:`~.words.features_layout` of the model).

    Attributes
    ----------
    i : ``In(stream.Signature(feeder_in_layout(features)))``
        Every pixel of the frame, raster order.
    o : ``Out(stream.Signature(...))``
        The right pass's pixels (``row_start``, ``first_row``, ``flush`` flags), for
        ``WordGenerator(..., pass_name="right")``.
    """

    def __init__(self, *, dmax: int, features: data.StructLayout) -> None:
        self._dmax = _check_int("dmax", dmax, 0, 4094)
        if not isinstance(features, data.StructLayout):
            raise TypeError(f"features must be a StructLayout, not {type(features).__name__}")
        self._features = features
        super().__init__({
            "i": In(stream.Signature(feeder_in_layout(features))),
            "o": Out(stream.Signature(pixel_features_layout(features, {
                "row_start": unsigned(1), "first_row": unsigned(1), "flush": unsigned(flush_bits(dmax))}))),
        })

    @property
    def dmax(self) -> int:
        return self._dmax

    @property
    def features(self) -> data.StructLayout:
        return self._features

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dmax = self._dmax
        i, o = self.i, self.o
        pending = Signal(range(dmax + 1))  # flush pixels still to write
        first_row = Signal()  # of the row being flushed
        flushing = pending != 0
        m.d.comb += [
            i.ready.eq(~flushing & o.ready),
            o.valid.eq(Mux(flushing, 1, i.valid)),
            o.payload.right.eq(Mux(flushing, 0, i.payload.left)),
            o.payload.output.eq(flushing | i.payload.output),
            o.payload.row_start.eq(~flushing & i.payload.row_start),
            o.payload.first_row.eq(Mux(flushing, first_row, i.payload.first_row)),
        ]
        if not dmax:
            m.d.comb += o.payload.left.eq(i.payload.right)
            return m
        step = o.valid & o.ready
        m.d.comb += [o.payload.flush.eq(Mux(flushing, dmax + 1 - pending, 0)),
                     o.payload.left.eq(self._delay_line(m, step, Mux(flushing, 0, i.payload.right)))]
        with m.If(flushing & o.ready):
            m.d.sync += pending.eq(pending - 1)
        with m.Elif(i.valid & i.ready & i.payload.output & i.payload.line_end):
            m.d.sync += [pending.eq(dmax), first_row.eq(i.payload.first_row)]
        return m

    def _delay_line(self, m: Module, step: Value, value: Value) -> Value:
        """``value`` of Dmax steps back: a circular buffer of Dmax entries (block RAM), written at
        ``head`` on each step and read one step ahead at the entry after it, so its output register
        holds entry ``head`` (the oldest) between steps. Uninitialized entries: an output pixel is at
        least Dmax pixels into its line, so none reads an entry of an earlier line or frame."""
        dmax = self._dmax
        m.submodules.line = line = memory.Memory(shape=self._features, depth=dmax, init=[])
        write = line.write_port()
        # With one entry the step reads the entry it writes: the new value (write-through).
        read = line.read_port(transparent_for=(write,) if dmax == 1 else ())
        head = Signal(range(dmax))
        after = Signal(range(dmax), init=1 % dmax)  # head + 1 modulo Dmax
        m.d.comb += [write.addr.eq(head), write.data.eq(value), write.en.eq(step),
                     read.addr.eq(after), read.en.eq(step)]
        with m.If(step):
            m.d.sync += [head.eq(after), after.eq(Mux(after == dmax - 1, 0, after + 1))]
        return read.data


class ConsistencyTest(wiring.Component):
    """The left pass's view of the right MAPs: entry d = d_R(x - d), and each lane's window test.

    Parameters
    ----------
    dmax : int
        The largest disparity (0 .. 4094).
    map_width : int
        Bits of a MAP (the right machine's ``map_width``).
    tolerance : int
        The window's half-width (``ModelParams.lr_tolerance``).

    Attributes
    ----------
    shift : ``In(1)``
        Shift ``entry`` in (as entry 0; entry d moves to d + 1).
    entry : ``In(right_map_layout(map_width))``
        The right MAP of the next map column.
    consistent : ``Out(dmax + 1)``
        Bit d: entry d is a disparity and ``|entry d - d| <= tolerance`` (combinational from the
        shift register).
    any : ``Out(1)``
        Some lane is consistent.
    unknown : ``Out(dmax + 1)``
        Bit d: entry d is no MAP (the right pass's no match or timeout: with ``lr_neutral`` the lane
        is neutral; twin :func:`~bayesmachine.columns.lr_unknown`).
    """

    def __init__(self, *, dmax: int, map_width: int, tolerance: int) -> None:
        self._dmax = _check_int("dmax", dmax, 0, 4094)
        self._map_width = _check_int("map_width", map_width, 1, 16)
        self._tolerance = _check_int("tolerance", tolerance, 0, 4094)
        super().__init__({
            "shift": In(1),
            "entry": In(right_map_layout(map_width)),
            "consistent": Out(dmax + 1),
            "any": Out(1),
            "unknown": Out(dmax + 1),
        })

    @property
    def dmax(self) -> int:
        return self._dmax

    @property
    def map_width(self) -> int:
        return self._map_width

    @property
    def tolerance(self) -> int:
        return self._tolerance

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dmax, t = self._dmax, self._tolerance
        layout = right_map_layout(self._map_width)
        # Reset: no MAP (a frame's first left pixels read entries of the row's own right pass only).
        line = [Signal(layout, name=f"right_map_{d}") for d in range(dmax + 1)]
        with m.If(self.shift):
            m.d.sync += line[0].eq(self.entry)
            m.d.sync += [line[d].eq(line[d - 1]) for d in range(1, dmax + 1)]
        bits = []
        for d, e in enumerate(line):
            # |map - d| <= t as two comparisons against constants (no subtractor), each left out where
            # the MAP's range makes it always true (verilator -Wall: no constant comparison).
            inside = Const(1)
            if d + t < (1 << self._map_width) - 1:
                inside = inside & (e.map <= d + t)
            if d - t > 0:
                inside = inside & (e.map >= d - t)
            bits.append(e.hit & inside)
        m.d.comb += [self.consistent.eq(Cat(*bits)), self.any.eq(Cat(*bits).any()),
                     self.unknown.eq(~Cat(*(e.hit for e in line)))]
        return m
