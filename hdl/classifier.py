"""The classifier top: a naive-Bayes classifier's likelihood memories addressed by the observation, in
front of the unchanged machine (docs/classifier.md, "On chip").

The fused layout of ``bayesmachine.classify.machine`` (one energy column, the default): per feature j a
likelihood memory of ``bins`` rows, row t holding every class's energy code of "feature j in bin t"
(``energy_codes`` of ``P(bin | class)``, 8 bits), and the prior's codes in a register row. An
observation (every feature's bin) reads each memory at its bin; per class the codes are summed,
``S_c = prior_c + sum_j E_j[c, bin_j]``, the least sum subtracted, and the differences go to the machine
as it loads them: the stochastic machine's words ``X[min(S_c - S_min, len(X) - 1)]`` through one exp
table (``exp_table(W)``), the log machine's codes ``min(S_c - S_min, INFINITE_CODE - 1)``. The machine
(``params.kind.machine_top``) and its result stream are unchanged. Its twin is
``ClassifierMachine.entries`` (the words) and ``ClassifierMachine.run`` (the decisions).

Ports: ``load``, one stream of beats in order (:func:`beat_layout`): a table row (``table`` set:
``feature`` j < features and ``bin`` t, the row of memory j; ``feature == features``, the prior's) or an
observation (``table`` clear: every feature's bin, one decision), so a table row takes effect for every
observation after it, and one bitstream serves any task of its size; ``result``, the machine's. A
decision takes four clocks to form (take, sum, least, words) plus one per further load beat of the
machine; the machine's own double buffer overlaps the next decision's forming with a run.
"""

from __future__ import annotations

from amaranth import Module, Mux, Signal, unsigned
from amaranth.lib import data, memory, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.columns.energy import ENERGY_MAX_BITS, INFINITE_CODE, exp_table
from bayesmachine.errors import ParameterError
from bayesmachine.params import MachineParams

from .signatures import beat_words, result_layout

__all__ = ["ClassifierTop", "beat_layout", "classifier_signature", "observation_layout", "table_layout"]

CODE_BITS = ENERGY_MAX_BITS  # a table's energy codes (saturated at 255)


def _bits(n: int) -> int:
    return max(1, (n - 1).bit_length())


def table_layout(classes: int, features: int, bins: int) -> data.StructLayout:
    """A table row of the load stream: memory ``feature``'s row ``bin`` (``feature == features``: the
    prior's)."""
    return data.StructLayout({"feature": unsigned(_bits(features + 1)), "bin": unsigned(_bits(bins)),
                              "codes": data.ArrayLayout(unsigned(CODE_BITS), classes)})


def observation_layout(features: int, bins: int) -> data.ArrayLayout:
    """One decision's observation: every feature's bin, feature 0 from bit 0."""
    return data.ArrayLayout(unsigned(_bits(bins)), features)


def beat_layout(classes: int, features: int, bins: int) -> data.StructLayout:
    """One beat of the top's ``load`` stream: ``table`` set, a table row; clear, an observation."""
    return data.StructLayout({"table": unsigned(1), "data": data.UnionLayout({
        "row": table_layout(classes, features, bins), "bins": observation_layout(features, bins)})})


def classifier_signature(params: MachineParams, features: int, bins: int) -> wiring.Signature:
    """The top's ports (``load`` in, ``result`` out), without building it (the Verilator harness's)."""
    return wiring.Signature({
        "load": In(stream.Signature(beat_layout(params.rows, features, bins))),
        "result": Out(stream.Signature(result_layout(params))),
    })


class ClassifierTop(wiring.Component):
    """The classifier top (module text).

    Parameters
    ----------
    params : MachineParams
        The machine of a fused classifier of one energy column (``classify.machine.classifier_params``
        with ``fuse=1``): rows = classes, one operator column, no prior column, no no-match row.
    features : int
        The features (memories), >= 1.
    bins : int
        The rows of each memory (the most bins of a feature), 1 .. 256.

    Attributes
    ----------
    load : ``In(stream.Signature(beat_layout(classes, features, bins)))``
    result : ``Out(stream.Signature(result_layout(params)))``
    params, features, bins : as given (read-only).
    """

    def __init__(self, *, params: MachineParams, features: int, bins: int) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"ClassifierTop takes a MachineParams, not {type(params).__name__}")
        if (params.columns, params.prior, params.nomatch_row) != (1, "uniform", False):
            raise ParameterError("params: the classifier top holds one fused energy column (columns 1, "
                                 "prior 'uniform', no no-match row: classifier_params(fuse=1))", "params")
        self._params = params
        self._features = as_int("features", features, 1)
        self._bins = as_int("bins", bins, 1, 256)
        super().__init__(classifier_signature(params, self._features, self._bins))

    params = property(lambda self: self._params)
    features = property(lambda self: self._features)
    bins = property(lambda self: self._bins)

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p, f, c = self._params, self._features, self._params.rows
        codes = data.ArrayLayout(unsigned(CODE_BITS), c)
        m.submodules.machine = machine = p.kind.machine_top(p)
        wiring.connect(m, machine.result, wiring.flipped(self.result))

        beat, row = self.load.payload, self.load.payload.data.row
        taken = self.load.valid & self.load.ready
        writing = taken & beat.table
        taking = Signal()  # an observation is taken this clock: the memories read at its bins
        m.d.comb += taking.eq(taken & ~beat.table)
        reads = []
        for j in range(f):
            m.submodules[f"likelihood{j}"] = mem = memory.Memory(shape=codes, depth=self._bins, init=[])
            w, r = mem.write_port(), mem.read_port()
            m.d.comb += [w.addr.eq(row.bin), w.data.eq(row.codes), w.en.eq(writing & (row.feature == j)),
                         r.addr.eq(beat.data.bins[j]), r.en.eq(taking)]
            reads.append(r.data)
        prior = Signal(codes)
        with m.If(writing & (row.feature == f)):
            m.d.sync += prior.eq(row.codes)

        sum_shape = unsigned(CODE_BITS + _bits(f + 2))
        sums = Signal(data.ArrayLayout(sum_shape, c))
        entries = Signal(data.ArrayLayout(unsigned(p.memory_word_width), c))
        sent = Signal(range(p.beats_per_pixel))
        lanes = p.words_per_beat
        words = beat_words(p, machine.load.payload)
        with m.FSM():
            with m.State("idle"):
                m.d.comb += self.load.ready.eq(1)
                with m.If(taking):
                    m.next = "sum"
            with m.State("sum"):  # the memories' rows of the observation's bins
                for k in range(c):
                    m.d.sync += sums[k].eq(sum((reads[j][k] for j in range(f)), prior[k]))
                m.next = "least"
            with m.State("least"):
                m.d.sync += [entries[k].eq(e) for k, e in enumerate(self._entries(m, sums, sum_shape))]
                m.d.sync += sent.eq(0)
                m.next = "send"
            with m.State("send"):
                m.d.comb += machine.load.valid.eq(1)
                for lane in range(lanes):
                    for b in range(p.beats_per_pixel):
                        o = b * lanes + lane
                        if o < c:
                            with m.If(sent == b):
                                m.d.comb += words[lane].eq(entries[o])
                with m.If(machine.load.ready):
                    m.d.sync += sent.eq(sent + 1)
                    with m.If(sent == p.beats_per_pixel - 1):
                        m.next = "idle"
        return m

    def _entries(self, m: Module, sums: data.View, shape: object) -> list:
        """Each class's loaded entry from its sum: the exp table read at its clamped distance above the
        least sum (words), or the clamped distance itself (codes)."""
        c = self._params.rows
        low = _minimum(m, [sums[k] for k in range(c)], shape)
        if self._params.kind.loads != "words":
            return [_clamped(m, sums[k] - low, INFINITE_CODE - 1, shape) for k in range(c)]
        table = exp_table(self._params.word_bits)
        m.submodules.exp_table = x = memory.Memory(shape=unsigned(self._params.memory_word_width),
                                                   depth=table.size, init=[int(v) for v in table])
        out = []
        for k in range(c):
            r = x.read_port(domain="comb")
            m.d.comb += r.addr.eq(_clamped(m, sums[k] - low, table.size - 1, shape))
            out.append(r.data)
        return out


def _minimum(m: Module, values: list, shape: object) -> Signal:
    """The least of ``values``: a balanced tree of comparisons."""
    level = list(values)
    while len(level) > 1:
        nxt = []
        for a, b in zip(level[0::2], level[1::2], strict=False):
            s = Signal(shape)
            m.d.comb += s.eq(Mux(b < a, b, a))
            nxt.append(s)
        level = nxt + ([level[-1]] if len(level) % 2 else [])
    return level[0]


def _clamped(m: Module, value: object, top: int, shape: object) -> Signal:
    """``min(value, top)`` (``value`` >= 0, of ``shape``)."""
    s = Signal(shape)
    m.d.comb += s.eq(value)
    out = Signal(range(top + 1))
    m.d.comb += out.eq(Mux(s > top, top, s))
    return out
