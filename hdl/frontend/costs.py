"""Costs and likelihood-memory words: the right features' delay line and the table look-ups.

``WordGenerator`` takes every pixel's features (left and right sums, census codes with the
census model, and whether the pixel is in the output region). Each pixel's right features enter
a delay line of Dmax + 1 pixels, so that when an output pixel at map column x arrives, entry d
holds the right features at x - d. For an output pixel it then writes the pixel's
``words_per_pixel`` words, ``words_per_beat`` per beat, in load order (word o in lane o % words_per_beat
of beat o // words_per_beat, row o // loaded_columns), exactly the words ``host.likelihoods.memory_words``
computes (its twin):

- row d <= Dmax, feature column f: the table of f at min(|left_f - right_f[d]|, last entry);
- census column (census model): the census table at popcount(left code xor right code[d]);
- the no-match row: the no-match table at min(|left gV|, last entry), then words of 1.0, and in
  the census column the census table's word at the constant Hamming distance h_nm;
- with a loaded prior (``prior="loaded"``), operator column 0 is 1.0 (a uniform prior), as the
  host writes it;
- with the neighbour prior (``prior="neighbour"``), the loaded column (the above neighbour's
  factor, the machine's operator column 1) is ``neighbour_words`` of the machine's own result
  for the pixel above: a line of MAPs (a ``Memory`` of the output width, written as results
  leave through ``result_*``, read when the pixel is taken) through the prior table clamped
  where it stops changing (the machine's ``feedback_words``); 1.0 in a frame's first output row
  and after a no-match or timeout above. An output pixel is taken only when the result above it
  has left the machine (fewer than an output row's pixels in flight), so no word is built from a
  stale entry, whatever the FIFO's depth and the image's width. Each beat of the first output
  pixel of a row carries ``line_start`` (the machine's left factor is then 1.0).
- census-lr (``hdl.frontend.lr``): the left pass's consistency column (the last loaded column),
  row d 1.0 or β by lane d's window test on the right MAP d_R(x - d) (:class:`~.lr.ConsistencyTest`,
  fed one right MAP per pixel at a map column of an output row: ``right_map``), the no-match row γ
  when any lane is consistent, else 1.0 (0 without a left no-match row); and with ``right_pass``
  the right pass's words (twin: ``host.likelihoods.right_memory_words``).

``words_per_beat`` must be a multiple of the loaded columns, so each lane (word position of a beat)
always holds the same operator column: a lane of feature f reads its own port of f's table. One
beat per cycle, in a four-step pipeline that stalls as a whole while the stream does: in the
cycle of the beat's issue each lane's difference (census: Hamming distance; prior: row minus the
MAP above) goes into a register; its absolute value, clamped, into the address register in the next;
the look-up (block RAM read) in the next; the beat on the stream the one after. The registers keep the
subtraction (on the left sums' wide fan-out), the absolute value and clamp, and the long route
to the block RAM apart. The difference's operands are registers: the left sums, and per lane the
delay-line entry of the beat, chosen a cycle ahead (beat 0's when the pixel is taken, the next
beat's at each issue), so no path runs from the beat counter through the entry multiplexer into
a table address. The delay line shifts a cycle after the take (from a register holding the taken
right features), its enables on registered copies of the take, so the take (which depends on the
stream's ready) drives only the entry registers and the left sums, not the delay line's
thousands of enables.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, memory, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.columns import AbovePrior, Census, Consistency
from bayesmachine.hdl.signatures import beat_words, load_stream
from bayesmachine.models import ModelParams, check_disparity_machine
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources import source_kind

from .filters import feature_layout
from .tables import FrontEndTables, frontend_tables

__all__ = ["FEATURES", "WordGenerator", "check_frontend_params", "check_frontend_types",
           "pixel_features_layout", "popcount"]

FEATURES = ("m25", "gh20", "gv20")  # feature sum fields, in the operator columns' order


def pixel_features_layout(census_bits: int = 0, neighbour: bool = False, *, consult: bool = False,
                          flush_bits: int = 0) -> data.StructLayout:
    """One pixel for the word generator: both images' feature sums (and census codes with
    ``census_bits``), the output-region flag and, with the neighbour prior, ``row_start`` (the
    first output pixel of an output row) and ``first_row`` (an output pixel of a frame's first
    output row: no pixel above). census-lr's left pass (``consult``): ``consult``, the pixel is at a
    map column (>= 0) of an output row, so its right MAP enters the consistency test; its right pass
    (``flush_bits``): ``flush`` = k, lanes d > Dmax - k pair the right pixel with a left pixel past the
    last output column (``hdl.frontend.lr.RightPassFeeder``)."""
    side = feature_layout(census_bits)
    fields = {"left": side, "right": side, "output": unsigned(1)}
    if neighbour:
        fields |= {"row_start": unsigned(1), "first_row": unsigned(1)}
    if consult:
        fields |= {"consult": unsigned(1)}
    if flush_bits:
        fields |= {"flush": unsigned(flush_bits)}
    return data.StructLayout(fields)


def popcount(value: Value) -> Value:
    """The number of set bits of ``value``, as a balanced adder tree."""
    terms: list[Value] = [value[i] for i in range(len(value))]
    if not terms:
        return Value.cast(0)
    while len(terms) > 1:
        terms = [terms[i] + terms[i + 1] if i + 1 < len(terms) else terms[i] for i in range(0, len(terms), 2)]
    return terms[0]


def check_frontend_types(params: object, model: object) -> None:
    """``TypeError`` unless ``params`` is a ``MachineParams`` and ``model`` a ``ModelParams``."""
    if not isinstance(params, MachineParams):
        raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
    if not isinstance(model, ModelParams):
        raise TypeError(f"model must be a bayesmachine.models.ModelParams, not {type(model).__name__}")


def check_frontend_params(params: MachineParams, model: ModelParams) -> None:
    """``ParameterError`` naming the parameter unless the front end can feed this machine this model."""
    if not isinstance(params, MachineParams):
        raise ParameterError(f"params must be a MachineParams, not {type(params).__name__}")
    if not isinstance(model, ModelParams):
        raise ParameterError(f"model must be a bayesmachine.models.ModelParams, not {type(model).__name__}")
    check_disparity_machine(model, params)
    if len(model.passes) > 1 and not source_kind(params.rng).on_chip:
        # The right pass's machine would need an entropy port of its own.
        raise ParameterError(f"rng: --model {model.name} on chip needs an on-chip random source (the right "
                             f"pass's machine has no entropy port), got {params.rng!r}")
    if params.words_per_beat % params.loaded_columns:
        raise ParameterError(
            f"words_per_beat ({params.words_per_beat}) must be a multiple of the loaded columns "
            f"({params.loaded_columns}) "
            f"for the front end, so that each word position of a beat holds one feature (e.g. words_per_beat="
            f"{min(params.words_per_pixel, 6 * params.loaded_columns)})")


class WordGenerator(wiring.Component):
    """Pixel features in, the output pixels' likelihood-memory words out (the machine's load beats).

    ``pixel.ready`` is high when no output pixel is being written, and in the cycle of its last
    beat's issue: a pixel outside the output region passes in one cycle, an output pixel holds
    the stream for ``beats_per_pixel`` cycles (more if ``beats`` is not ready, or, with the
    neighbour prior, until the result of the pixel above has left the machine).

    Parameters
    ----------
    params : MachineParams
        The machine fed (``words_per_beat`` a multiple of the loaded columns: :func:`check_frontend_params`).
    model : ModelParams
        The disparity model (Dmax, p0, sigmas, p_nm0, sigma_nm; the census model's fields).
    tables : FrontEndTables, optional
        The likelihood tables (default: ``frontend_tables(model, params.word_bits)``).
    output_columns : int, optional
        Output pixels per row (W - 2·margin - Dmax): the line of MAPs of the neighbour prior
        (required with ``prior="neighbour"``, refused otherwise).
    leads : bool
        Neighbour prior: whether this generator's machine runs a frame's first map row (True: the
        only machine, or machine 0 of several); otherwise its results above come from the machine
        of the map rows just before its own, which must write an output row's first result
        before this generator takes that row's first output pixel (see ``result_room``).
    right_pass : bool
        census-lr's right pass (``model`` its ``model.pass_named("right").model``,
        pixels from :class:`~.lr.RightPassFeeder`): ``left`` is the right pixel (the reference), lane d
        reads delay-line entry Dmax - d (the left pixel x_r + d), a lane past the last output column
        (``flush``) and the no-match row are word 0 in every data column (with ``right_nomatch`` the
        no-match row is the census model's).
    right_nomatch : bool
        With ``right_pass``: ``ModelParams.lr_right_nomatch`` of the census-lr model.

    Attributes
    ----------
    pixel : ``In(stream.Signature(pixel_features_layout(bits, neighbour)))``
        Every pixel of the frame in raster order (the right features of all of them enter the
        delay line).
    beats : ``Out(load_stream(params))``
        ``beats_per_pixel`` beats per pixel whose ``output`` flag is set.
    result_take, result_map, result_hit : ``In(1)``, ``In(params.map_width)``, ``In(1)``
        Neighbour prior only: a result of the map rows above this generator's leaves its machine
        (its MAP row, and whether it is a disparity: not no match, not a timeout), in raster
        order of those rows.
    result_room : ``Out(1)``
        Neighbour prior only: a result may be written into the line of MAPs this cycle (its entry
        has been read). With one machine it is always set when a result leaves.
    frame_reset : ``In(1)``
        Neighbour prior only: every machine is idle and a frame starts (the counts start afresh);
        held low with one machine.
    right_map : ``In(stream.Signature(right_map_layout(params.map_width)))``
        census-lr's left pass only: the right pass's MAPs in raster order of its columns; one is taken
        with each pixel whose ``consult`` is set, into the consistency column's test
        (:class:`~.lr.ConsistencyTest`), and such a pixel waits for it.
    """

    def __init__(self, *, params: MachineParams, model: ModelParams,
                 tables: FrontEndTables | None = None, output_columns: int | None = None,
                 leads: bool = True, right_pass: bool = False, right_nomatch: bool = False) -> None:
        check_frontend_types(params, model)
        check_frontend_params(params, model)
        for name, value in (("right_pass", right_pass), ("right_nomatch", right_nomatch)):
            if not isinstance(value, bool):
                raise TypeError(f"{name} must be a bool, not {type(value).__name__}")
        if right_pass and (model.column(Census) is None or model.column(AbovePrior) is None):
            raise ParameterError("right_pass: the right pass runs a census-lr model's right_model (the "
                                 f"census model with its neighbour prior), got the {model.name} model")
        if right_nomatch and not right_pass:
            raise ParameterError("right_nomatch: only with right_pass")
        self._right_pass = right_pass
        self._right_nomatch = right_nomatch
        if tables is not None and not isinstance(tables, FrontEndTables):
            raise TypeError(f"tables must be a FrontEndTables, not {type(tables).__name__}")
        neighbour = params.feedback_columns > 0
        if output_columns is not None and (isinstance(output_columns, bool)
                                           or not isinstance(output_columns, int)):
            raise TypeError(f"output_columns must be an integer, not {type(output_columns).__name__}")
        if neighbour and (output_columns is None or output_columns < 1):
            raise ParameterError(f"output_columns: the neighbour prior's line of MAPs needs the output "
                                 "pixels "
                                 f"per row (>= 1), got {output_columns!r}")
        if not neighbour and output_columns is not None:
            raise ParameterError("output_columns: only for a machine with prior = 'neighbour'")
        if not isinstance(leads, bool):
            raise TypeError(f"leads must be a bool, not {type(leads).__name__}")
        self._leads = leads
        self._params = params
        self._model = model
        self._tables = tables if tables is not None else frontend_tables(model, params.word_bits)
        self._output_columns = output_columns
        census = model.column(Census)
        bits = census.bits if census is not None else 0
        lr = model.column(Consistency) is not None
        from .lr import flush_bits, right_map_layout

        layout = pixel_features_layout(bits, neighbour, consult=lr,
                                       flush_bits=flush_bits(model.dmax) if right_pass else 0)
        members = {
            "pixel": In(stream.Signature(layout)),
            "beats": Out(load_stream(params)),
        }
        if neighbour:
            members |= {"result_take": In(1), "result_map": In(params.map_width), "result_hit": In(1),
                        "result_room": Out(1), "frame_reset": In(1)}
        if lr:
            members |= {"right_map": In(stream.Signature(right_map_layout(params.map_width)))}
        super().__init__(members)

    @property
    def right_pass(self) -> bool:
        return self._right_pass

    @property
    def right_nomatch(self) -> bool:
        return self._right_nomatch

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def leads(self) -> bool:
        return self._leads

    @property
    def tables(self) -> FrontEndTables:
        return self._tables

    @property
    def output_columns(self) -> int | None:
        return self._output_columns

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p, model = self._params, self._model
        dmax = model.dmax
        lc = p.loaded_columns  # words per row in a beat
        off = lc - p.columns  # 1 with a loaded prior column (the above factor with the neighbour prior)
        neighbour = p.feedback_columns > 0
        census = model.column(Census)
        lr = model.column(Consistency)
        fields = FEATURES + (("census",) if census is not None else ())
        rows_per_beat = p.words_per_beat // lc
        n_beats = p.beats_per_pixel
        one = p.word_one
        bits = census.bits if census is not None else 0

        # Delay line: right[d] = right features d pixels back (reset-less: no output reads a
        # stale entry, since an output pixel is at least Dmax pixels into its line).
        right = [Signal(feature_layout(bits), name=f"right_{d}", reset_less=True) for d in range(dmax + 1)]
        left = Signal(feature_layout(bits), reset_less=True)
        active = Signal()  # writing the words of an output pixel
        beat = Signal(range(max(2, n_beats)))
        beat_d = Signal(range(max(2, n_beats)))  # the beat in the difference registers
        diff_valid = Signal()
        beat_a = Signal(range(max(2, n_beats)))  # the beat in the address registers
        addr_valid = Signal()
        beat_q = Signal(range(max(2, n_beats)))  # the beat on the stream

        out = self.beats
        words = beat_words(p, out.payload)
        advance = Signal()  # the look-up pipeline (address registers, table reads, stream) moves
        issue = Signal()
        m.d.comb += [advance.eq(~out.valid | out.ready), issue.eq(active & advance)]
        last = beat == n_beats - 1
        free = ~active | (issue & last)
        if neighbour:
            # An output pixel waits until the result above it is in the line of MAPs, and a result
            # is written only over an entry already read: ``unread`` = results written - output
            # pixels taken (+ an output row with ``leads``: the first map row reads no result).
            # An output pixel is taken while unread >= 1, a result written while unread < the row.
            # Both tests are on the counts of the next cycle, registered (a register toward the
            # take, no path from the result). With one machine this is "fewer than an output
            # row's pixels taken and not yet out".
            wo = self._output_columns
            assert wo is not None
            start = wo if self._leads else 0
            unread = Signal(range(wo + 1), init=start)
            room = Signal(init=start >= 1)
            write_room = Signal(init=start < wo)
            m.d.comb += self.result_room.eq(write_room)
            out_take = self.pixel.valid & self.pixel.ready & self.pixel.payload.output
            unread_next = Signal.like(unread)
            m.d.comb += unread_next.eq(unread + self.result_take - out_take)
            with m.If(self.frame_reset):  # every machine idle: a frame starts afresh
                m.d.sync += [unread.eq(start), room.eq(start >= 1), write_room.eq(start < wo)]
            with m.Else():
                m.d.sync += [unread.eq(unread_next), room.eq(unread_next >= 1),
                             write_room.eq(unread_next < wo)]
            ready = free & (~self.pixel.payload.output | room)
        else:
            ready = free
        if lr is not None:  # a pixel whose right MAP enters the consistency test waits for it
            ready = ready & (~self.pixel.payload.consult | self.right_map.valid)
        m.d.comb += self.pixel.ready.eq(ready)
        take = self.pixel.valid & self.pixel.ready

        with m.If(advance):
            m.d.sync += [diff_valid.eq(issue), beat_d.eq(beat), addr_valid.eq(diff_valid), beat_a.eq(beat_d),
                         out.valid.eq(addr_valid), beat_q.eq(beat_a)]
        with m.If(issue):
            with m.If(last):
                m.d.sync += [beat.eq(0), active.eq(0)]
            with m.Else():
                m.d.sync += beat.eq(beat + 1)
        # The delay line shifts a cycle after the take, from a register holding the taken
        # pixel's right features: its thousands of enables hang on registered copies of the
        # take (groups of entries), not on the take itself (FIFO ready -> issue -> take). While
        # a shift is pending (``shift_q``) the line as the words see it is [right_in, right...].
        right_in = Signal(feature_layout(bits), reset_less=True)
        shift_q = Signal()
        group = 9  # delay-line entries per copy of the shift enable
        shift_rep = [Signal(name=f"shift_rep{g}") for g in range((dmax + group) // group)]
        m.d.sync += [shift_q.eq(take), *(r.eq(take) for r in shift_rep)]
        for d in range(dmax + 1):
            with m.If(shift_rep[d // group]):
                m.d.sync += right[d].eq(right_in if d == 0 else right[d - 1])
        with m.If(take):
            m.d.sync += [right_in.eq(self.pixel.payload.right), left.eq(self.pixel.payload.left)]
            with m.If(self.pixel.payload.output):
                m.d.sync += [active.eq(1), beat.eq(0)]

        # Table reads: the issued beat's differences into registers, then their clamped absolute
        # values (the addresses), read a cycle later, data with the beat on the stream; every
        # register holds while the stream is stalled.
        def address(value: object, depth: int, name: str) -> Signal:
            diff = Signal(signed(14), name=f"diff_{name}", reset_less=True)  # guarded by diff_valid
            a = Signal(unsigned(14))
            # The clamp's test on the difference itself, beside the absolute value, not after it.
            far = (diff >= depth - 1) | (diff <= -(depth - 1))
            m.d.comb += a.eq(abs(diff))
            reg = Signal(range(depth), name=f"addr_{name}", reset_less=True)  # guarded by addr_valid
            with m.If(advance):
                m.d.sync += [diff.eq(value), reg.eq(Mux(far, depth - 1, a))]
            return reg

        def table_memory(name: str, table: object) -> memory.Memory:
            words_ = [int(w) for w in table]
            mem = memory.Memory(shape=unsigned(p.memory_word_width), depth=len(words_), init=words_)
            m.submodules[f"table_{name}"] = mem
            return mem

        # The delay-line entry of lane row r: d = r, or in the right pass Dmax - r (the left pixel x_r + d).
        def lane_entry(row: int) -> int:
            d = min(row, dmax)
            return dmax - d if self._right_pass else d

        # Each lane's delay-line entry comes from a register loaded a cycle ahead (the beat
        # counter's multiplexer ends there, not at the table address): with beat 0's entry when
        # a pixel is taken (the line as it is after the shift), with the next beat's on an issue.
        lane_data: dict[int, object] = {}
        for f, name in enumerate(fields):
            mem = table_memory(name, self._tables.census if name == "census" else self._tables.feature(f))
            for j in range(rows_per_beat):
                def entry(d: int, name: str = name) -> object:
                    # Entry d of the line as the words see it (a pending shift included).
                    seen = right_in if d == 0 else right[d - 1]
                    return Mux(shift_q, getattr(seen, name), getattr(right[d], name))

                entries = [getattr(right[lane_entry(b * rows_per_beat + j)], name) for b in range(n_beats)]
                sel = Signal(entries[0].shape(), name=f"right_{name}_{j}", reset_less=True)
                with m.If(take):
                    d = lane_entry(j)  # entry d after the take is entry d - 1 now
                    m.d.sync += sel.eq(getattr(self.pixel.payload.right, name) if d == 0 else entry(d - 1))
                with m.Elif(issue):
                    with m.Switch(beat):
                        if n_beats > 1:  # beat 0: the only one issued with a shift pending
                            with m.Case(0):
                                m.d.sync += sel.eq(entry(lane_entry(rows_per_beat + j)))
                        for b in range(1, n_beats - 1):
                            with m.Case(b):
                                m.d.sync += sel.eq(entries[b + 1])
                        with m.Default():  # the last beat: the next take reloads it; a complete case
                            m.d.sync += sel.eq(entries[-1])
                port = mem.read_port()
                # A feature's |difference of sums|, or the census codes' Hamming distance.
                value = popcount(left.census ^ sel) if name == "census" else getattr(left, name) - sel
                m.d.comb += [port.en.eq(advance), port.addr.eq(address(value, mem.depth, f"{name}_{j}"))]
                lane_data[j * lc + off + f] = port.data
        nm_port = table_memory("nomatch", self._tables.nomatch).read_port()
        m.d.comb += [nm_port.en.eq(advance),
                     nm_port.addr.eq(address(left.gv20, len(self._tables.nomatch), "nomatch"))]
        census_nm = 0
        if census is not None:
            # The no-match row's census word: the census table read at the constant address h_nm.
            t = self._tables.census
            census_nm = int(t[min(census.nomatch_h, len(t) - 1)])

        prior_data: dict[int, object] = {}
        above_valid = Signal()  # the pixel above is a disparity (with the beat on the stream)
        if neighbour:
            above_valid = self._above_prior(m, take, advance, beat, address, table_memory, rows_per_beat,
                                            prior_data)
        line_start_q = Signal()
        if neighbour:
            row_start = Signal()
            ls_d, ls_a = Signal(), Signal()
            with m.If(take):
                m.d.sync += row_start.eq(self.pixel.payload.row_start)
            with m.If(advance):
                m.d.sync += [ls_d.eq(row_start), ls_a.eq(ls_d), line_start_q.eq(ls_a)]
            m.d.comb += out.payload.line_start.eq(line_start_q)

        lane_ok, consistent, any_consistent = self._lr_lanes(m, take, advance, beat, rows_per_beat)

        # The beat on the stream: each lane's word by its (row, loaded column).
        prior_nm = p.feedback_nomatch_word if neighbour else one
        beta = gamma = 0
        if lr is not None:
            q = lr.table(p.word_bits)
            beta, gamma = int(q.values[1]), int(q.nomatch[0])
        unused = range(n_beats, 1 << len(beat_q))  # never occur; in the last case for a complete case
        with m.Switch(beat_q):
            for b in range(n_beats):
                with m.Case(b, *(unused if b == n_beats - 1 else ())):
                    for lane in range(p.words_per_beat):
                        row = b * rows_per_beat + lane // lc
                        col = lane % lc
                        if row > dmax + 1:
                            word: object = 0  # past the last operator: the machine ignores it
                        elif col < off:
                            if not neighbour:
                                word = one  # loaded prior: uniform
                            elif row <= dmax:
                                word = Mux(above_valid, prior_data[lane // lc], one)
                            else:
                                word = Mux(above_valid, prior_nm, one)
                        elif row <= dmax and col == off + 4:  # census-lr: the consistency column
                            word = Mux(consistent[lane // lc], one, beta)
                        elif row <= dmax:
                            word = lane_data[lane]
                            if self._right_pass:  # a lane past the last output column never fires
                                word = Mux(lane_ok[lane // lc], word, 0)
                        elif self._right_pass and not self._right_nomatch:
                            word = 0  # the right pass has no no-match row
                        elif col == off:
                            word = nm_port.data
                        elif col == off + 3:
                            word = census_nm
                        elif col == off + 4:
                            word = Mux(any_consistent, gamma, one) if lr.has_nomatch else 0
                        else:
                            word = one
                        m.d.comb += words[lane].eq(word)
        return m

    def _lr_lanes(self, m: Module, take: Value, advance: Value, beat: Value,
                  rows_per_beat: int) -> tuple[list[Value], list[Value], Value]:
        """census-lr's per-lane flags, aligned with the beat on the stream (registered on ``advance``
        as the table look-ups are: issue, address, data). Right pass: whether lane row j of the beat
        pairs with a left pixel inside the output region (row + flush <= Dmax). Left pass: whether
        lane row j's word is 1.0 (its right MAP consistent, or with ``lr_neutral`` none), and whether
        any lane is consistent (the no-match row's word)."""
        dmax = self._model.dmax
        n_beats = self._params.beats_per_pixel
        pix = self.pixel.payload
        lane_ok: list[Value] = []
        consistent: list[Value] = []
        any_q: Value = Const(0)

        def pipeline(value: Value, name: str) -> Signal:
            stages = [Signal(name=f"{name}_{s}") for s in "daq"]
            with m.If(advance):
                m.d.sync += [stages[0].eq(value), stages[1].eq(stages[0]), stages[2].eq(stages[1])]
            return stages[2]

        if self._right_pass:
            flush = Signal.like(pix.flush)
            with m.If(take):
                m.d.sync += flush.eq(pix.flush)
            for j in range(rows_per_beat):
                row = beat * rows_per_beat + j
                lane_ok.append(pipeline(row + flush <= dmax, f"lane_ok{j}"))
        lr = self._model.column(Consistency)
        if lr is not None:
            from .lr import ConsistencyTest

            m.submodules.consistency = test = ConsistencyTest(dmax=dmax, map_width=self._params.map_width,
                                                              tolerance=lr.tolerance)
            shift = take & pix.consult
            m.d.comb += [test.shift.eq(shift), test.entry.eq(self.right_map.payload),
                         self.right_map.ready.eq(shift)]
            # Padded with 0 to every row a beat can reach (rows past Dmax are not read).
            # A lane reading a right pixel without a MAP is neutral (factor 1) with lr_neutral.
            one_bits = test.consistent | test.unknown if lr.neutral else test.consistent
            bits = Cat(one_bits, Const(0, n_beats * rows_per_beat))
            for j in range(rows_per_beat):
                consistent.append(pipeline(bits.bit_select(beat * rows_per_beat + j, 1), f"consistent{j}"))
            any_q = pipeline(test.any, "any_consistent")
        return lane_ok, consistent, any_q

    def _above_prior(self, m: Module, take: Value, advance: Value, beat: Value,
                     address: object, table_memory: object, rows_per_beat: int,
                     prior_data: dict[int, object]) -> Signal:
        """The neighbour prior's line of MAPs and its look-ups: fills ``prior_data`` (lane row j ->
        the prior table's word at min(|row - MAP above|, last)); returns whether the pixel above
        (of the beat on the stream) is a disparity."""
        p = self._params
        wo = self._output_columns
        assert wo is not None
        pix = self.pixel.payload
        above_layout = data.StructLayout({"map": unsigned(p.map_width), "hit": unsigned(1)})
        m.submodules.above_line = line = memory.Memory(shape=above_layout, depth=wo, init=[])
        wr = line.write_port()
        rd = line.read_port()  # not transparent: a result written this cycle is read the next
        wr_ptr = Signal(range(wo))
        rd_ptr = Signal(range(wo))
        m.d.comb += [wr.en.eq(self.result_take), wr.addr.eq(wr_ptr),
                     wr.data.map.eq(self.result_map), wr.data.hit.eq(self.result_hit)]
        with m.If(self.result_take):
            m.d.sync += wr_ptr.eq(Mux(wr_ptr == wo - 1, 0, wr_ptr + 1))
        out_take = take & pix.output
        m.d.comb += [rd.en.eq(out_take), rd.addr.eq(rd_ptr)]
        with m.If(out_take):
            m.d.sync += rd_ptr.eq(Mux(rd_ptr == wo - 1, 0, rd_ptr + 1))
        with m.If(self.frame_reset):  # (both are back at 0 after whole rows; said, not assumed)
            m.d.sync += [wr_ptr.eq(0), rd_ptr.eq(0)]
        first_row = Signal()
        with m.If(take):
            m.d.sync += first_row.eq(pix.first_row)
        # The read data holds from the cycle after the take until the next output pixel's take (in
        # the cycle of this pixel's last issue), so each issue sees this pixel's MAP above.
        hit = ~first_row & rd.data.hit
        hit_d, hit_a, hit_q = Signal(), Signal(), Signal()
        with m.If(advance):
            m.d.sync += [hit_d.eq(hit), hit_a.eq(hit_d), hit_q.eq(hit_a)]
        table = p.feedback_words  # the quantized prior clamped where it stops changing
        mem = table_memory("prior", table)
        for j in range(rows_per_beat):
            port = mem.read_port()
            row = beat * rows_per_beat + j
            m.d.comb += [port.en.eq(advance),
                         port.addr.eq(address(row - rd.data.map, len(table), f"prior_{j}"))]
            prior_data[j] = port.data
        return hit_q
