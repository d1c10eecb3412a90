"""The run API: a rectified pair -> likelihood memories -> the machine -> a compared result.

``prepare`` computes what does not depend on the machine (features, the float64 reference
MAP, ground truth cut to the output region); ``run_machine`` streams the likelihood memories
through an engine one chunk of map rows at a time (engines keep their LFSR state across
calls, so chunking does not change results); ``run_pair`` does both and the metrics.
A machine with the neighbour prior (``prior="neighbour"``, the census model's) runs one map row
per call: row y's loaded prior column is the above neighbours' factor, formed from the machine's
own results of row y - 1 (none for row 0), and each row's first pixel is flagged ``line_start``
(the machine forms the left neighbour's factor itself from its previous result).
The census-lr model runs a second machine (:func:`bayesmachine.likelihood.right_machine`, the same
engine kind) for its right pass: per map row, first the right pass's row (its own above prior from
its previous row), then the left pass's row, whose consistency column comes from the right MAPs just
produced (:func:`bayesmachine.likelihood.lr_column`); the run keeps them as ``run.right``.
Memory grows with the outputs (per-pixel maps and counts), not with frame x Dmax: the
float64 posterior is only ever computed one band of rows at a time.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from bayesmachine.likelihood import lr_column, neighbour_words, right_machine
from bayesmachine.outputs import require_memory
from bayesmachine.params import MachineParams
from bayesmachine.region import OutputRegion
from bayesmachine.sim.engines import ENGINES, PIXEL_ENGINES, get_engine, get_pixel_engine
from bayesmachine.sim.results import MachineResult, disparities

from .confidence import ConfidenceParams
from .features import model_features
from .images import validate_pair
from .likelihoods import (
    ModelParams,
    QuantizedTables,
    likelihood_tables,
    memory_words,
    right_columns,
    right_memory_words,
)
from .metrics import RunMetrics, evaluate, gt_region
from .records import MachineRun, Prepared, RightPass, counts_dtype
from .reference import reference_map, warm_up

__all__ = [
    "ENGINES",
    "FEEDS",
    "Prepared",
    "MachineRun",
    "RunOutcome",
    "prepare",
    "run_machine",
    "run_pair",
    "result_bytes",
    "machines_model",
]

# How the machine is fed: the host's likelihood words (any engine), or the pixel pairs through the
# on-chip front end (the StereoMachine RTL: a pixel engine, sim.engines.PIXEL_ENGINES).
FEEDS = ("words", "pixels")


@dataclass
class RunOutcome:
    prepared: Prepared
    run: MachineRun
    metrics: RunMetrics = field(repr=False)


def result_bytes(region: OutputRegion, machine: MachineParams) -> int:
    """Bytes of a run's per-pixel results: counts, map, cycles, no-match and timeout flags."""
    per_pixel = machine.rows * counts_dtype(machine.counter_max).itemsize + 2 + 8 + 1 + 1
    return region.pixels * per_pixel


def prepare(
    left: np.ndarray, right: np.ndarray, model: ModelParams, gt: np.ndarray | None = None,
    reference: bool = True,
) -> Prepared:
    """Validate the pair, compute the features and the float64 reference MAP (band by band).

    ``reference=False`` skips the reference (``reference_map`` is None): enough to run the
    machine (``run_machine``, e.g. to measure its cycles), not to evaluate it."""
    validate_pair(left, right, model.dmax, model.margin)
    if gt is not None and gt.shape != left.shape:
        raise ValueError(f"ground truth shape {gt.shape} differs from the images' {left.shape}")
    if reference:
        warm_up(model)  # keep numba's cache load / compilation out of reference_seconds
    t0 = time.perf_counter()
    feats = (model_features(left, model), model_features(right, model))
    ref_map = reference_map(*feats, model) if reference else None
    seconds = time.perf_counter() - t0
    cut = gt_region(gt, model.dmax, model.margin) if gt is not None else None
    return Prepared(left, right, model, feats, ref_map, seconds, cut, gt)


def _want_progress(progress: bool | None) -> bool:
    return sys.stderr.isatty() if progress is None else progress


def run_machine(
    prepared: Prepared,
    machine: MachineParams,
    engine: str = "model",
    progress: bool | None = None,
    chunk_rows: int = 1,
    engine_options: dict[str, object] | None = None,
    feed: str = "words",
    machines: int = 1,
) -> MachineRun:
    """Stream the output pixels (row-major) through ``engine``, ``chunk_rows`` map rows per call.

    ``engine_options`` go to the engine's constructor (e.g. ``trace`` for ``verilator``).
    ``feed="pixels"``: the pair itself goes into the StereoMachine (front end on chip), through the
    pixel engine ``engine`` (``verilator``, or ``board``: :data:`~bayesmachine.sim.engines.PIXEL_ENGINES`).
    A neighbour-prior machine runs one map row per call whatever ``chunk_rows`` (its above column
    needs the previous row's results; see the module's text).
    ``machines`` = K > 1: map row y runs on machine y mod K (``feed="pixels"``: the StereoMachine
    with K machines; ``feed="words"``: K engines, one map row per call, as :func:`machines_model`
    says; their wall cycles are not a K-machine design's, so ``wall_cycles`` is None).
    """
    model = prepared.model
    if machine.rows != model.hypotheses:
        raise ValueError(
            f"machine rows ({machine.rows}) must be dmax + 2 = {model.hypotheses}; "
            f"build it with MachineParams.for_disparity({model.dmax}, ...)"
        )
    if feed not in FEEDS:
        raise ValueError(f"unknown feed {feed!r}: choose one of {', '.join(FEEDS)}")
    ho, wo = prepared.shape
    m = model.hypotheses
    require_memory(
        result_bytes(prepared.region, machine),
        f"the per-pixel results of {ho}x{wo} pixels x {m} counters",
        "use --crop or a smaller --dmax",
    )
    if machines != 1 and model.lr:
        raise ValueError(f"--machines {machines}: --model {model.name} runs with one machine")
    if feed == "pixels":
        return _run_pixels(prepared, machine, engine, engine_options, machines)
    neighbour = machine.feedback_columns > 0
    if neighbour or machines != 1:
        chunk_rows = 1  # row y's above column is the machine's own row y - 1; rows dealt to machines
    engines = [get_engine(engine, machine, **(engine_options or {})) for _ in range(machines)]
    qtables = QuantizedTables(likelihood_tables(model), machine.word_bits)
    lr = _RightRun(prepared, machine, engine, engine_options) if model.lr else None
    counts = np.zeros((ho, wo, m), counts_dtype(machine.counter_max))
    flat_map = np.zeros((ho, wo), np.int16)  # row indices < 4096
    nomatch = np.zeros((ho, wo), bool)
    timeout = np.zeros((ho, wo), bool)
    cycles = np.zeros((ho, wo), np.int64)
    engine_s = words_s = 0.0
    left_f, right_f = prepared.features

    def disp_row(y: int) -> np.ndarray:
        return disparities(flat_map[y], nomatch[y], timeout[y])

    try:
        with tqdm(total=ho * wo, unit="px", disable=not _want_progress(progress), desc=f"{engine}") as bar:
            for y0 in range(0, ho, chunk_rows):
                rows = slice(y0, min(ho, y0 + chunk_rows))
                t0 = time.perf_counter()
                if neighbour:
                    # The machine's own results of the row above (-1: no match, timeout, none for row 0).
                    above = np.full(wo, -1, np.int16) if y0 == 0 else disp_row(y0 - 1)
                    prior = neighbour_words(qtables, model.dmax, above)
                    consistency = None
                    if lr is not None:
                        t_r = time.perf_counter()
                        consistency = lr.row(y0, qtables)
                        t0 += time.perf_counter() - t_r  # the right pass's time is its own
                    words = memory_words(left_f, right_f, model, machine, rows=rows, qtables=qtables,
                                         prior=prior, consistency=consistency)
                    starts = np.zeros(wo, bool)
                    starts[0] = True  # each map row's first pixel has no left neighbour
                    t1 = time.perf_counter()
                    res = engines[y0 % machines].run(words, line_start=starts)
                else:
                    words = memory_words(left_f, right_f, model, machine, rows=rows, qtables=qtables)
                    t1 = time.perf_counter()
                    res = engines[y0 % machines].run(words)
                t2 = time.perf_counter()
                words_s += t1 - t0
                engine_s += t2 - t1
                n = rows.stop - rows.start
                counts[rows] = np.asarray(res.counts).reshape(n, wo, m)
                flat_map[rows] = np.asarray(res.map).reshape(n, wo)
                nomatch[rows] = np.asarray(res.nomatch).reshape(n, wo)
                timeout[rows] = np.asarray(res.timeout).reshape(n, wo)
                cycles[rows] = np.asarray(res.cycles).reshape(n, wo)
                bar.update(n * wo)
        wall = engines[0].wall_cycles if machines == 1 else None
    finally:
        for eng in engines:
            eng.close()  # the Verilator harness is a process: end it now, not at garbage collection
        if lr is not None:
            lr.close()
    # Timeouts count as no match: the machine gave no answer within its watchdog.
    disp = disparities(flat_map, nomatch, timeout)
    right = lr.result() if lr is not None else None
    return MachineRun(engine, machine, disp, counts, cycles, nomatch, timeout, engine_s, words_s, wall, right)


class _RightRun:
    """census-lr's right pass, one map row at a time, on its own machine (the left pass's engine kind)."""

    def __init__(self, prepared: Prepared, machine: MachineParams, engine: str,
                 engine_options: dict[str, object] | None) -> None:
        model = prepared.model
        self.model = model
        self.features = prepared.features
        self.machine = right_machine(model, machine)
        self.qtables = QuantizedTables(likelihood_tables(model.right_model), machine.word_bits)
        region = OutputRegion.of_features(prepared.features[0].shape, model.dmax)
        self.columns = right_columns(region)
        self.map_columns = region.map_columns
        ho, wr = region.shape[0], self.columns.size
        self.map = np.full((ho, wr), -1, np.int16)
        self.cycles = np.zeros((ho, wr), np.int64)
        self.timeout = np.zeros((ho, wr), bool)
        self.seconds = 0.0
        self.wall: int | None = None
        self.engine = get_engine(engine, self.machine, **(engine_options or {}))

    def row(self, y: int, left_q: QuantizedTables) -> np.ndarray:
        """Run right map row ``y`` and return the left pass's consistency words (Wo, Dmax+2) of row ``y``."""
        model, wr = self.model, self.columns.size
        above = np.full(wr, -1, np.int16) if y == 0 else self.map[y - 1]
        prior = neighbour_words(self.qtables, model.dmax, above)
        words = right_memory_words(*self.features, model, self.machine, rows=slice(y, y + 1),
                                   qtables=self.qtables, prior=prior)
        starts = np.zeros(wr, bool)
        starts[0] = True
        t0 = time.perf_counter()
        res = self.engine.run(words, line_start=starts)
        self.seconds += time.perf_counter() - t0
        timeout = np.asarray(res.timeout, bool)
        self.timeout[y] = timeout
        self.cycles[y] = np.asarray(res.cycles)
        # A no-match call (the right pass's no-match row, lr_right_nomatch) or a timeout: no right MAP.
        self.map[y] = res.disparities()
        return lr_column(self.map[y], int(self.columns[0]), self.map_columns, model, left_q.one,
                         left_q.lr_beta, left_q.lr_gamma)

    def close(self) -> None:
        self.wall = self.engine.wall_cycles
        self.engine.close()

    def result(self) -> RightPass:
        return RightPass(self.machine, self.map, self.cycles, self.timeout, self.seconds, self.wall)


def _run_pixels(
    prepared: Prepared, machine: MachineParams, engine: str, engine_options: dict[str, object] | None,
    machines: int = 1,
) -> MachineRun:
    """The whole pair through a pixel engine (the StereoMachine RTL under Verilator, or on a board):
    pixels in, one result per output pixel out."""
    if engine not in PIXEL_ENGINES:
        raise ValueError(f"--feed pixels runs the StereoMachine RTL: use --engine verilator (or board) "
                         f"(got --engine {engine})")
    model = prepared.model
    options = dict(engine_options or {}, **({"machines": machines} if machines != 1 else {}))
    eng = get_pixel_engine(engine, machine, model, prepared.left.shape[1], **options)
    try:
        t0 = time.perf_counter()
        res = eng.run(prepared.left, prepared.right)
        seconds = time.perf_counter() - t0
        wall, figures, r = eng.wall_cycles, eng.figures, eng.last_right
    finally:
        eng.close()
    ho, wo = prepared.shape
    m = model.hypotheses
    timeout = res.timeout.reshape(ho, wo)
    nomatch = res.nomatch.reshape(ho, wo)
    disp = disparities(res.map.reshape(ho, wo), nomatch, timeout)
    # A board asked for the MAP alone sent no counts or cycles: absent, never made up.
    dtype = counts_dtype(machine.counter_max)
    counts = None if res.counts is None else res.counts.reshape(ho, wo, m).astype(dtype)
    cycles = None if res.cycles is None else res.cycles.reshape(ho, wo)
    right = None
    if model.lr:
        # The right pass ran on chip beside the left one (its own machine, the same clock): it adds no
        # wall cycles of its own, the frame's (first pixel in to last result out) are both passes'.
        from bayesmachine.hdl.frontend.lr import right_pass_params

        assert r is not None
        wr = r.map.size // ho
        r_timeout = r.timeout.reshape(ho, wr)
        r_map = r.disparities().reshape(ho, wr)
        right = RightPass(right_pass_params(model, machine), r_map, r.cycles.reshape(ho, wr), r_timeout,
                          seconds, 0)
    return MachineRun(engine, machine, disp, counts, cycles, nomatch, timeout, seconds, 0.0, wall, right,
                      figures)


def machines_model(
    frames: list[tuple[np.ndarray, np.ndarray]], model: ModelParams, machine: MachineParams,
    machines: int = 1, engine: str = "model",
) -> MachineResult:
    """What ``StereoMachine(machines=K)`` streams out for ``frames`` (pairs, back to back), from an
    engine fed with the host's words: map row y of a frame runs on machine y mod K, each machine an
    engine of its own from reset, so its random source (every on-chip kind: a ``sobol`` pixel's
    shift, the LFSRs) and its left neighbour's result run over its own rows only, frame after frame;
    with the neighbour prior the above column comes from row y - 1's results (machine (y - 1) mod K),
    each row's first pixel is flagged ``line_start``. Results in raster order of each frame's output
    region (the same as one engine when K = 1)."""
    neighbour = machine.feedback_columns > 0
    qtables = QuantizedTables(likelihood_tables(model), machine.word_bits)
    engines = [get_engine(engine, machine) for _ in range(machines)]
    parts: list[MachineResult] = []
    try:
        for left, right in frames:
            fl, fr = model_features(left, model), model_features(right, model)
            ho, wo = fl.m25.shape[0], fl.m25.shape[1] - model.dmax  # the output region's
            above = np.full(wo, -1, np.int16)
            for y in range(ho):
                eng = engines[y % machines]
                if neighbour:
                    words = memory_words(fl, fr, model, machine, rows=slice(y, y + 1), qtables=qtables,
                                         prior=neighbour_words(qtables, model.dmax, above))
                    starts = np.zeros(wo, bool)
                    starts[0] = True
                    res = eng.run(words, line_start=starts)
                    above = res.disparities()
                else:
                    res = eng.run(memory_words(fl, fr, model, machine, rows=slice(y, y + 1), qtables=qtables))
                parts.append(res)
    finally:
        for eng in engines:
            eng.close()
    return MachineResult.concatenate(parts, machine.rows)


def run_pair(
    left: np.ndarray,
    right: np.ndarray,
    model_params: ModelParams,
    machine_params: MachineParams,
    engine: str = "model",
    gt: np.ndarray | None = None,
    progress: bool | None = None,
    prepared: Prepared | None = None,
    sgbm: bool | None = None,
    engine_options: dict[str, object] | None = None,
    feed: str = "words",
    machines: int = 1,
    confidence: ConfidenceParams | None = None,
) -> RunOutcome:
    """Run the machine on a gray pair and compare it with the reference (and gt, if given).

    ``prepared`` reuses an earlier ``prepare`` of the same pair (sweeps). ``sgbm``: also
    evaluate OpenCV StereoSGBM (default: when ground truth is given). ``confidence``: how the
    per-pixel confidence is read (:class:`~.confidence.ConfidenceParams`, default its defaults).
    """
    if prepared is None:
        prepared = prepare(left, right, model_params, gt)
    run = run_machine(prepared, machine_params, engine, progress, engine_options=engine_options, feed=feed,
                      machines=machines)
    metrics = evaluate(prepared, run, sgbm=sgbm, confidence=confidence)
    return RunOutcome(prepared, run, metrics)
