"""The word generator: one pass's likelihood-memory words from its pixels' features, beat by beat.

``WordGenerator`` takes every pixel's features (both images' planes, whether the pixel is in the output
region, and the position flags its columns read: :func:`~.layouts.pass_pixel_layout`). The match image's
features enter a delay line of Dmax + 1 pixels, so that when an output pixel arrives entry d holds the
features of the pixel lane d pairs it with (the pass's reference, :mod:`.reference`: x - d for the left
image, and for a right-reference pass fed by :class:`~.passes.PassFeeder` entry Dmax - d, the left pixel
x_r + d). For an output pixel it writes ``words_per_pixel`` words, ``words_per_beat`` per beat, in load
order (word o in lane o % words_per_beat of beat o // words_per_beat, row o // loaded_columns, operator
column o % loaded_columns), exactly the words ``host.likelihoods.pass_words`` computes (its twin).

Each operator column's words come from its column kind's lane builder (:mod:`.lanes`, one per kind,
chosen from the column's class), built on the generator's shared pipeline
(:class:`~.wordpipe.WordPipeline`, which lane builders see as a :class:`~.lanes.context.LaneContext`): a
FEATURES column's table at its cost (a feature difference, a census Hamming distance), an ABOVE
column's prior from a line of the pass's own MAPs, a PASS column's consistency test of another pass's
MAPs; a FEEDBACK column is formed by the machine (its lane builder flags each beat of a row's first
output pixel ``line_start``); the machine's own loaded prior column (``prior="loaded"`` without an ABOVE
column) is 1.0. In the no-match row the pass's no-match rule (its lane builder: the floor P_nm(gV) of the
reference pixel) sits in the first FEATURES column, each other column gives its own entry; a pass without
a no-match row (``Pass.nomatch`` off) has 0 in every FEATURES column there; a lane whose match pixel lies
past the last output column (a right-reference pass's flush) is 0 in every FEATURES column.

The generator's ports are its pixel and beat streams and its lane builders' (:func:`generator_signature`:
each declared once, by the lane builder that reads it). ``words_per_beat`` must be a multiple of the
loaded columns, so each lane (word position of a beat) always holds the same operator column.
"""

from __future__ import annotations

import dataclasses

from amaranth.hdl import Module, Mux, ValueLike
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_bool, as_int
from bayesmachine.columns import Source
from bayesmachine.hdl.signatures import load_stream
from bayesmachine.models import ModelParams, Pass, check_disparity_machine, pass_machine
from bayesmachine.params import MachineParams, ParameterError

from .lanes import Lanes, lanes_for
from .layouts import declared_passes, pass_pixel_layout, pass_terms
from .reference import Reference, reference_of
from .shared import FusedShare, fused_term
from .tables import FrontEndTables, frontend_tables
from .wordpipe import WordPipeline, word_pipeline

__all__ = ["WordGenerator", "WordPipeline", "check_frontend_params", "check_frontend_types",
           "generator_signature", "pass_params"]


def generator_signature(params: MachineParams, model: ModelParams, p: Pass,
                        fused_share: FusedShare | None = None) -> wiring.Signature:
    """The ports of the word generator of ``model``'s pass ``p`` on the machine ``params``: ``pixel``
    (``In``: :func:`~.layouts.pass_pixel_layout`), ``beats`` (``Out(load_stream(params))``), each of its
    columns' lane builder's (``Lanes.members``) and with ``fused_share`` ``fused_sums``
    (``FusedShare.signature``); ``ParameterError`` naming the model when two columns of the pass would
    share one port (two line-of-MAPs columns, two columns reading one pass's MAPs)."""
    members: dict[str, wiring.Member] = {"pixel": In(stream.Signature(pass_pixel_layout(model, p))),
                                         "beats": Out(load_stream(params))}
    owner: dict[str, str] = {}
    for c in p.columns:
        for name, member in lanes_for(c).members(c, params).items():
            if name in members:
                raise ParameterError(f"model: the {p.name} pass's {c.name} column takes the port {name}, "
                                     f"which its {owner.get(name, 'word generator')} has already: a word "
                                     "generator feeds one column from each stream", "model")
            members[name], owner[name] = member, f"{c.name} column"
    if fused_share is not None:
        members["fused_sums"] = Out(fused_share.signature())
    return wiring.Signature(members)


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
    for term in pass_terms(p):
        lanes_for(term).check(term, model, p)
    generator_signature(params, model, p)
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
    check_frontend_types(params, model)
    names = [p.name for p in model.passes]
    for name in names:  # a pass's name names its ports
        if not name.isidentifier() or names.count(name) > 1:
            raise ParameterError(f"model: the {model.name} model's passes need distinct names that can name "
                                 f"ports, got {', '.join(names)}", "model")
    _check_pass(model, model.passes[-1], params)
    for p in declared_passes(model):
        if params.takes_numbers:
            raise ParameterError(f"rng must be an on-chip random source for the {model.name} model on chip, "
                                 f"got {params.rng!r}: its {p.name} pass runs on a machine of its own, "
                                 "which has no entropy port", "rng")
        _check_pass(model, p, pass_params(model, params, p.name))


def pass_params(model: ModelParams, params: MachineParams, name: str) -> MachineParams:
    """The machine on chip of ``model``'s pass ``name`` when its own pass runs on ``params``: ``params``
    for the own pass; for a declared one :func:`~bayesmachine.models.pass_machine` with the own pass's
    rows per beat (``params.words_per_beat // params.loaded_columns``, at most the pass's rows) times its
    loaded columns, so that every pass takes a pixel in as many beats (the default: the front end's 6 rows,
    :func:`~bayesmachine.params.stereo_words_per_beat`; words per beat change no result)."""
    p = model.pass_named(name)
    if p is model.passes[-1]:
        return params
    machine = pass_machine(model, params, name)
    rows = max(1, min(params.words_per_beat // params.loaded_columns, machine.rows))
    return dataclasses.replace(machine, words_per_beat=rows * machine.loaded_columns)


def _check_fused_share(model: ModelParams, p: Pass, params: MachineParams,
                       share: object) -> FusedShare | None:
    """``share`` if pass ``p`` on ``params`` can take that part in sharing its fused sums (a fused column,
    the role of its reference, its rows per beat and beats; an importer's pixels carry ``row_start``)."""
    if share is None:
        return None
    if not isinstance(share, FusedShare):
        raise TypeError(f"fused_share must be a FusedShare, not {type(share).__name__}")
    role = "export" if reference_of(p).swaps else "import"
    rows = params.words_per_beat // params.loaded_columns
    problems = [
        *(["a fused column"] if fused_term(p) is None else []),
        *([f"role {role!r} (its reference)"] if share.role != role else []),
        *([f"{rows} rows per beat and {params.beats_per_pixel} beats"]
          if (share.rows, share.beats) != (rows, params.beats_per_pixel) else []),
        *(["pixels that carry row_start"] if role == "import"
          and "row_start" not in pass_pixel_layout(model, p).members else []),
    ]
    if problems:
        raise ParameterError(f"fused_share: the {p.name} pass needs {', '.join(problems)}", "fused_share")
    return share


def _check_output_columns(p: Pass, output_columns: object) -> int | None:
    if output_columns is not None:
        output_columns = as_int("output_columns", output_columns)
    # An ABOVE column reads a line of the pass's own MAPs, a semi-global column keeps the row above's path
    # costs (Lanes.needs_row): their length is the output row's.
    line = [c.name for c in p.columns if lanes_for(c).needs_row(c)]
    if line and (output_columns is None or output_columns < 1):
        raise ParameterError(f"output_columns: the {line[0]} column needs the output pixels "
                             f"per row (>= 1), got {output_columns!r}", "output_columns")
    if not line and output_columns is not None:
        raise ParameterError(f"output_columns: only for a pass with a line of MAPs (an ABOVE column) or a "
                             f"semi-global column; the {p.name} pass of the {p.model.name} model has none",
                             "output_columns")
    return output_columns


class WordGenerator(wiring.Component):
    """Pixel features in, one pass's output pixels' likelihood-memory words out (the machine's load beats).

    ``pixel.ready`` is high when no output pixel is being written, and in the cycle of its last
    beat's issue: a pixel outside the output region passes in one cycle, an output pixel holds the
    stream for ``beats_per_pixel`` cycles (more if ``beats`` is not ready, or while a lane builder
    holds it: an ABOVE column until the result above has left the machine, a PASS column until the
    MAP it reads is in). A fused column's pass scans an output pixel's beats before its words issue, the
    next pixels' scans beside the current one's issues: the stream's pixels wait in a ring of registers
    for their scans (``beats_per_pixel`` + 6 cycles: ``Lanes.scan_latency``) and then for the previous
    pixel's last issue; its ``pixel.ready`` is that of the ring (a free slot) and of the scan (an output
    pixel's scan starts in the cycle of the previous one's last fetch), so in steady state an output pixel
    is taken every ``beats_per_pixel`` cycles. At two beats or more per pixel an output pixel is not taken
    in the cycle after a take (a cycle at a line's first output pixel: ``WordPipeline.accept``).

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
        The clamped tables (default: ``frontend_tables(pass's model, params.word_bits,
        params.integrator)``: words, or energy codes for a log machine).
    output_columns : int, optional
        Output pixels per row (W - 2·margin - Dmax): the length of an ABOVE column's line of MAPs
        (required with one, refused otherwise).
    leads : bool
        An ABOVE column: whether this generator's machine runs a frame's first map row (True: the only
        machine, or machine 0 of several); otherwise its results above come from the machine of the
        map rows just before its own (see ``maps``).
    fused_share : FusedShare, optional
        The pass's part in sharing its fused column's sums with another pass's generator (the front end
        gives census-lr's passes theirs: ``passes.fused_shares``); adds the port ``fused_sums``.

    Attributes
    ----------
    pixel : ``In(stream.Signature(pass_pixel_layout(model, pass)))``
        Every pixel of the frame in raster order (the match features of all of them enter the delay
        line).
    beats : ``Out(load_stream(params))``
        ``beats_per_pixel`` beats per pixel whose ``output`` flag is set.
    pass_ : Pass
        The pass.
    reference : Reference
        Its reference image's entries and flags (:mod:`.reference`).
    The lane builders' ports (:func:`generator_signature`): an ABOVE column's ``maps``
    (``In(map_stream(params))``: the pass's own results as they leave its machine, ``ready`` while the line
    of MAPs has room) and ``frame_reset`` (:class:`~.lanes.prior.AboveLanes`); a PASS column's
    ``<pass>_maps`` (``In(map_stream(...))``: the other pass's MAPs, one taken per pixel it consults,
    :class:`~.lanes.consistency.ConsistencyLanes`); with ``fused_share`` ``fused_sums``
    (``Out(fused_share.signature())``: to :class:`~.shared.SharedSums`'s writer or reader).
    """

    def __init__(self, *, params: MachineParams, model: ModelParams, pass_name: str | None = None,
                 tables: FrontEndTables | None = None, output_columns: int | None = None,
                 leads: bool = True, fused_share: FusedShare | None = None) -> None:
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
        self._output_columns = _check_output_columns(p, output_columns)
        self._leads = as_bool("leads", leads)
        self._fused_share = _check_fused_share(model, p, params, fused_share)
        self._params = params
        self._model = model
        self._pass = p
        self._tables = (tables if tables is not None
                        else frontend_tables(p.model, params.word_bits, params.integrator))
        self._reference = reference_of(p)
        super().__init__(generator_signature(params, model, p, self._fused_share))

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
    def reference(self) -> Reference:
        return self._reference

    @property
    def fused_share(self) -> FusedShare | None:
        return self._fused_share

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
        return self.build(platform)[0]

    def build(self, platform: object) -> tuple[Module, WordPipeline]:
        """The generator's module (what :meth:`elaborate` gives) and its shared pipeline (its beat
        counter, ``active``, ...: a mutant of ``hdl.formal`` changes them)."""
        m = Module()
        scan = max(lanes_for(c).scan_latency(c, self._params.beats_per_pixel) for c in self._pass.columns)
        nets = word_pipeline(m, self, scan)
        columns = [lanes_for(c)(c, nets) for c in self._pass.columns]
        rule = self._pass.model.nomatch
        # The rule's floor, unless a column's words hold it (a fused column's no-match row).
        floor = None if any(c.holds_rule for c in self._pass.columns) else lanes_for(rule)(rule, nets)
        for lanes in (*columns, *([floor] if floor else [])):
            lanes.build()
        ready = nets.free
        for lanes in columns:
            ready = ready & lanes.ready()
        m.d.comb += self.pixel.ready.eq(nets.accept(ready))
        nets.write_beats(self._loaded(nets, columns, floor))
        return m, nets

    def _loaded(self, nets: WordPipeline, columns: list[Lanes],
                floor: Lanes | None) -> list[tuple[list[ValueLike], ValueLike]]:
        """(words of lane rows 0..R-1, no-match word) of each loaded operator column, in operator order:
        the machine's own loaded prior columns (1.0), then every column but a FEEDBACK one (formed by the
        machine). The no-match rule's word sits in the first FEATURES column's no-match row; a pass
        without a no-match row has 0 in every FEATURES column there; a FEATURES lane without a match
        pixel is 0."""
        p, one = self._pass, nets.one
        loaded = [lanes for lanes in columns if lanes.term.source is not Source.FEEDBACK]
        own = self._params.loaded_columns - len(loaded)
        out: list[tuple[list[ValueLike], ValueLike]] = [([one] * nets.rows_per_beat, one)] * own
        rule_word = None if floor is None else floor.nomatch()
        valid = [nets.reference.lane_valid(nets, j) for j in range(nets.rows_per_beat)]
        for lanes in loaded:
            words = [lanes.word(j) for j in range(nets.rows_per_beat)]
            nomatch = lanes.nomatch()
            if lanes.term.source is Source.FEATURES:
                words = [w if ok is None else Mux(ok, w, nets.zero)
                         for w, ok in zip(words, valid, strict=True)]
                nomatch, rule_word = (nomatch if rule_word is None else rule_word), None
                nomatch = nomatch if p.nomatch else nets.zero
            out.append((words, nomatch))
        return out


