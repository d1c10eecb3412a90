# amaranth: UnusedElaboratable=no
"""Properties of the on-chip front end, stated on its interfaces: the pixel stream in, the load
beats out (``WordGenerator``, ``FrontEnd``), and the FIFO between the front end and the machine
inside ``StereoMachine`` (its write and read streams and the beat count it keeps).

- ``GeneratorProperties``: the word generator writes exactly ``beats_per_pixel`` beats per pixel
  flagged ``output``, none for the others, and lets no beat wait once its stream is free.
- ``FrontEndProperties``: a reference position counter, restarted by every ``first`` marker, says
  which pixels taken are output pixels (image lines 4.. and columns Dmax + 4..); the front end writes
  exactly ``beats_per_pixel`` beats for each of them (so a frame start restarts it cleanly,
  whatever came before), and none for the others.
- ``FifoProperties``: the FIFO never overflows (no beat written while it is full: the registered
  ready) nor underflows (no beat read that was not written), and the count ``StereoMachine`` keeps is
  its true level.

Every input is free (pixels, ``first``, the beats' ``ready``, the machine's numbers, the reset); the
pixel source follows the stream rule.
"""

from __future__ import annotations

from amaranth.hdl import Assert, Assume, Cover, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.frontend.layouts import pixel_features_layout
from bayesmachine.hdl.frontend.linebuffer import WINDOW
from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine
from bayesmachine.hdl.frontend.words import WordGenerator
from bayesmachine.hdl.signatures import entropy_layout, pixel_in_layout, result_layout
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams

__all__ = ["FifoProperties", "FrontEndProperties", "GeneratorProperties", "GENERATOR_LATENCY"]

GENERATOR_LATENCY = 3  # the word generator's issue -> difference -> address -> beat on the stream


def _stream_rule(m: Module, valid: Signal, payload: Signal, ready: Signal) -> None:
    """Assume the source of a stream holds ``valid`` and its payload until ``ready``."""
    stall = Signal()
    prev = Signal.like(payload)
    m.d.sync += [stall.eq(valid & ~ready), prev.eq(payload)]
    with m.If(stall):
        m.d.comb += Assume(valid & (payload.as_value() == prev.as_value()))


def _beats_owed(m: Module, bpp: int, output_taken: Signal, beat_taken: Signal, ready: Signal,
                drain: int) -> Signal:
    """The beats the block still owes (``bpp`` per output pixel taken, less the beats handed over),
    asserted never negative (no beat more than bpp per output pixel) and zero after ``drain``
    cycles in a row with the beat stream ready and no output pixel taken (no beat fewer, none
    waiting). Returns the count."""
    owed = Signal(range(-4 * bpp - 8, 4 * bpp + 8))
    m.d.sync += owed.eq(owed + Mux(output_taken, bpp, 0) - beat_taken)
    m.d.comb += Assert(owed >= 0, "no beat more than beats_per_pixel per output pixel")
    m.d.comb += Assert(~(beat_taken & (owed == 0)), "no beat without an output pixel")
    quiet = Signal(range(drain + 1))
    with m.If(output_taken | ~ready):
        m.d.sync += quiet.eq(0)
    with m.Elif(quiet != drain):
        m.d.sync += quiet.eq(quiet + 1)
    m.d.comb += Assert((quiet != drain) | (owed == 0),
                       "every output pixel's beats are all handed over (none fewer, none held)")
    return owed


class GeneratorProperties(wiring.Component):
    """A formal-only wrapper: a word generator with a free pixel stream and a free beat ``ready``.

    Parameters
    ----------
    params : MachineParams
        The machine fed.
    model : ModelParams
        The disparity model.
    generator : callable
        Builds the generator from ``params`` and ``model`` keywords; ``WordGenerator`` unless a mutant
        is being checked.

    Attributes
    ----------
    pixel_valid, pixel_payload, beats_ready : ``In``
        The environment (free; the pixel source follows the stream rule).
    beats_valid : ``Out(1)``
        The generator's beat stream, for the trace.
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, generator: type = WordGenerator) -> None:
        self._params = params
        self._dut = generator(params=params, model=model)
        super().__init__({"pixel_valid": In(1), "pixel_payload": In(pixel_features_layout()),
                          "beats_ready": In(1), "beats_valid": Out(1)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.dut = dut = self._dut
        bpp = self._params.beats_per_pixel
        m.d.comb += [dut.pixel.valid.eq(self.pixel_valid), dut.pixel.payload.eq(self.pixel_payload),
                     dut.beats.ready.eq(self.beats_ready), self.beats_valid.eq(dut.beats.valid)]
        _stream_rule(m, self.pixel_valid, self.pixel_payload, dut.pixel.ready)
        taken = dut.pixel.valid & dut.pixel.ready
        out_taken = taken & self.pixel_payload.output
        beat = dut.beats.valid & dut.beats.ready
        _beats_owed(m, bpp, out_taken, beat, self.beats_ready, bpp + GENERATOR_LATENCY)
        # Not vacuous: two output pixels back to back with all their beats out, and a non-output
        # pixel passing while none is owed.
        beats = Signal(range(2 * bpp + 2))
        with m.If(beat & (beats != 2 * bpp + 1)):
            m.d.sync += beats.eq(beats + 1)
        m.d.comb += Cover(beats == 2 * bpp)
        m.d.comb += Cover(taken & ~self.pixel_payload.output & (beats == bpp))
        return m


class FrontEndProperties(wiring.Component):
    """A formal-only wrapper: a front end with a free pixel stream (``first`` included) and free ``ready``.

    Parameters
    ----------
    params, model, width
        As for ``FrontEnd``.
    frontend : callable
        Builds the front end from ``params``, ``model`` and ``width`` keywords; ``FrontEnd`` unless a
        mutant is being checked.

    Attributes
    ----------
    pixels_valid, pixels_payload, beats_ready : ``In``
        The environment (free; the pixel source follows the stream rule).
    beats_valid : ``Out(1)``
        The front end's beat stream, for the trace.
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int,
                 frontend: type = FrontEnd) -> None:
        self._params = params
        self._model = model
        self._width = width
        self._dut = frontend(params=params, model=model, width=width)
        super().__init__({"pixels_valid": In(1), "pixels_payload": In(pixel_in_layout()),
                          "beats_ready": In(1), "beats_valid": Out(1)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.dut = dut = self._dut
        bpp, width, dmax = self._params.beats_per_pixel, self._width, self._model.dmax
        pin = self.pixels_payload
        m.d.comb += [dut.pixels.valid.eq(self.pixels_valid), dut.pixels.payload.eq(pin),
                     dut.beats.ready.eq(self.beats_ready), self.beats_valid.eq(dut.beats.valid)]
        _stream_rule(m, self.pixels_valid, pin, dut.pixels.ready)
        taken = dut.pixels.valid & dut.pixels.ready
        # The reference position: the pixel's column and line (saturating at a window's bottom
        # line), both 0 at a frame's first pixel; an output pixel is on line 4.. and column Dmax + 4...
        col = Signal(range(width))
        line = Signal(range(WINDOW))
        cur_col = Mux(pin.first, 0, col)
        cur_line = Mux(pin.first, 0, line)
        with m.If(taken):
            with m.If(cur_col == width - 1):
                m.d.sync += [col.eq(0), line.eq(Mux(cur_line == WINDOW - 1, cur_line, cur_line + 1))]
            with m.Else():
                m.d.sync += [col.eq(cur_col + 1), line.eq(cur_line)]
        output = (cur_line == WINDOW - 1) & (cur_col >= dmax + WINDOW - 1)
        out_taken = taken & output
        beat = dut.beats.valid & dut.beats.ready
        # Three pipeline stages in front of the word generator, which may take an output pixel a cycle
        # late (after a take at two beats or more: WordPipeline.accept).
        _beats_owed(m, bpp, out_taken, beat, self.beats_ready, bpp + GENERATOR_LATENCY + 4)
        # Not vacuous: all the beats of an output pixel of a frame started again (a ``first`` after
        # another one's pixels) handed over.
        restarted = Signal()
        with m.If(taken & pin.first & (col != 0)):
            m.d.sync += restarted.eq(1)
        beats = Signal(range(bpp + 2))
        with m.If(beat & restarted & (beats != bpp + 1)):
            m.d.sync += beats.eq(beats + 1)
        m.d.comb += Cover(beats == bpp)
        return m


class FifoProperties(wiring.Component):
    """A formal-only wrapper: a ``StereoMachine`` with free inputs, its FIFO watched.

    Parameters
    ----------
    params, model, width, fifo_pixels
        As for ``StereoMachine`` (an off-chip ``rng``: the numbers are free too).
    stereo : callable
        Builds the top from those keywords; ``StereoMachine`` unless a mutant is being checked.
    full_cover : bool
        Add the cover of a full FIFO (it needs three output pixels: a deep, slow cover run).

    Attributes
    ----------
    pixels_valid, pixels_payload, result_ready, entropy : ``In``
        The environment (free; the pixel source follows the stream rule).
    result_valid : ``Out(1)``
        For the trace.
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, width: int, fifo_pixels: int,
                 stereo: type = StereoMachine, full_cover: bool = False) -> None:
        self._params = params
        self._full_cover = full_cover
        self._depth = fifo_pixels * params.beats_per_pixel + 1
        self._dut = stereo(params=params, model=model, width=width, fifo_pixels=fifo_pixels)
        super().__init__({"pixels_valid": In(1), "pixels_payload": In(pixel_in_layout()),
                          "result_ready": In(1), "entropy": In(entropy_layout(params)),
                          "result_valid": Out(1), "result_payload": Out(result_layout(params))})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dut = self._dut
        m.submodules.dut, nets = dut.build(platform)  # built here, with the blocks watched below
        front, machine, load = nets.frontend, nets.machines[0], nets.loads[0]
        buf, used = load.buffer, load.used
        m.d.comb += [dut.pixels.valid.eq(self.pixels_valid), dut.pixels.payload.eq(self.pixels_payload),
                     dut.result.ready.eq(self.result_ready), dut.entropy.eq(self.entropy),
                     self.result_valid.eq(dut.result.valid), self.result_payload.eq(dut.result.payload)]
        _stream_rule(m, self.pixels_valid, self.pixels_payload, dut.pixels.ready)
        depth = self._depth
        # The beats in the FIFO, from its interfaces: the front end's handshakes in, the machine's out.
        handed = front.beats.valid & front.beats.ready
        loaded = machine.load.valid & machine.load.ready
        level = Signal(range(-1, depth + 2))
        m.d.sync += level.eq(level + handed - loaded)
        # Every beat the front end hands over is written: the FIFO has room for it (no overflow, no
        # beat lost), and it fills to its pixels' beats at most.
        with m.If(handed):
            m.d.comb += Assert(buf.w_stream.valid & buf.w_stream.ready, "a beat handed over is written")
        m.d.comb += Assert(~(buf.w_stream.valid & ~buf.w_stream.ready), "no write into a full FIFO")
        m.d.comb += Assert(level <= depth - 1, "the FIFO holds at most fifo_pixels pixels' beats")
        # No beat read that was not written (no underflow), and the count StereoMachine keeps for its
        # registered ready is the FIFO's true level.
        m.d.comb += Assert(level >= 0, "no beat read that was not written")
        with m.If(loaded):
            m.d.comb += Assert(level >= 1, "the machine reads only beats in the FIFO")
        m.d.comb += Assert(used == level, "StereoMachine's beat count is the FIFO's level")
        m.d.comb += Assert(buf.level == level, "the FIFO's own level agrees")
        # The machine reads a beat only when the FIFO offers one (its read side, not our count).
        m.d.comb += Assert(~(loaded & ~buf.r_stream.valid), "no read from an empty FIFO")
        # Not vacuous: a beat written and one read in the same cycle with beats waiting; the front end
        # held back by the FIFO's registered ready, the FIFO full (three output pixels in: the
        # machine busy with one, its shadow holding the next, the FIFO the third).
        m.d.comb += Cover(handed & loaded & (level >= 1))
        if self._full_cover:
            m.d.comb += Cover(front.beats.valid & ~front.beats.ready & (level == depth - 1))
        return m
