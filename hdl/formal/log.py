"""The log integrator's blocks (``hdl.log``) against references written here, for every input and
every back-pressure.

``PipelineProperties`` puts a block (any ``StallPipeline``: the row adders, the argmin tree, the
weights stage) beside a *reference line* that follows the pipeline's
timing rule (``hdl.log.pipeline``, docs/integrators.md): ``latency - 1`` slots moving on a ``go``
register that says the line's skid is empty, then a head and a skid; each slot holds a pixel's
expected result, computed when the pixel is taken by a reference written here from the rule alone:

- the argmin: a sequential scan over the rows (a row not excluded replaces the best one so far
  when its sum is lower, or, for the no-match row under ``nomatch-first``, not higher); with
  feedback codes, over the sums with the codes added;
- the row adders: a chain of additions, and an OR of "code is all-ones";
- the weights: per row a chain of equality tests against each distance of the table.

The input stream, ``ready`` of the output and the reset are free (no assumption at all: the block
takes whatever is offered when it is ready). Asserted on the ports: the block takes a pixel exactly
when the reference line does, offers a result exactly when it does, and that result is the
reference's (so every pixel taken comes out once, in order, with its result); a result offered and
not taken is offered again unchanged; the pixels taken and not yet given out are those the line
holds, at most ``latency + 1``; with ``ready`` high the block takes a pixel every clock.
Strengthening invariants, read through the nets its builder returns (``StallPipeline.build``): each
stage's ``valid`` and the skid's are the reference's, every copy of ``go`` is the reference's, and each
valid stage's registers, finished by the block's remaining stages (``StallPipeline.remaining``), and the
skid give the reference's results.

``IntegratorProperties`` checks the whole ``LogIntegrator`` (the blocks as it builds them, the issue
register and the feedback column formed from the argmin tree's latest result between them) from its
ports against a scoreboard of expected results (:func:`reference_chain`, the feedback codes by the rule
from the previous pixel's expected result), bounded from reset: its parts are proved above, the chain
they make is checked to a depth.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from amaranth.hdl import Array, Assert, Const, Cover, Module, Mux, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.log import LogIntegrator, LogParams
from bayesmachine.hdl.log.pipeline import StallPipeline

__all__ = ["IntegratorProperties", "PipelineProperties", "Reference", "chain_sums", "integrator_params",
           "reference_argmin", "reference_chain", "reference_feedback_argmin", "reference_row_sums",
           "reference_weights", "scan_argmin", "table_weight"]

# ``reference(m, params, payload, out)``: drives the fields of ``out`` (a Signal of the block's
# output layout, comb) from the input ``payload`` (a view of the block's input layout).
Reference = Callable[[Module, LogParams, data.View, data.View], None]


def _net(m: Module, value: Value, name: str) -> Signal:
    net = Signal(Value.cast(value).shape(), name=name)
    m.d.comb += net.eq(value)
    return net


def scan_argmin(m: Module, p: LogParams, sums: list[Value], excluded: list[Value]
                ) -> tuple[Value, Value, Value, Value]:
    """The rule's MAP by a sequential scan: ``(map, nomatch, all_excluded, s_min)``."""
    best, best_sum, found = Const(0, p.map_width), Const(0, p.sum_bits), Const(0, 1)
    for r in range(p.rows):
        nomatch_tie = p.nomatch_first and r == p.rows - 1
        lower = (sums[r] <= best_sum) if nomatch_tie else (sums[r] < best_sum)
        take = _net(m, ~excluded[r] & (~found | lower), f"scan_take{r}")
        best = _net(m, Mux(take, r, best), f"scan_best{r}")
        best_sum = _net(m, Mux(take, sums[r], best_sum), f"scan_sum{r}")
        found = _net(m, found | ~excluded[r], f"scan_found{r}")
    map_ = Mux(found, best, p.none_index)
    nomatch = (map_ == p.rows - 1) if p.nomatch_row else Const(0, 1)
    return map_, nomatch, ~found, Mux(found, best_sum, 0)


def reference_argmin(m: Module, p: LogParams, payload: data.View, out: data.View) -> None:
    sums = [payload.sums[r] for r in range(p.rows)]
    map_, nomatch, none, s_min = scan_argmin(m, p, sums, [payload.excluded[r] for r in range(p.rows)])
    m.d.comb += [out.map.eq(map_), out.nomatch.eq(nomatch), out.all_excluded.eq(none), out.s_min.eq(s_min)]
    if "sums" in out.shape().members:
        m.d.comb += [out.sums.eq(payload.sums), out.excluded.eq(payload.excluded)]


def reference_feedback_argmin(m: Module, p: LogParams, payload: data.View, out: data.View) -> None:
    """``ArgminTree(feedback=True)``: the scan over each row's sum plus its feedback code (cut to
    ``sum_bits``), a row excluded by its flag or an all-ones feedback code."""
    sums = [_net(m, (payload.sums[r] + payload.feedback[r])[:p.sum_bits], f"ref_total{r}")
            for r in range(p.rows)]
    excluded = [payload.excluded[r] | (payload.feedback[r] == p.infinite) for r in range(p.rows)]
    map_, nomatch, none, s_min = scan_argmin(m, p, sums, excluded)
    m.d.comb += [out.map.eq(map_), out.nomatch.eq(nomatch), out.all_excluded.eq(none), out.s_min.eq(s_min)]
    if "sums" in out.shape().members:
        m.d.comb += [out.sums[r].eq(x) for r, x in enumerate(sums)]
        m.d.comb += [out.excluded[r].eq(x) for r, x in enumerate(excluded)]


def chain_sums(p: LogParams, codes: data.View) -> tuple[list[Value], list[Value]]:
    """Each row's sum (left to right) and whether one of its codes is all-ones."""
    sums, excluded = [], []
    for r in range(p.rows):
        total, infinite = Const(0, p.sum_bits), Const(0, 1)
        for c in range(p.codes):
            total = (total + codes[r][c])[:p.sum_bits]
            infinite = infinite | (codes[r][c] == (1 << p.code_bits) - 1)
        sums.append(total)
        excluded.append(infinite)
    return sums, excluded


def reference_row_sums(m: Module, p: LogParams, payload: data.View, out: data.View) -> None:
    if "carried" in out.shape().members:  # RowAdders(carried=): the bits come out unchanged
        m.d.comb += out.carried.eq(payload.carried)
        payload = payload.codes
    sums, excluded = chain_sums(p, payload)
    m.d.comb += [out.sums[r].eq(s) for r, s in enumerate(sums)]
    m.d.comb += [out.excluded[r].eq(x) for r, x in enumerate(excluded)]


def table_weight(p: LogParams, sum_: Value, excluded: Value, s_min: Value) -> Value:
    """X at the row's distance from the least: equality tests, the last entry beyond them, X[0] below 0."""
    d = sum_ - s_min
    weight = Const(p.weights[-1], p.weight_bits)
    for e in reversed(range(len(p.weights) - 1)):
        weight = Mux(d == e, p.weights[e], weight)
    return Mux(excluded, 0, Mux(d < 0, p.weights[0], weight))


def reference_weights(m: Module, p: LogParams, payload: data.View, out: data.View) -> None:
    m.d.comb += [out.map.eq(payload.map), out.nomatch.eq(payload.nomatch),
                 out.all_excluded.eq(payload.all_excluded), out.s_min.eq(payload.s_min)]
    m.d.comb += [out.weights[r].eq(table_weight(p, payload.sums[r], payload.excluded[r], payload.s_min))
                 for r in range(p.rows)]


@dataclass
class _Line:
    """The reference line: slots (the last the head), the skid, ``go``."""

    valid: list[Signal]
    data: list[Signal]
    skid_valid: Signal
    skid: Signal
    go: Signal


class PipelineProperties(wiring.Component):
    """A formal-only wrapper: a log block against its reference line (module docstring).

    Parameters
    ----------
    params : LogParams
        The rule the reference follows.
    dut : StallPipeline
        The block under check, built from ``params`` (or a mutant, ``hdl.formal.log_mutants``).
    reference : Reference
        The result it must give for a payload: one of this module's ``reference_*``.

    Attributes
    ----------
    in_valid, in_payload, out_ready : inputs
        The input stream and the output's ``ready`` (free).
    out_valid, out_payload : outputs
        The block's output stream, for the trace.
    """

    def __init__(self, *, params: LogParams, dut: StallPipeline, reference: Reference) -> None:
        if not isinstance(params, LogParams):
            raise TypeError(f"params must be a LogParams, not {type(params).__name__}")
        self._params = params
        self._dut = dut
        self._reference = reference
        sink, source = dut.stream_names
        members = dut.signature.members
        self._in_layout = members[sink].signature.members["payload"].shape
        self._out_layout = members[source].signature.members["payload"].shape
        super().__init__({"in_valid": In(1), "in_payload": In(self._in_layout), "out_ready": In(1),
                          "out_valid": Out(1), "out_payload": Out(self._out_layout)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dut = self._dut
        m.submodules.dut, nets = dut.build(platform)  # built here: its nets are read below
        sink, source = (getattr(dut, name) for name in dut.stream_names)
        m.d.comb += [sink.valid.eq(self.in_valid), sink.payload.eq(self.in_payload),
                     source.ready.eq(self.out_ready), self.out_valid.eq(source.valid),
                     self.out_payload.eq(source.payload)]
        line = self._reference_line(m)
        self._port_properties(m, line)
        # Strengthening invariants: the block's registers are the reference line's.
        for i in range(dut.latency):
            m.d.comb += Assert(nets.valid[i] == line.valid[i], f"stage {i} holds a pixel iff slot {i} does")
            with m.If(line.valid[i]):
                finished = dut.remaining(m, i, nets.banks[i])
                m.d.comb += Assert(finished == line.data[i].as_value(), f"stage {i} finishes as slot {i}")
        m.d.comb += Assert(nets.skid_valid == line.skid_valid, "the skid holds a pixel iff the line's does")
        with m.If(line.skid_valid):
            m.d.comb += Assert(nets.skid == line.skid.as_value(), "the skid's result is the line's")
        for i, go in enumerate(nets.go):
            m.d.comb += Assert(go == line.go, f"go copy {i} is the line's go")
        # The output buffer is a two-entry FIFO: the entry read is the older one, written before the
        # other; the write pointer is past the valid entries.
        buf = nets.output
        m.d.comb += Assert(~nets.skid_valid | nets.valid[-1], "no skid without a head")
        m.d.comb += Assert((buf.write == buf.reads[0]) == (buf.entry_valid[0] == buf.entry_valid[1]),
                           "the write pointer follows the valid entries")
        for i, read in enumerate(buf.reads[1:]):
            m.d.comb += Assert(read == buf.reads[0], f"read pointer copy {i} is the pointer")
        return m

    def _reference_line(self, m: Module) -> _Line:
        """The slots (valid, expected result), the head (the last slot), the skid and ``go``."""
        expected = Signal(self._out_layout)
        self._reference(m, self._params, self.in_payload, expected)
        latency = self._dut.latency
        line = _Line(valid=[Signal(name=f"ref_valid{i}") for i in range(latency)],
                     data=[Signal(self._out_layout, name=f"ref_data{i}") for i in range(latency)],
                     skid_valid=Signal(name="ref_skid_valid"), skid=Signal(self._out_layout, name="ref_skid"),
                     go=Signal(name="ref_go", init=1))
        before_v, before_d = self.in_valid, expected
        for i in range(latency - 1):
            with m.If(line.go):
                m.d.sync += line.valid[i].eq(before_v)
                with m.If(before_v):
                    m.d.sync += line.data[i].eq(before_d)
            before_v, before_d = line.valid[i], line.data[i]
        # The last slot (the head) and the skid: an arriving result goes to the head when it is empty
        # or taken and the skid is empty, else to the skid; the skid moves up when the head frees.
        arriving = _net(m, line.go & before_v, "ref_arriving")
        head_v, head = line.valid[-1], line.data[-1]
        free = _net(m, ~head_v | self.out_ready, "ref_free")
        skid_next = Signal(name="ref_skid_next")
        with m.If(free):
            m.d.comb += skid_next.eq(line.skid_valid & arriving)
            m.d.sync += head_v.eq(line.skid_valid | arriving)
            m.d.sync += head.eq(Mux(line.skid_valid, line.skid, before_d))
            with m.If(line.skid_valid & arriving):
                m.d.sync += line.skid.eq(before_d)
        with m.Else():
            m.d.comb += skid_next.eq(line.skid_valid | arriving)
            with m.If(arriving):
                m.d.sync += line.skid.eq(before_d)
        m.d.sync += [line.skid_valid.eq(skid_next), line.go.eq(~skid_next)]
        return line

    def _port_properties(self, m: Module, line: _Line) -> None:
        dut = self._dut
        sink, source = (getattr(dut, name) for name in dut.stream_names)
        taken_in, taken_out = sink.valid & sink.ready, source.valid & source.ready
        m.d.comb += Assert(sink.ready == line.go, "takes a pixel iff the line moves")
        m.d.comb += Assert(source.valid == line.valid[-1], "offers a result iff the line's head holds one")
        with m.If(source.valid):
            m.d.comb += Assert(source.payload.as_value() == line.data[-1].as_value(),
                               "the reference's result")
        # The stream rule from the source side: a result not taken is offered again, unchanged.
        stall, prev = Signal(), Signal(self._out_layout)
        m.d.sync += [stall.eq(source.valid & ~source.ready), prev.eq(source.payload)]
        with m.If(stall):
            m.d.comb += Assert(source.valid & (source.payload.as_value() == prev.as_value()),
                               "a result offered and not taken is held")
        # One pixel per clock: a block whose output was taken in the last clock takes the next pixel.
        flowing = Signal()
        m.d.sync += flowing.eq(~source.valid | source.ready)
        with m.If(flowing):
            m.d.comb += Assert(sink.ready, "ready after a clock whose output was empty or taken")
        # Pixels in flight: taken and not given out, as many as the line holds, at most latency.
        latency = dut.latency
        inflight = Signal(range(latency + 3))
        m.d.sync += inflight.eq(inflight + taken_in - taken_out)
        m.d.comb += Assert(inflight == sum(line.valid) + line.skid_valid,
                           "pixels in flight: those the line holds")
        m.d.comb += Assert(inflight <= latency + 1, "at most latency + 1 pixels in flight")
        # Not vacuous: a full pipeline held, then a result taken after a stall; a result taken while
        # the skid holds the next.
        m.d.comb += Cover((inflight == latency) & stall & taken_out & taken_in)
        m.d.comb += Cover(line.skid_valid & taken_out)
        m.d.comb += Cover(source.valid & source.payload.as_value().any() & stall)


def integrator_params(rows: int, codes: int, code_bits: int, **kwargs: object) -> LogParams:
    """A small LogParams for a proof, with a 4-entry exp table (4, 2, 1, 0)."""
    return LogParams(rows=rows, codes=codes, code_bits=code_bits, weights=(4, 2, 1, 0),
                     **kwargs)  # type: ignore[arg-type]



def reference_chain(m: Module, p: LogParams, codes: data.View, feedback: list[Value], out: data.View) -> None:
    """``LogIntegrator``'s result of a pixel: its loaded ``codes`` summed left to right, each row's
    ``feedback`` code added (an all-ones one excludes the row; none without a feedback column), the
    scan's MAP and the table's weights."""
    loaded = replace(p, codes=p.codes - bool(feedback))
    sums, excluded = chain_sums(loaded, codes)
    if feedback:
        excluded = [x | (f == p.infinite) for x, f in zip(excluded, feedback, strict=True)]
        sums = [(s + f)[:p.sum_bits] for s, f in zip(sums, feedback, strict=True)]
    sums = [_net(m, s, f"ref_sum{r}") for r, s in enumerate(sums)]
    map_, nomatch, none, s_min = scan_argmin(m, p, sums, excluded)
    s_min = _net(m, s_min, "ref_s_min")
    m.d.comb += [out.map.eq(map_), out.nomatch.eq(nomatch), out.all_excluded.eq(none), out.s_min.eq(s_min)]
    m.d.comb += [out.weights[r].eq(table_weight(p, sums[r], excluded[r], s_min)) for r in range(p.rows)]


class IntegratorProperties(wiring.Component):
    """A formal-only wrapper: the whole ``LogIntegrator`` (the blocks and the issue between them) against
    a *scoreboard*, from its ports alone, checked bounded from reset (``bmc``).

    Each pixel taken gets its expected result at once (:func:`reference_chain`), its feedback codes
    formed by the rule (``sim.model.fill_feedback``, flat code 0) from the expected result of the pixel
    taken before it (0 at a line start and from reset), and joins the scoreboard's queue; asserted:
    a result is offered only for a pixel in the queue, and the result (and its ``line_start``) taken is
    the queue's oldest; a result offered and not taken is offered again unchanged. The input stream,
    ``ready`` of the output and the reset are free. Covers: a pixel taken with its feedback column formed
    from a MAP (another MAP its answer), a result taken after a stall with more pixels in flight.

    Parameters
    ----------
    dut : LogIntegrator
        The integrator under check (or a mutant, ``hdl.formal.log_mutants``).
    params : LogParams or None
        The rule the reference follows (default the integrator's).
    """

    QUEUE = 16  # scoreboard entries: more than the integrator holds (asserted)

    def __init__(self, *, dut: LogIntegrator, params: LogParams | None = None) -> None:
        if not isinstance(dut, LogIntegrator):
            raise TypeError(f"dut must be a LogIntegrator, not {type(dut).__name__}")
        self._dut = dut
        self._params = params or dut.params
        members = dut.signature.members
        self._in_layout = members["codes"].signature.members["payload"].shape
        self._out_layout = members["result"].signature.members["payload"].shape
        super().__init__({"in_valid": In(1), "in_payload": In(self._in_layout), "out_ready": In(1),
                          "out_valid": Out(1), "out_payload": Out(self._out_layout)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.dut = dut = self._dut
        m.d.comb += [dut.codes.valid.eq(self.in_valid), dut.codes.payload.eq(self.in_payload),
                     dut.result.ready.eq(self.out_ready), self.out_valid.eq(dut.result.valid),
                     self.out_payload.eq(dut.result.payload)]
        taken_in = dut.codes.valid & dut.codes.ready
        taken_out = dut.result.valid & dut.result.ready
        entry = data.StructLayout({"result": self._out_layout, "start": 1})
        queue = Array(Signal(entry, name=f"board{i}") for i in range(self.QUEUE))
        head, tail = Signal(range(self.QUEUE)), Signal(range(self.QUEUE))
        count = Signal(range(self.QUEUE + 1))
        expected, start = self._expected(m, taken_in)
        with m.If(taken_in):
            m.d.sync += [queue[tail].result.eq(expected), queue[tail].start.eq(start), tail.eq(tail + 1)]
        with m.If(taken_out):
            m.d.sync += head.eq(head + 1)
        m.d.sync += count.eq(count + taken_in - taken_out)
        m.d.comb += Assert(count < self.QUEUE, "the scoreboard holds every pixel in flight")
        oldest = queue[head]
        with m.If(dut.result.valid):
            m.d.comb += Assert(count > 0, "a result is offered only for a pixel taken")
            m.d.comb += Assert(dut.result.payload.as_value() == oldest.result.as_value(),
                               "the result is the oldest pixel's, by the rule")
            if dut.feedback:
                m.d.comb += Assert(dut.line_start == oldest.start, "the oldest pixel's line_start")
        stall, prev = Signal(), Signal(self._out_layout)
        m.d.sync += [stall.eq(dut.result.valid & ~dut.result.ready), prev.eq(dut.result.payload)]
        with m.If(stall):
            m.d.comb += Assert(dut.result.valid & (dut.result.payload.as_value() == prev.as_value()),
                               "a result offered and not taken is held")
        m.d.comb += Cover(stall & taken_out & (count > 1))
        return m

    def _expected(self, m: Module, taken_in: Value) -> tuple[Signal, Value]:
        """The expected result of the pixel offered (and its line_start), the feedback codes formed from
        the last pixel taken's expected result (kept on a take)."""
        p, dut = self._params, self._dut
        expected = Signal(self._out_layout)
        if not dut.feedback:
            reference_chain(m, p, self.in_payload, [], expected)
            return expected, Const(0, 1)
        start = self.in_payload.line_start
        last = Signal(data.StructLayout({"map": p.map_width, "answer": 1}))  # the last pixel's MAP, if any
        words = dut.feedback_words
        codes = []
        for r in range(p.rows):
            if p.nomatch_row and r == p.rows - 1:
                code = Const(dut.feedback_nomatch_word, p.code_bits)
            else:
                code = Const(words[-1], p.code_bits)
                for d in reversed(range(len(words) - 1)):  # the table at |r - MAP|, clamped
                    near = (last.map == r - d) | (last.map == r + d) if d else (last.map == r)
                    code = Mux(near, words[d], code)
            codes.append(_net(m, Mux(last.answer & ~start, code, 0), f"ref_feedback{r}"))
        reference_chain(m, p, self.in_payload.codes, codes, expected)
        with m.If(taken_in):
            m.d.sync += [last.map.eq(expected.map),
                         last.answer.eq(~expected.nomatch & ~expected.all_excluded)]
        m.d.comb += Cover(taken_in & ~start & last.answer & (expected.map != last.map))
        return expected, start
