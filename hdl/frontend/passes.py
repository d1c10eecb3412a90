"""A model's passes on chip: every pass a word generator of its own, fed from the one feature pipeline,
each declared pass (``model.passes`` but the last: census-lr's right pass) on a machine of its own beside
the own pass's; twins in ``bayesmachine.columns`` and ``host.likelihoods``.

- :class:`PassFeeder` (one per declared pass): the feature pipeline's pixels in, the pass's pixels out,
  by its reference image (:mod:`.reference`): the left image's pixels as they are; the right image's
  with the images swapped and the reference delayed by Dmax pixels (a delay line in block RAM), so that
  when left map column x arrives the right pixel x_r = x - Dmax has every left pixel it pairs with
  (x_r .. x_r + Dmax: the word generator's delay line, read backwards); after a line's last pixel the
  feeder writes Dmax more right pixels (x_r = W4 - Dmax .. W4 - 1), each with ``flush`` = k: its lanes
  d > Dmax - k pair it with a left pixel past the last output column
  (:func:`~bayesmachine.columns.right_lanes_valid`: word 0), so each takes the next row's pixel outside
  the output region with it if one is there (that row's first Dmax + 2k pixels: its steps into the
  delay lines) and the next row starts during the flush. So a right-reference pass covers right map
  columns 0 .. W4 - 1 of every output row, in raster order, as the host's (``host.likelihoods.pass_grid``).
- :func:`split_pixels`: the pipeline's pixel goes to every pass together (a broadcast: each takes it
  when all can); to the own pass through a FIFO of Dmax + 4 + :func:`pass_lag_pixels` pixels when the model
  declares passes (its pixel at map column x may wait for another pass's MAP of x, which needs the left
  pixels up to x + Dmax and the other pass's generator and machine: the FIFO lets them pass).
- :func:`watch_passes`: each declared pass's results, as they leave its machine (the front end's
  ``<pass>_maps`` port), into its own generator's line of MAPs (its above prior) and into a FIFO of its
  MAPs (Dmax + 8 + :func:`pass_lag_pixels`: never full while the own pass waits, it holds at most the pixel
  FIFO's pixels' MAPs) for each generator whose pass column reads them (census-lr's consistency column).
- :func:`fused_shares`: the passes' parts in sharing a fused column's sums (:mod:`.shared`): census-lr's
  right pass computes the members' codes of every pair of pixels both passes compare, the own pass reads
  them; :func:`share_fused_sums` puts the memories between the two generators.
- :func:`frontend_signature`: the front end's ports, taken from its generators' (each declared once, by
  the lane builder that reads it).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from amaranth.hdl import Module, Mux, Shape, Signal, Value, unsigned
from amaranth.lib import data, fifo, memory, stream, wiring
from amaranth.lib.wiring import In

from bayesmachine.checks import as_int
from bayesmachine.hdl.signatures import pixel_stream
from bayesmachine.models import ModelParams, Pass
from bayesmachine.params import MachineParams, ParameterError

from .lanes import lanes_for
from .lanes.fused import fused_sum_bits
from .layouts import FLAGS, declared_passes, features_layout, pass_pixel_layout, pixel_features_layout
from .reference import REFERENCES, reference_of
from .shared import FusedShare, SharedSums, fused_term
from .tables import frontend_tables
from .words import WordGenerator, generator_signature, pass_params

# Pixels the own pass may fall behind the feature pipeline beyond Dmax + 4 while a declared pass's MAP
# it reads goes through that pass's generator and machine: at a few clocks a pixel (wide beats) their
# latency is tens of pixels, and a shallower FIFO makes the pipeline wait for it.
PASS_LAG_PIXELS = 128

__all__ = ["PASS_LAG_PIXELS", "PassFeeder", "all_of", "copy_fields", "feeder_in_layout", "fork",
           "frontend_signature", "fused_shares", "map_readers", "pass_lag_pixels", "pass_port",
           "pass_row_pixels", "share_fused_sums", "shared_sums_depth", "split_pixels", "watch_passes"]


def pass_lag_pixels(dmax: int) -> int:
    """Pixels the own pass may lag beyond Dmax + 4: ``PASS_LAG_PIXELS``, and at least Dmax + 4, so that
    its FIFO is never full while a right-reference pass's flush waits for the next row's pixels
    (:class:`PassFeeder`): the own pixels then waiting for the flush's MAPs (at most Dmax) and the next
    row's pixels the flush has taken (fewer than Dmax) fit."""
    return max(PASS_LAG_PIXELS, dmax + 4)


def pass_row_pixels(model: ModelParams, name: str, width: int) -> int:
    """The pixels (results) of ``model``'s pass ``name`` per map row of ``width``-pixel frames, by its
    reference (:meth:`~.reference.Reference.row_pixels`): the own pass's output pixels, W - 2k - Dmax; a
    right-reference pass's every right map column, W - 2k."""
    return reference_of(model.pass_named(name)).row_pixels(width - 2 * model.margin, model.dmax)


def pass_port(model: ModelParams, p: Pass, what: str) -> str:
    """The front end's (or the stereo top's) port ``what`` of pass ``p``: unprefixed for the model's own
    pass (``beats``, ``maps``, ``result``), ``<pass>_<what>`` for a declared one (``right_beats``)."""
    return what if p is model.passes[-1] else f"{p.name}_{what}"


def frontend_signature(params: MachineParams, model: ModelParams) -> wiring.Signature:
    """The front end's ports: ``pixels`` and per pass ``beats`` (its generator's) and, when something on
    chip reads the pass's MAPs (its own line of MAPs, another pass's pass column), ``maps``: the
    generator's, or the reading column's (:func:`pass_port` names them)."""
    sigs = {p.name: generator_signature(pass_params(model, params, p.name), model, p).members
            for p in model.passes}
    members: dict[str, wiring.Member] = {"pixels": In(pixel_stream())}
    for p in model.passes:
        members[pass_port(model, p, "beats")] = sigs[p.name]["beats"]
        readers = [sig[f"{p.name}_maps"] for sig in sigs.values() if f"{p.name}_maps" in sig]
        own = [sigs[p.name]["maps"]] if "maps" in sigs[p.name] else []
        if own or readers:
            members[pass_port(model, p, "maps")] = (own + readers)[0]
    return wiring.Signature(members)


def fork(m: Module, source: Any, sinks: Sequence[Any]) -> None:
    """One stream (``source``: ``valid``, ``ready``) into several (each ``valid``, ``ready``; the caller
    drives their payloads): a handshake when every sink is ready, each sink's ``valid`` the source's
    while all the others are ready."""
    readies = [s.ready for s in sinks]
    m.d.comb += source.ready.eq(all_of(readies))
    for i, s in enumerate(sinks):
        m.d.comb += s.valid.eq(source.valid & all_of(readies[:i] + readies[i + 1:]))


def all_of(values: Iterable[Value]) -> Value:
    """The AND of ``values`` (1 for none)."""
    out: Value = Value.cast(1)
    for v in values:
        out = out & v
    return out


def feeder_in_layout(features: data.StructLayout, flags: Mapping[str, Any]) -> data.StructLayout:
    """A pixel into :class:`PassFeeder`: both images' ``features``, ``output`` (the pixel is an output
    pixel: the own pass's), the pass's position ``flags`` and ``line_end`` (the last map column of an
    output row)."""
    return pixel_features_layout(features, {**flags, "line_end": unsigned(1)})


class PassFeeder(wiring.Component):
    """The feature pipeline's pixels in, one declared pass's pixels out, by its reference image (see the
    module text).

    The left image: one output pixel per input pixel, unchanged. The right image: for an input pixel at
    left map column x, ``left`` (the word generator's reference) = the right features of x - Dmax (a
    delay line of Dmax pixels: a circular buffer in block RAM), ``right`` (its delay line's input) = the
    left features of x, ``output`` and the flags passed on, ``flush`` 0; after an input pixel with
    ``output`` and ``line_end``, Dmax flush pixels k = 1 .. Dmax: the right features of the next
    delay-line entries, ``output`` 1, ``row_start`` 0, ``first_row`` the row's, ``flush`` k; a flush pixel
    takes an input pixel outside the output region with it when one is offered (its right features into
    the delay line, its left features as ``right``: they fill lanes past the last output column), else
    it writes 0 into both lines; once one has taken a pixel, each later one of the flush waits for one
    (no flush entry between the next row's pixels). The handshake passes through (no register on the
    valid path): ``i.ready`` is ``o.ready``, but for an output pixel while a flush is pending.

    Parameters
    ----------
    reference : str
        The pass's reference image, "left" or "right" (``Pass.reference``).
    dmax : int
        The largest disparity (0 .. 4094).
    features : StructLayout
        One image's planes (:func:`~.layouts.features_layout` of the model).
    flags : Mapping[str, Shape]
        The position flags the pass's columns read (of :data:`~.layouts.FLAGS`; a right-reference pass's
        pixels carry no ``consult``: its MAPs would be read before they exist).

    Attributes
    ----------
    i : ``In(stream.Signature(feeder_in_layout(features, flags)))``
        Every pixel of the frame, raster order.
    o : ``Out(stream.Signature(...))``
        The pass's pixels (``flags`` and its reference's: ``flush``), for its ``WordGenerator``.
    """

    def __init__(self, *, reference: str, dmax: int, features: data.StructLayout,
                 flags: Mapping[str, Any] | None = None) -> None:
        if not isinstance(reference, str):
            raise TypeError(f"reference must be an image's name (str), not {type(reference).__name__}")
        if reference not in REFERENCES:
            raise ParameterError(f"reference must be one of {', '.join(REFERENCES)}, got {reference!r}",
                                 "reference")
        dmax = as_int("dmax", dmax, 0, 4094)
        if not isinstance(features, data.StructLayout):
            raise TypeError(f"features must be a StructLayout, not {type(features).__name__}")
        flags = dict(flags or {})
        carried = [f for f in FLAGS if f != "consult" or not REFERENCES[reference].swaps]
        wrong = [f for f in flags if f not in carried]
        if wrong:
            raise ParameterError(f"flags: a {reference}-reference pass's pixels carry {', '.join(carried)}, "
                                 f"not {', '.join(wrong)}", "flags")
        self._reference, self._dmax, self._features, self._flags = reference, dmax, features, flags
        out = pixel_features_layout(features, {**flags, **REFERENCES[reference].flags(dmax)})
        super().__init__({"i": In(stream.Signature(feeder_in_layout(features, flags))),
                          "o": wiring.Out(stream.Signature(out))})

    @property
    def reference(self) -> str:
        return self._reference

    @property
    def dmax(self) -> int:
        return self._dmax

    @property
    def features(self) -> data.StructLayout:
        return self._features

    @property
    def flags(self) -> dict[str, Any]:
        return dict(self._flags)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        i, o = self.i, self.o
        if not REFERENCES[self._reference].swaps:
            m.d.comb += [o.valid.eq(i.valid), i.ready.eq(o.ready)]
            m.d.comb += [getattr(o.payload, f).eq(getattr(i.payload, f)) for f in o.payload.shape().members]
            return m
        dmax = self._dmax
        pending = Signal(range(dmax + 1))  # flush pixels still to write
        first_row = Signal()  # of the row being flushed
        flushing = pending != 0
        # A flush pixel steps the delay lines with the next row's pixel outside the output region, if
        # one is there: the row's start no longer waits for the flush (its lanes past the line are 0).
        # Once one has, every later one waits for one, so that the row's pixels sit in the lines with
        # no flush entry between them (the row's first output pixel reads the last Dmax + 1).
        absorbing = Signal()
        offered = i.valid & ~i.payload.output
        fresh = ~flushing | offered
        m.d.comb += [
            i.ready.eq(o.ready & (~flushing | ~i.payload.output)),
            o.valid.eq(Mux(flushing, ~absorbing | offered, i.valid)),
            o.payload.right.eq(Mux(fresh, i.payload.left, 0)),
            o.payload.output.eq(flushing | i.payload.output),
        ]
        if "row_start" in self._flags:
            m.d.comb += o.payload.row_start.eq(~flushing & i.payload.row_start)
        if "first_row" in self._flags:
            m.d.comb += o.payload.first_row.eq(Mux(flushing, first_row, i.payload.first_row))
        if not dmax:
            m.d.comb += o.payload.left.eq(i.payload.right)
            return m
        step = o.valid & o.ready
        m.d.comb += [o.payload.flush.eq(Mux(flushing, dmax + 1 - pending, 0)),
                     o.payload.left.eq(self._delay_line(m, step, Mux(fresh, i.payload.right, 0)))]
        with m.If(flushing & o.valid & o.ready):
            m.d.sync += [pending.eq(pending - 1), absorbing.eq((pending != 1) & (absorbing | offered))]
        with m.Elif(i.valid & i.ready & i.payload.output & i.payload.line_end):
            m.d.sync += pending.eq(dmax)
            if "first_row" in self._flags:
                m.d.sync += first_row.eq(i.payload.first_row)
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


def copy_fields(m: Module, dst: Any, pixel: Any, line_end: Value | None = None) -> None:
    """``dst``'s fields from ``pixel``'s of the same names (``line_end``, if given, from it)."""
    for f in dst.shape().members:
        given = line_end is not None and f == "line_end"
        m.d.comb += getattr(dst, f).eq(line_end if given else getattr(pixel, f))


def split_pixels(m: Module, model: ModelParams, features: Any, gens: Mapping[str, WordGenerator]) -> None:
    """The feature pipeline's pixels (``features``: a stream of :func:`~.pipeline.pipeline_layout`) to
    every pass's word generator ``gens`` (by pass name), all taking each pixel together (see the module
    text)."""
    pixel, sinks = features.payload.pixel, []
    own = model.passes[-1]
    for p in model.passes:
        gen = gens[p.name]
        if p is not own:
            flags = {f: s for f, s in pass_pixel_layout(model, p).members.items() if f in FLAGS}
            feeder = PassFeeder(reference=p.reference, dmax=model.dmax, features=features_layout(model),
                                flags=flags)
            m.submodules[f"{p.name}_feeder"] = feeder
            wiring.connect(m, feeder.o, gen.pixel)
            copy_fields(m, feeder.i.payload, pixel, features.payload.line_end)
            sinks.append(feeder.i)
        elif declared_passes(model):
            layout = gen.pixel.payload.shape()
            depth = model.dmax + 4 + pass_lag_pixels(model.dmax)
            m.submodules.own_pixels = pix = fifo.SyncFIFOBuffered(width=Shape.cast(layout).width, depth=depth)
            staged = Signal(layout)
            copy_fields(m, staged, pixel)
            m.d.comb += [pix.w_stream.payload.eq(staged), gen.pixel.valid.eq(pix.r_stream.valid),
                         gen.pixel.payload.eq(pix.r_stream.payload), pix.r_stream.ready.eq(gen.pixel.ready)]
            sinks.append(pix.w_stream)
        else:
            copy_fields(m, gen.pixel.payload, pixel)
            sinks.append(gen.pixel)
    fork(m, features, sinks)


def watch_passes(m: Module, front: Any, gens: Mapping[str, WordGenerator]) -> None:
    """Each pass's MAPs in on the front end's ``maps`` ports (:func:`frontend_signature`) to what reads
    them: its own generator's line of MAPs and, through :func:`map_readers`, every generator whose pass
    column reads them (see the module text)."""
    model = front.model
    for p in model.passes:
        name = pass_port(model, p, "maps")
        if name not in front.signature.members:
            continue
        port = getattr(front, name)
        readers = map_readers(m, model, p, gens, port.payload)
        if not readers:  # only its own line of MAPs reads them
            wiring.connect(m, wiring.flipped(port), gens[p.name].maps)
            continue
        sinks = []
        if "maps" in gens[p.name].signature.members:
            m.d.comb += gens[p.name].maps.payload.eq(port.payload)
            sinks.append(gens[p.name].maps)
        fork(m, port, sinks + readers)


def map_readers(m: Module, model: ModelParams, p: Pass, gens: Mapping[str, WordGenerator],
                maps: Value) -> list[Any]:
    """Pass ``p``'s MAPs (``maps``: a ``map_layout`` value, valid as each result leaves its machine) into a
    FIFO of Dmax + 8 + ``pass_lag_pixels`` MAPs for each generator of ``gens`` whose pass column reads them
    (submodule ``<pass>_maps_<reader>``); returns the FIFOs' write streams, for the caller's fork."""
    sinks = []
    for reader, gen in gens.items():
        if f"{p.name}_maps" not in gen.signature.members:
            continue
        sink = getattr(gen, f"{p.name}_maps")
        m.submodules[f"{p.name}_maps_{reader}"] = buf = fifo.SyncFIFOBuffered(
            width=Shape.cast(sink.payload.shape()).width, depth=model.dmax + 8 + pass_lag_pixels(model.dmax))
        m.d.comb += [buf.w_stream.payload.eq(maps), sink.valid.eq(buf.r_stream.valid),
                     sink.payload.eq(buf.r_stream.payload), buf.r_stream.ready.eq(sink.ready)]
        sinks.append(buf.w_stream)
    return sinks


def shared_sums_depth(reach: int, dmax: int) -> int:
    """Positions the shared fused sums hold (:class:`~.shared.FusedShare`'s ``depth``): enough that the
    exporter may run the own pass's whole lag ahead (Dmax + 4 + ``pass_lag_pixels`` pixels: its pixel
    FIFO) before it waits for the importer, a pixel's rows (``reach``) and Dmax + 1 beyond."""
    return 1 << (reach + 2 * dmax + 6 + pass_lag_pixels(dmax)).bit_length()


def _same_codes(model: ModelParams, params: MachineParams, a: Pass, b: Pass) -> bool:
    """Whether passes ``a`` and ``b`` give a pair of pixels the same fused sums: one fused column each, of
    one kind and values, members of symmetric costs, the same energy tables."""
    fa, fb = fused_term(a), fused_term(b)
    if fa is None or fb is None or repr(fa) != repr(fb):
        return False
    if not all(lanes_for(m).symmetric for m in fa.members):
        return False
    tables = [frontend_tables(p.model, pass_params(model, params, p.name).word_bits, params.integrator)
              for p in (a, b)]
    names = [f"{m.name}_energy" for m in fa.members] + ["nomatch_energy"]
    return all(np.array_equal(tables[0][n], tables[1][n]) for n in names)


def fused_shares(model: ModelParams, params: MachineParams) -> dict[str, FusedShare]:
    """Each pass's part in sharing its fused sums (by pass name; empty when none share): the first declared
    right-reference pass that gives the own (left-reference) pass's pairs the same sums exports them, the
    own pass imports them, when both take a pixel in as many beats of as many rows and the own pass's
    pixels carry ``row_start``."""
    own = model.passes[-1]
    if reference_of(own).swaps or "row_start" not in pass_pixel_layout(model, own).members:
        return {}
    rows = params.words_per_beat // params.loaded_columns
    for p in declared_passes(model):
        pp = pass_params(model, params, p.name)
        beats = params.beats_per_pixel
        if (not reference_of(p).swaps or fused_term(p) is None
                or (pp.words_per_beat // pp.loaded_columns, pp.beats_per_pixel) != (rows, beats)
                or not _same_codes(model, params, p, own)):
            continue
        tables = frontend_tables(own.model, params.word_bits, params.integrator)
        geometry = {"rows": rows, "beats": beats, "width": fused_sum_bits(fused_term(own), tables),
                    "dmax": model.dmax, "depth": shared_sums_depth(rows * beats - 1, model.dmax)}
        return {p.name: FusedShare(role="export", **geometry),
                own.name: FusedShare(role="import", **geometry)}
    return {}


def share_fused_sums(m: Module, gens: Mapping[str, WordGenerator]) -> None:
    """The shared fused sums (:class:`~.shared.SharedSums`, submodule ``fused_sums``) between the generators
    ``gens`` (by pass name) that have a part in them."""
    parts = {gen.fused_share.role: gen for gen in gens.values() if gen.fused_share is not None}
    if not parts:
        return
    m.submodules.fused_sums = sums = SharedSums(writer=parts["export"].fused_share,
                                                reader=parts["import"].fused_share)
    wiring.connect(m, parts["export"].fused_sums, sums.writer)
    wiring.connect(m, parts["import"].fused_sums, sums.reader)
