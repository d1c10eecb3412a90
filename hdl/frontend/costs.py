"""Costs and likelihood-memory words: the right features' delay line and the table look-ups.

``WordGenerator`` takes every pixel's features (left and right sums, and whether the pixel is
in the output region). Each pixel's right features enter a delay line of Dmax + 1 pixels, so
that when an output pixel at map column x arrives, entry d holds the right features at x - d.
For an output pixel it then writes the pixel's ``words_per_pixel`` words, ``lanes`` per beat,
in operator order (word o in lane o % lanes of beat o // lanes), exactly the words
``host.likelihoods.memory_words`` computes (its twin):

- row d <= Dmax, feature column f: the table of f at min(|left_f - right_f[d]|, last entry);
- the no-match row: the no-match table at min(|left gV|, last entry), then words of 1.0;
- with a loaded prior, operator column 0 is 1.0 (a uniform prior), as the host writes it.

``lanes`` must be a multiple of the operator columns, so each lane always holds the same
operator column: a lane of feature f reads its own port of f's table. One beat per cycle, in
a four-step pipeline that stalls as a whole while the stream does: in the cycle of the beat's
issue each lane's difference goes into a register; its absolute value, clamped, into the
address register in the next; the look-up (block RAM read) in the next; the beat on the stream
the one after. The registers keep the subtraction (on the left sums' wide fan-out), the
absolute value and clamp, and the long route to the block RAM apart. The difference's operands
are registers: the left sums, and per lane the delay-line entry of the
beat, chosen a cycle ahead (beat 0's when the pixel is taken, the next beat's at each issue), so
no path runs from the beat counter through the entry multiplexer into a table address. The delay
line shifts a cycle after the take (from a register holding the taken right features), its
enables on registered copies of the take, so the take (which depends on the stream's ready)
drives only the entry registers and the left sums, not the delay line's thousands of enables.
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, memory, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.signatures import load_stream
from bayesmachine.likelihood import ModelParams, check_disparity_machine
from bayesmachine.params import MachineParams, ParameterError

from .filters import feature_layout
from .tables import FrontEndTables, frontend_tables

__all__ = ["FEATURES", "WordGenerator", "check_frontend_params", "check_frontend_types",
           "pixel_features_layout"]

FEATURES = ("m25", "gh20", "gv20")  # feature sum fields, in the operator columns' order


def pixel_features_layout() -> data.StructLayout:
    """One pixel for the word generator: both images' feature sums and the output-region flag."""
    return data.StructLayout({"left": feature_layout(), "right": feature_layout(), "output": unsigned(1)})


def check_frontend_types(params: object, model: object) -> None:
    """``TypeError`` unless ``params`` is a ``MachineParams`` and ``model`` a ``ModelParams``."""
    if not isinstance(params, MachineParams):
        raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
    if not isinstance(model, ModelParams):
        raise TypeError(f"model must be a host.likelihoods.ModelParams, not {type(model).__name__}")


def check_frontend_params(params: MachineParams, model: ModelParams) -> None:
    """``ParameterError`` naming the parameter unless the front end can feed this machine this model."""
    if not isinstance(params, MachineParams):
        raise ParameterError(f"params must be a MachineParams, not {type(params).__name__}")
    if not isinstance(model, ModelParams):
        raise ParameterError(f"model must be a host.likelihoods.ModelParams, not {type(model).__name__}")
    if model.census:
        raise ParameterError("--model: the on-chip front end computes the paper model only (census: not yet)")
    if params.feedback_columns:
        # Its words are one data column short and the beats carry no line_start flags.
        raise ParameterError(
            "prior: the on-chip front end does not feed a machine with prior = 'neighbour' (its feedback "
            "column and line_start flags); use prior = 'loaded' or 'uniform' with --feed pixels")
    check_disparity_machine(model, params)
    if params.lanes % params.operator_columns:
        raise ParameterError(
            f"lanes ({params.lanes}) must be a multiple of the operator columns ({params.operator_columns}) "
            f"for the front end, so that each lane holds one feature (e.g. lanes="
            f"{min(params.words_per_pixel, 6 * params.operator_columns)})")


class WordGenerator(wiring.Component):
    """Pixel features in, the output pixels' likelihood-memory words out (the machine's load beats).

    ``pixel.ready`` is high when no output pixel is being written, and in the cycle of its last
    beat's issue: a pixel outside the output region passes in one cycle, an output pixel holds
    the stream for ``beats_per_pixel`` cycles (more if ``beats`` is not ready).

    Parameters
    ----------
    params : MachineParams
        The machine fed (``lanes`` a multiple of the operator columns: :func:`check_frontend_params`).
    model : ModelParams
        The disparity model (Dmax, p0, sigmas, p_nm0, sigma_nm).
    tables : FrontEndTables, optional
        The likelihood tables (default: ``frontend_tables(model, params.word_bits)``).

    Attributes
    ----------
    pixel : ``In(stream.Signature(pixel_features_layout()))``
        Every pixel of the frame in raster order (the right features of all of them enter the
        delay line).
    beats : ``Out(load_stream(params))``
        ``beats_per_pixel`` beats per pixel whose ``output`` flag is set.
    """

    def __init__(self, *, params: MachineParams, model: ModelParams,
                 tables: FrontEndTables | None = None) -> None:
        check_frontend_types(params, model)
        check_frontend_params(params, model)
        if tables is not None and not isinstance(tables, FrontEndTables):
            raise TypeError(f"tables must be a FrontEndTables, not {type(tables).__name__}")
        self._params = params
        self._model = model
        self._tables = tables if tables is not None else frontend_tables(model, params.word_bits)
        super().__init__({
            "pixel": In(stream.Signature(pixel_features_layout())),
            "beats": Out(load_stream(params)),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def tables(self) -> FrontEndTables:
        return self._tables

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p, dmax = self._params, self._model.dmax
        cols = p.operator_columns
        off = cols - p.columns  # 1 with a loaded prior (operator column 0)
        rows_per_beat = p.lanes // cols
        n_beats = p.beats_per_pixel
        one = p.word_one

        # Delay line: right[d] = right features d pixels back (reset-less: no output reads a
        # stale entry, since an output pixel is at least Dmax pixels into its line).
        right = [Signal(feature_layout(), name=f"right_{d}", reset_less=True) for d in range(dmax + 1)]
        left = Signal(feature_layout(), reset_less=True)
        active = Signal()  # writing the words of an output pixel
        beat = Signal(range(max(2, n_beats)))
        beat_d = Signal(range(max(2, n_beats)))  # the beat in the difference registers
        diff_valid = Signal()
        beat_a = Signal(range(max(2, n_beats)))  # the beat in the address registers
        addr_valid = Signal()
        beat_q = Signal(range(max(2, n_beats)))  # the beat on the stream

        out = self.beats
        advance = Signal()  # the look-up pipeline (address registers, table reads, stream) moves
        issue = Signal()
        m.d.comb += [advance.eq(~out.valid | out.ready), issue.eq(active & advance)]
        last = beat == n_beats - 1
        m.d.comb += self.pixel.ready.eq(~active | (issue & last))
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
        right_in = Signal(feature_layout(), reset_less=True)
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

        # Each lane's delay-line entry comes from a register loaded a cycle ahead (the beat
        # counter's multiplexer ends there, not at the table address): with beat 0's entry when
        # a pixel is taken (the line as it is after the shift), with the next beat's on an issue.
        lane_data: dict[int, object] = {}
        for f, name in enumerate(FEATURES):
            table = self._tables.feature(f)
            mem = memory.Memory(shape=unsigned(p.memory_word_width), depth=len(table), init=table.tolist())
            m.submodules[f"table_{name}"] = mem
            for j in range(rows_per_beat):
                def entry(d: int, name: str = name) -> object:
                    # Entry d of the line as the words see it (a pending shift included).
                    seen = right_in if d == 0 else right[d - 1]
                    return Mux(shift_q, getattr(seen, name), getattr(right[d], name))

                entries = [getattr(right[min(b * rows_per_beat + j, dmax)], name) for b in range(n_beats)]
                sel = Signal(entries[0].shape(), name=f"right_{name}_{j}", reset_less=True)
                with m.If(take):
                    d = min(j, dmax)  # entry d after the take is entry d - 1 now
                    m.d.sync += sel.eq(getattr(self.pixel.payload.right, name) if d == 0 else entry(d - 1))
                with m.Elif(issue):
                    with m.Switch(beat):
                        if n_beats > 1:  # beat 0: the only one issued with a shift pending
                            with m.Case(0):
                                m.d.sync += sel.eq(entry(min(rows_per_beat + j, dmax)))
                        for b in range(1, n_beats - 1):
                            with m.Case(b):
                                m.d.sync += sel.eq(entries[b + 1])
                        with m.Default():  # the last beat: the next take reloads it; a complete case
                            m.d.sync += sel.eq(entries[-1])
                port = mem.read_port()
                m.d.comb += [port.en.eq(advance),
                             port.addr.eq(address(getattr(left, name) - sel, len(table), f"{name}_{j}"))]
                lane_data[j * cols + off + f] = port.data
        nm_table = self._tables.nomatch
        nm_mem = memory.Memory(shape=unsigned(p.memory_word_width), depth=len(nm_table),
                               init=nm_table.tolist())
        m.submodules.table_nomatch = nm_mem
        nm_port = nm_mem.read_port()
        m.d.comb += [nm_port.en.eq(advance),
                     nm_port.addr.eq(address(left.gv20, len(nm_table), "nomatch"))]

        # The beat on the stream: each lane's word by its operator (row, column).
        unused = range(n_beats, 1 << len(beat_q))  # never occur; in the last case for a complete case
        with m.Switch(beat_q):
            for b in range(n_beats):
                with m.Case(b, *(unused if b == n_beats - 1 else ())):
                    for lane in range(p.lanes):
                        row = b * rows_per_beat + lane // cols
                        col = lane % cols
                        if row > dmax + 1:
                            word: object = 0  # past the last operator: the machine ignores it
                        elif col < off:
                            word = one  # loaded prior: uniform
                        elif row <= dmax:
                            word = lane_data[lane]
                        elif col == off:
                            word = nm_port.data
                        else:
                            word = one
                        m.d.comb += out.payload[lane].eq(word)
        return m
