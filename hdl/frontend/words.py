"""The word generator: one pass's likelihood-memory words from its pixels' features, beat by beat.

``WordGenerator`` takes every pixel's features (both images' planes, whether the pixel is in the output
region, and the position flags its columns read). The match image's features enter a delay line of
Dmax + 1 pixels, so that when an output pixel arrives entry d holds the features of the pixel lane d
pairs it with (:class:`Reference`: x - d for the left image as reference, and for a right-reference pass
fed by :class:`~.lr.RightPassFeeder` entry Dmax - d, the left pixel x_r + d). For an output pixel it
writes ``words_per_pixel`` words, ``words_per_beat`` per beat, in load order (word o in lane o %
words_per_beat of beat o // words_per_beat, row o // loaded_columns, operator column o % loaded_columns),
exactly the words ``host.likelihoods.pass_words`` computes (its twin).

Each operator column's words come from its column kind's lane builder (:mod:`.lanes`, one per kind,
chosen from the column's class): a FEATURES column's table at its cost (a feature difference, a census
Hamming distance), an ABOVE column's prior from a line of the pass's own MAPs, a PASS column's
consistency test of another pass's MAPs; a FEEDBACK column is formed by the machine (its lane builder
flags each beat of a row's first output pixel ``line_start``); the machine's own loaded prior column
(``prior="loaded"`` without an ABOVE column) is 1.0. In the no-match row the pass's no-match rule
(its lane builder: the floor P_nm(gV) of the reference pixel) sits in the first FEATURES column, each
other column gives its own entry; a pass without a no-match row (``Pass.nomatch`` off) has 0 in every
FEATURES column there; a lane whose match pixel lies past the last output column (a right-reference
pass's flush) is 0 in every FEATURES column.

``words_per_beat`` must be a multiple of the loaded columns, so each lane (word position of a beat)
always holds the same operator column. One beat per cycle, in a four-step pipeline that stalls as a
whole while the stream does (:class:`WordNets`): in the cycle of the beat's issue each lane's cost (a
difference, a Hamming distance, row minus the MAP above) goes into a register; its absolute value,
clamped, into the address register in the next; the look-up (block RAM read) in the next; the beat on
the stream the one after. The registers keep the subtraction (on the reference features' wide fan-out),
the absolute value and clamp, and the long route to the block RAM apart. The cost's operands are
registers: the reference features, and per lane the delay-line entry of the beat, chosen a cycle ahead
(beat 0's when the pixel is taken, the next beat's at each issue), so no path runs from the beat
counter through the entry multiplexer into a table address. The delay line is a circular buffer in
distributed RAM, banked so that each lane row of a beat reads a bank of its own
(:meth:`WordNets._delay_line`); a pixel is written into it a cycle after its take (from a register
holding the taken match features), so the take (which depends on the stream's ready) drives only the
entry registers and the reference features, not the buffer's write enables.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from amaranth.hdl import Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, memory, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.columns import Source
from bayesmachine.hdl.signatures import beat_words, load_stream
from bayesmachine.models import ModelParams, Pass, check_disparity_machine
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources import source_kind

from .filters import feature_layout
from .lanes import Lanes, PlaneFilter, lanes_for
from .tables import FrontEndTables, frontend_tables

__all__ = ["FLAGS", "Reference", "WordGenerator", "WordNets", "check_frontend_params", "check_frontend_types",
           "declared_passes", "features_layout", "flush_bits", "model_filters", "pass_pixel_layout",
           "pixel_features_layout"]

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


def _terms(p: Pass) -> tuple[Any, ...]:
    return (*p.columns, p.model.nomatch)


def features_layout(model: ModelParams) -> data.StructLayout:
    """One image's planes, every one a pass of ``model`` reads, in the order its terms read them."""
    fields: dict[str, Any] = {}
    for p in model.passes:
        for term in _terms(p):
            for name, shape in lanes_for(term).planes(term, model.margin).items():
                fields.setdefault(name, shape)
    return data.StructLayout(fields)


def declared_passes(model: ModelParams) -> tuple[Pass, ...]:
    """The passes ``model`` runs before its own (census-lr's right pass), each on a machine of its own
    beside the own pass's."""
    return model.passes[:-1]


def model_filters(model: ModelParams) -> tuple[PlaneFilter, ...]:
    """The plane filters the terms of every pass of ``model`` read, each once (equal filters are shared),
    in the order the terms read them."""
    out: dict[PlaneFilter, None] = {}
    for p in model.passes:
        for term in _terms(p):
            out.update(dict.fromkeys(lanes_for(term).filters(term, model.margin)))
    return tuple(out)


def pass_flags(model: ModelParams, p: Pass) -> dict[str, Any]:
    """The flags pass ``p``'s pixels carry: its columns' (:data:`FLAGS` order), then its reference's."""
    wanted = {f for c in p.columns for f in lanes_for(c).flags(c)}
    return {f: unsigned(1) for f in FLAGS if f in wanted} | reference_of(p).flags(model.dmax)


def pass_pixel_layout(model: ModelParams, p: Pass) -> data.StructLayout:
    """One pixel for the word generator of ``model``'s pass ``p``."""
    return pixel_features_layout(features_layout(model), pass_flags(model, p))


class Reference:
    """Which delay-line entry lane d of a pass reads, by the pass's reference image (``Pass.reference``):
    the left image (the match is the right pixel x - d, entry d) or the right (:class:`RightReference`)."""

    name: ClassVar[str] = "left"

    @staticmethod
    def entry(d: int, dmax: int) -> int:
        return d

    @staticmethod
    def flags(dmax: int) -> dict[str, Any]:
        return {}

    def lane_valid(self, nets: WordNets, j: int) -> Value | None:
        """Whether lane row j of the beat on the stream has a match pixel (None: always)."""
        return None


class RightReference(Reference):
    """The right image as reference (pixels from :class:`~.lr.RightPassFeeder`: the reference
    delayed by Dmax): lane d pairs right map column x_r with left map column x_r + d, entry Dmax - d.
    ``flush`` = k: lanes d > Dmax - k pair it with a left pixel past the last output column (word 0 in
    every FEATURES column)."""

    name = "right"

    @staticmethod
    def entry(d: int, dmax: int) -> int:
        return dmax - d

    @staticmethod
    def flags(dmax: int) -> dict[str, Any]:
        return {"flush": unsigned(flush_bits(dmax))}

    def lane_valid(self, nets: WordNets, j: int) -> Value | None:
        if not hasattr(self, "_flush"):
            self._flush = nets.at_take(nets.pixel.flush, "flush")
        return nets.aligned(nets.row(j) + self._flush <= nets.dmax, f"lane_ok{j}")


REFERENCES = {r.name: r for r in (Reference, RightReference)}


def reference_of(p: Pass) -> Reference:
    if p.reference not in REFERENCES:
        raise ParameterError(f"model: the on-chip front end takes passes with the {' or '.join(REFERENCES)} "
                             f"image as reference, not the {p.name} pass's {p.reference!r}", "model")
    return REFERENCES[p.reference]()


def flush_bits(dmax: int) -> int:
    """Width of a right-reference pass's ``flush`` field (0 .. Dmax)."""
    return max(1, dmax.bit_length())


def check_frontend_types(params: object, model: object) -> None:
    """``TypeError`` unless ``params`` is a ``MachineParams`` and ``model`` a ``ModelParams``."""
    if not isinstance(params, MachineParams):
        raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
    if not isinstance(model, ModelParams):
        raise TypeError(f"model must be a bayesmachine.models.ModelParams, not {type(model).__name__}")


def _check_pass(model: ModelParams, p: Pass, params: MachineParams) -> None:
    """``ParameterError`` unless a word generator can feed ``params`` pass ``p``'s words."""
    check_disparity_machine(p.model, params)
    reference_of(p)
    for term in _terms(p):
        lanes_for(term)
    if params.words_per_beat % params.loaded_columns:
        raise ParameterError(
            f"words_per_beat ({params.words_per_beat}) must be a multiple of the loaded columns "
            f"({params.loaded_columns}) for the front end, so that each word position of a beat holds one "
            f"operator column (e.g. words_per_beat={min(params.words_per_pixel, 6 * params.loaded_columns)})",
            "words_per_beat")


def check_frontend_params(params: MachineParams, model: ModelParams) -> None:
    """``ParameterError`` naming the parameter unless the front end can feed this machine this model
    (its own pass; each declared pass runs on a machine of its own beside it, with an on-chip random
    source: it has no entropy port)."""
    if not isinstance(params, MachineParams):
        raise ParameterError(f"params must be a MachineParams, not {type(params).__name__}")
    if not isinstance(model, ModelParams):
        raise ParameterError(f"model must be a bayesmachine.models.ModelParams, not {type(model).__name__}")
    _check_pass(model, model.passes[-1], params)
    for p in declared_passes(model):
        if not source_kind(params.rng).on_chip:
            raise ParameterError(f"rng: --model {model.name} on chip needs an on-chip random source (the "
                                 f"{p.name} pass's machine has no entropy port), got {params.rng!r}", "rng")
        reference_of(p)


def _check_output_columns(p: Pass, output_columns: object) -> int | None:
    if output_columns is not None and (isinstance(output_columns, bool)
                                       or not isinstance(output_columns, int)):
        raise TypeError(f"output_columns must be an integer, not {type(output_columns).__name__}")
    # An ABOVE column reads a line of the pass's own MAPs: its length is the output row's.
    line = [c.name for c in p.columns if c.source is Source.ABOVE]
    if line and (output_columns is None or output_columns < 1):
        raise ParameterError(f"output_columns: the {line[0]} column's line of MAPs needs the output pixels "
                             f"per row (>= 1), got {output_columns!r}", "output_columns")
    if not line and output_columns is not None:
        raise ParameterError(f"output_columns: only for a pass with a line of MAPs (an ABOVE column); the "
                             f"{p.name} pass of the {p.model.name} model has none", "output_columns")
    return output_columns


class WordGenerator(wiring.Component):
    """Pixel features in, one pass's output pixels' likelihood-memory words out (the machine's load beats).

    ``pixel.ready`` is high when no output pixel is being written, and in the cycle of its last
    beat's issue: a pixel outside the output region passes in one cycle, an output pixel holds the
    stream for ``beats_per_pixel`` cycles (more if ``beats`` is not ready, or while a lane builder
    holds it: an ABOVE column until the result above has left the machine, a PASS column until the
    MAP it reads is in).

    Parameters
    ----------
    params : MachineParams
        The pass's machine (``words_per_beat`` a multiple of the loaded columns:
        :func:`check_frontend_params`).
    model : ModelParams
        The disparity model.
    pass_name : str, optional
        The pass whose words these are (``model.pass_named``; default the model's own, the last).
    tables : FrontEndTables, optional
        The clamped word tables (default: ``frontend_tables(pass's model, params.word_bits)``).
    output_columns : int, optional
        Output pixels per row (W - 2·margin - Dmax): the length of an ABOVE column's line of MAPs
        (required with one, refused otherwise).
    leads : bool
        An ABOVE column: whether this generator's machine runs a frame's first map row (True: the only
        machine, or machine 0 of several); otherwise its results above come from the machine of the
        map rows just before its own (see ``result_room``).

    Attributes
    ----------
    pixel : ``In(stream.Signature(pass_pixel_layout(model, pass)))``
        Every pixel of the frame in raster order (the match features of all of them enter the delay
        line).
    beats : ``Out(load_stream(params))``
        ``beats_per_pixel`` beats per pixel whose ``output`` flag is set.
    pass_ : Pass
        The pass.
    nets : WordNets
        After elaboration: the generator's shared pipeline (its beat counter, ``active``, ...), for
        the formal wrappers of ``hdl.formal`` and their mutants (read-only).
    The lane builders' ports: an ABOVE column's ``result_take``, ``result_map``, ``result_hit``,
    ``result_room``, ``frame_reset`` (:class:`~.lanes.prior.AboveLanes`); a PASS column's
    ``<pass>_map`` (:class:`~.lanes.consistency.ConsistencyLanes`).
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, pass_name: str | None = None,
                 tables: FrontEndTables | None = None, output_columns: int | None = None,
                 leads: bool = True) -> None:
        check_frontend_types(params, model)
        if pass_name is not None and not isinstance(pass_name, str):
            raise TypeError(f"pass_name must be a pass's name (str), not {type(pass_name).__name__}")
        try:
            p = model.passes[-1] if pass_name is None else model.pass_named(pass_name)
        except ValueError as e:
            raise ParameterError(f"pass_name: {e}", "pass_name") from None
        if p is model.passes[-1]:
            check_frontend_params(params, model)
        else:
            _check_pass(model, p, params)
        if tables is not None and not isinstance(tables, FrontEndTables):
            raise TypeError(f"tables must be a FrontEndTables, not {type(tables).__name__}")
        if not isinstance(leads, bool):
            raise TypeError(f"leads must be a bool, not {type(leads).__name__}")
        self._output_columns = _check_output_columns(p, output_columns)
        self._leads = leads
        self._nets: WordNets | None = None
        self._params = params
        self._model = model
        self._pass = p
        self._tables = tables if tables is not None else frontend_tables(p.model, params.word_bits)
        members = {"pixel": In(stream.Signature(pass_pixel_layout(model, p))),
                   "beats": Out(load_stream(params))}
        for c in p.columns:
            members |= lanes_for(c).members(c, params)
        super().__init__(members)

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def pass_(self) -> Pass:
        return self._pass

    @property
    def leads(self) -> bool:
        return self._leads

    @property
    def tables(self) -> FrontEndTables:
        return self._tables

    @property
    def output_columns(self) -> int | None:
        return self._output_columns

    @property
    def nets(self) -> WordNets:
        """The :class:`WordNets` of the last :meth:`elaborate`; elaborate first."""
        if self._nets is None:
            raise RuntimeError("WordGenerator.nets: elaborate the generator first (Fragment.get)")
        return self._nets

    def elaborate(self, platform: object) -> Module:
        m = Module()
        nets = self._nets = WordNets(m, self)
        columns = [lanes_for(c)(c, nets) for c in self._pass.columns]
        rule = self._pass.model.nomatch
        floor = lanes_for(rule)(rule, nets)
        for lanes in (*columns, floor):
            lanes.build()
        ready = nets.free
        for lanes in columns:
            ready = ready & lanes.ready()
        m.d.comb += self.pixel.ready.eq(ready)
        nets.write_beats(self._loaded(nets, columns, floor))
        return m

    def _loaded(self, nets: WordNets, columns: list[Lanes], floor: Lanes) -> list[tuple[list[Any], Any]]:
        """(words of lane rows 0..R-1, no-match word) of each loaded operator column, in operator order:
        the machine's own loaded prior columns (1.0), then every column but a FEEDBACK one (formed by the
        machine). The no-match rule's word sits in the first FEATURES column's no-match row; a pass
        without a no-match row has 0 in every FEATURES column there; a FEATURES lane without a match
        pixel is 0."""
        p, one = self._pass, nets.one
        loaded = [lanes for lanes in columns if lanes.term.source is not Source.FEEDBACK]
        own = self._params.loaded_columns - len(loaded)
        out: list[tuple[list[Any], Any]] = [([one] * nets.rows_per_beat, one)] * own
        rule_word = floor.nomatch()
        valid = [nets.reference.lane_valid(nets, j) for j in range(nets.rows_per_beat)]
        for lanes in loaded:
            words = [lanes.word(j) for j in range(nets.rows_per_beat)]
            nomatch = lanes.nomatch()
            if lanes.term.source is Source.FEATURES:
                words = [w if ok is None else Mux(ok, w, 0) for w, ok in zip(words, valid, strict=True)]
                nomatch, rule_word = (nomatch if rule_word is None else rule_word), None
                nomatch = nomatch if p.nomatch else 0
            out.append((words, nomatch))
        return out


class WordNets:
    """The word generator's shared pipeline, on which every lane builder builds its lanes.

    One beat per cycle, in four steps that stall together with the stream (``advance``): the beat's
    issue (``issue``, beat number ``beat``: each lane's cost into a register, :meth:`address`), the
    cost's clamped absolute value into the address register, the table read (:meth:`table`), the beat
    on the stream (:meth:`aligned` carries a value of the issue's cycle along). ``take``: a pixel is
    taken; ``left``: the taken pixel's reference features; :meth:`entry`: a lane's match features.

    Attributes
    ----------
    m : Module
        The generator's module.
    params : MachineParams
    pass_ : Pass
    reference : Reference
    tables : FrontEndTables
    pixel, beats : View
        The pixel stream's and the load stream's payloads.
    dmax, rows_per_beat, n_beats, one : int
        The largest disparity, lane rows per beat (R), beats per pixel, the word of 1.0.
    take, advance, issue, beat, free : Value
    active : Signal
        Writing the words of an output pixel (``beat`` counts its beats).
    left : Signal
        The taken pixel's reference features (its ``left`` field).
    """

    def __init__(self, m: Module, gen: WordGenerator) -> None:
        p = gen.params
        self.m = m
        self.params = p
        self.pass_ = gen.pass_
        self.reference = reference_of(gen.pass_)
        self.tables = gen.tables
        self.generator = gen
        self.pixel = gen.pixel.payload
        self.beats = gen.beats.payload
        self.dmax = gen.pass_.model.dmax
        self.rows_per_beat = p.words_per_beat // p.loaded_columns
        self.n_beats = p.beats_per_pixel
        self.one = p.word_one
        self.take = Signal()
        self.advance = Signal()  # the look-up pipeline (address registers, table reads, stream) moves
        self.issue = Signal()
        self.beat = Signal(range(max(2, self.n_beats)))
        side = gen.pixel.payload.left.shape()
        self.left = Signal(side, reset_less=True)
        self._entries: dict[tuple[str, int], Signal] = {}
        self._pipeline()
        self._delay_line(side)

    def _pipeline(self) -> None:
        """The beat counter and the valid flags of the four steps."""
        m, n_beats = self.m, self.n_beats
        out = self.generator.beats
        active = Signal()  # writing the words of an output pixel
        self.active = active
        beat_d = Signal(range(max(2, n_beats)))  # the beat in the cost registers
        diff_valid = Signal()
        beat_a = Signal(range(max(2, n_beats)))  # the beat in the address registers
        addr_valid = Signal()
        self.beat_q = Signal(range(max(2, n_beats)))  # the beat on the stream
        m.d.comb += [self.advance.eq(~out.valid | out.ready), self.issue.eq(active & self.advance),
                     self.take.eq(self.generator.pixel.valid & self.generator.pixel.ready)]
        last = self.beat == n_beats - 1
        self.free = ~active | (self.issue & last)
        with m.If(self.advance):
            m.d.sync += [diff_valid.eq(self.issue), beat_d.eq(self.beat), addr_valid.eq(diff_valid),
                         beat_a.eq(beat_d), out.valid.eq(addr_valid), self.beat_q.eq(beat_a)]
        with m.If(self.issue):
            with m.If(last):
                m.d.sync += [self.beat.eq(0), active.eq(0)]
            with m.Else():
                m.d.sync += self.beat.eq(self.beat + 1)
        with m.If(self.take):
            m.d.sync += self.left.eq(self.pixel.left)
            with m.If(self.pixel.output):
                m.d.sync += [active.eq(1), self.beat.eq(0)]

    def _delay_line(self, side: Any) -> None:
        """The match features of the last pixels: pixel t (the t-th taken) at address t mod N of a
        circular buffer of N = R·M entries (R lane rows per beat, M = ceil((Dmax + 1) / R)), banked by
        address mod R, bank k holding addresses k, k + R, ... at index address // R (distributed RAM,
        one combinational read port each). Entry d of pixel t (the match features d pixels back) is at
        address t - d; a beat's R lanes read R consecutive entries, so R consecutive addresses, one in
        each bank (:meth:`_next_load`). Entries of a lane row past Dmax read some older pixel (their
        words are the no-match row's or 0, not a table's). A pixel is written a cycle after its take,
        from a register holding its match features (``right_in``): the take (FIFO ready -> issue ->
        take) drives the entry registers, not the buffer's write enables. While that write is pending
        (``shift_q``) the newest pixel is in ``right_in``. Uninitialized entries: an output pixel is at
        least Dmax pixels into its line, so none reads an entry of an earlier line or frame."""
        m, rows = self.m, self.rows_per_beat
        self._bank_depth = -(-(self.dmax + 1) // rows)  # M: entries per bank
        self.right_in = Signal(side, reset_less=True)
        self.shift_q = Signal()
        write_bank = Signal(range(rows))  # the next write's address t mod N, as bank and index
        write_index = Signal(range(self._bank_depth))
        q, q_wrap, start = self._next_load()
        self._bank_data = []
        for k in range(rows):
            mem = memory.Memory(shape=side, depth=self._bank_depth, init=[])
            m.submodules[f"line_{k}"] = mem
            write, read = mem.write_port(), mem.read_port(domain="comb")
            # The window runs from bank ``start`` towards lower banks (left reference) or higher ones;
            # the banks it reaches after wrapping around hold its end at the neighbouring index.
            # (a bank no window reaches after wrapping is never compared: a constant compare lints)
            if self._towards < 0:
                wraps = start[0] < k if k > 0 else Const(0, 1)
            else:
                wraps = start[0] > k if k < rows - 1 else Const(0, 1)
            m.d.comb += [write.addr.eq(write_index), write.data.eq(self.right_in),
                         write.en.eq(self.shift_q & (write_bank == k)), read.addr.eq(Mux(wraps, q_wrap, q))]
            self._bank_data.append(read.data)
        m.d.sync += self.shift_q.eq(self.take)
        with m.If(self.shift_q):
            m.d.sync += [write_bank.eq(Mux(write_bank == rows - 1, 0, write_bank + 1)),
                         write_index.eq(Mux(write_bank == rows - 1, self._step(write_index, 1), write_index))]
        with m.If(self.take):
            m.d.sync += self.right_in.eq(self.pixel.right)

    def _step(self, index: Value, by: int) -> Value:
        """A bank index plus ``by`` (-2 .. 2) modulo M (a compare and a multiplexer a step)."""
        last = self._bank_depth - 1
        for _ in range(abs(by)):
            index = Mux(index == last, 0, index + 1) if by > 0 else Mux(index == 0, last, index - 1)
        return index

    def _next_load(self) -> tuple[Signal, Signal, list[Signal]]:
        """Where the next entry load reads: (``q``, ``q_wrap``, ``start``). Beat b of pixel t reads
        entries c + g·(b·R + j) (lane j; c, g from the pass's reference: entry = c + g·row), addresses
        u - g·(b·R + j) with u = t - c: its window starts at address u - g·b·R, in bank s = u mod R
        (fixed for the pixel) at index q (one step of -g a beat), and runs through the banks s - g·j,
        those past the last bank at index ``q_wrap`` = q - g; lane j reads bank s - g·j (``start``: s, a
        registered copy per lane row for the rotations' fan-out). The next load is beat 0 of the next
        pixel until an output pixel's take, then beats 1 .. n - 1 of that pixel at its issues of beats
        0 .. n - 2, then beat 0 of the pixel after; all in registers, so a bank's address is a
        multiplexer of registers."""
        m, rows, n_beats = self.m, self.rows_per_beat, self.n_beats
        c = self.reference.entry(0, self.dmax)
        g = self.reference.entry(1, self.dmax) - c
        self._towards = -g
        u0 = (-c) % (rows * self._bank_depth)
        q0 = Signal(range(self._bank_depth), init=u0 // rows)  # beat 0 of the pixel taken next
        s0 = Signal(range(rows), init=u0 % rows)
        q = Signal(range(self._bank_depth), init=u0 // rows)  # the next load's window
        q_wrap = Signal(range(self._bank_depth), init=(u0 // rows - g) % self._bank_depth)
        start = [Signal(range(rows), init=u0 % rows, name=f"load_start_rep{j}") for j in range(rows)]
        carry = s0 == rows - 1
        q0_next = Mux(carry, self._step(q0, 1), q0)
        s0_next = Mux(carry, 0, s0 + 1)
        next_pixel = [q.eq(q0_next), q_wrap.eq(self._step(q0_next, -g)), *(r.eq(s0_next) for r in start)]
        with m.If(self.take):
            m.d.sync += [q0.eq(q0_next), s0.eq(s0_next)]
            if n_beats > 1:
                with m.If(self.pixel.output):  # next: beat 1 of this pixel
                    m.d.sync += [q.eq(self._step(q0, -g)), q_wrap.eq(self._step(q0, -2 * g))]
                with m.Else():  # next: beat 0 of the next pixel
                    m.d.sync += next_pixel
            else:
                m.d.sync += next_pixel
        if n_beats > 1:
            with m.Elif(self.issue & (self.beat == n_beats - 2)):  # next: beat 0 of the next pixel
                m.d.sync += [q.eq(q0), q_wrap.eq(self._step(q0, -g)), *(r.eq(s0) for r in start)]
        if n_beats > 2:
            with m.Elif(self.issue & (self.beat < n_beats - 2)):  # next: beat b + 2
                m.d.sync += [q.eq(self._step(q, -g)), q_wrap.eq(self._step(q_wrap, -g))]
        self._start = start
        return q, q_wrap, start

    def row(self, j: int) -> Value:
        """The row of lane row j of the beat being issued."""
        return self.beat * self.rows_per_beat + j

    def at_take(self, value: Value, name: str) -> Signal:
        """``value`` of the pixel taken (registered at the take)."""
        reg = Signal.like(value, name=name)
        with self.m.If(self.take):
            self.m.d.sync += reg.eq(value)
        return reg

    def aligned(self, value: Value, name: str) -> Signal:
        """``value`` of the issue's cycle, with its beat on the stream (the three steps' registers)."""
        stages = [Signal.like(Value.cast(value), name=f"{name}_{s}") for s in "daq"]
        with self.m.If(self.advance):
            self.m.d.sync += [stages[0].eq(value), stages[1].eq(stages[0]), stages[2].eq(stages[1])]
        return stages[2]

    def address(self, value: Value, depth: int, name: str) -> Signal:
        """The table address of a lane's cost ``value`` (of the issue's cycle): its absolute value clamped
        to ``depth - 1``, a cycle later (the cost in a register, then the address in one)."""
        if Value.cast(value).shape().width > 14:
            raise ValueError(f"{name}: a cost of {Value.cast(value).shape()} does not fit the 14-bit "
                             "register")
        diff = Signal(signed(14), name=f"diff_{name}", reset_less=True)  # guarded by the pipeline's valid
        a = Signal(unsigned(14))
        # The clamp's test on the difference itself, beside the absolute value, not after it.
        far = (diff >= depth - 1) | (diff <= -(depth - 1))
        self.m.d.comb += a.eq(abs(diff))
        reg = Signal(range(depth), name=f"addr_{name}", reset_less=True)  # guarded by the pipeline's valid
        with self.m.If(self.advance):
            self.m.d.sync += [diff.eq(value), reg.eq(Mux(far, depth - 1, a))]
        return reg

    def table(self, name: str, words: Any) -> memory.Memory:
        """A read-only table of W + 1-bit words (block RAM), submodule ``table_{name}``."""
        init = [int(w) for w in words]
        mem = memory.Memory(shape=unsigned(self.params.memory_word_width), depth=len(init), init=init)
        self.m.submodules[f"table_{name}"] = mem
        return mem

    def lookup(self, name: str, words: Any, costs: list[Value]) -> list[Value]:
        """The words of a table ``words`` at each lane row's cost ``costs[j]``, with the beat on the stream
        (one read port per lane row)."""
        mem = self.table(name, words)
        out = []
        for j, cost in enumerate(costs):
            port = mem.read_port()
            addr = self.address(cost, mem.depth, f"{name}_{j}")
            self.m.d.comb += [port.en.eq(self.advance), port.addr.eq(addr)]
            out.append(port.data)
        return out

    def entry(self, plane: str, j: int) -> Signal:
        """The ``plane`` value of lane row j's match pixel for the beat being issued: a register loaded a
        cycle ahead from the delay line's banks (the beat counter ends there, not at the table address),
        with beat 0's entry when a pixel is taken, the next beat's on an issue. The newest pixels come
        from the registers in front of the buffer until they are written: at the take the taken pixel
        (entry 0) and the one before it (entry 1) while its write is pending; at beat 0's issue the
        taken pixel while its write is pending."""
        key = (plane, j)
        if key in self._entries:
            return self._entries[key]
        m, rows = self.m, self.rows_per_beat
        banks = [getattr(d, plane) for d in self._bank_data]
        read = Signal(banks[0].shape(), name=f"line_{plane}_{j}")
        with m.Switch(self._start[j]):  # lane j reads bank s - g·j (s < R: the last case is the default)
            for start in range(rows):
                with m.Case(start) if start < rows - 1 else m.Default():
                    m.d.comb += read.eq(banks[(start + self._towards * j) % rows])
        pending = getattr(self.right_in, plane)

        def newest(d: int) -> Value:  # entry d of the pixel being loaded, a pending write included
            return Mux(self.shift_q, pending, read) if d == 0 else read

        d0 = self.reference.entry(j, self.dmax)
        sel = Signal(banks[0].shape(), name=f"right_{plane}_{j}", reset_less=True)
        with m.If(self.take):
            m.d.sync += sel.eq(getattr(self.pixel.right, plane) if d0 == 0 else newest(d0 - 1))
        with m.Elif(self.issue):  # beat b + 1's entry; shift_q is set at beat 0's issue at most
            m.d.sync += sel.eq(newest(self.reference.entry(rows + j, self.dmax)))
        self._entries[key] = sel
        return sel

    def write_beats(self, columns: list[tuple[list[Any], Any]]) -> None:
        """The beat on the stream: lane L's word by its (row, operator column) from ``columns`` (each
        loaded column's words of lane rows 0..R-1 and its no-match word); 0 past the last row."""
        m, dmax, rows = self.m, self.dmax, self.rows_per_beat
        lc = len(columns)
        words = beat_words(self.params, self.beats)
        unused = range(self.n_beats, 1 << len(self.beat_q))  # never occur; in the last case: a complete case
        with m.Switch(self.beat_q):
            for b in range(self.n_beats):
                with m.Case(b, *(unused if b == self.n_beats - 1 else ())):
                    for lane in range(self.params.words_per_beat):
                        row, (col_words, nomatch) = b * rows + lane // lc, columns[lane % lc]
                        if row > dmax + 1:
                            word: Any = 0  # past the last operator: the machine ignores it
                        else:
                            word = col_words[lane // lc] if row <= dmax else nomatch
                        m.d.comb += words[lane].eq(word)

