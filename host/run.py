"""The run API: a rectified pair -> likelihood memories -> the machine -> a compared result.

``prepare`` computes what does not depend on the machine (features, the float64 reference
MAP, ground truth cut to the output region); ``run_machine`` streams the likelihood memories
through an engine one chunk of map rows at a time (engines keep their LFSR state across
calls, so chunking does not change results); ``run_pair`` does both and the metrics.
The run makes every pass the model declares (:attr:`~bayesmachine.models.ModelParams.passes`), each on
its own machine of the same engine kind, map row by map row in order, and each column builds its words
from where it says (:meth:`~bayesmachine.columns.Column.words`): a FEATURES column from the pair's
planes, an ABOVE column from the pass's own results of map row y - 1 (none for row 0), a PASS column
from the results of the pass it names for the same row (census-lr's consistency column: the right
pass's MAPs, which that pass produced just before); a FEEDBACK column is formed by the machine from its
previous result, each row's first pixel flagged ``line_start``. A pass with a column fed by results runs
one map row per call. The declared passes' results are kept by pass name (``run.passes``).
Memory grows with the outputs (per-pixel maps and counts), not with frame x Dmax: the
float64 posterior is only ever computed one band of rows at a time.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from bayesmachine.models import ModelParams, Pass, pass_machine
from bayesmachine.outputs import require_memory
from bayesmachine.params import MachineParams
from bayesmachine.region import OutputRegion
from bayesmachine.sim.engines import ENGINES, PIXEL_ENGINES, get_engine, get_pixel_engine
from bayesmachine.sim.results import MachineResult, disparities

from .confidence import ConfidenceParams
from .features import Planes, model_planes
from .fill import DEFAULT_FILL, Fill, run_fill
from .images import validate_pair
from .likelihoods import pass_grid, pass_words
from .metrics import RunMetrics, evaluate, gt_region
from .records import MachineRun, PassRecord, Prepared, counts_dtype
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
    "stereo_model",
]

# How the machine is fed: the host's likelihood words (any engine), or the pixel pairs through the
# on-chip front end (the StereoMachine RTL: a pixel engine, sim.engines.PIXEL_ENGINES).
FEEDS = ("words", "pixels")


@dataclass
class RunOutcome:
    prepared: Prepared
    run: MachineRun
    metrics: RunMetrics = field(repr=False)
    fill: Fill | None = field(default=None, repr=False)  # the run's map filled (host.fill; None: not)


def result_bytes(region: OutputRegion, machine: MachineParams) -> int:
    """Bytes of a run's per-pixel results: counts, map, cycles, no-match and timeout flags."""
    per_pixel = machine.rows * counts_dtype(machine.readout_max).itemsize + 2 + 8 + 1 + 1
    return region.pixels * per_pixel


def prepare(
    left: np.ndarray, right: np.ndarray, model: ModelParams, gt: np.ndarray | None = None,
    reference: bool = True,
) -> Prepared:
    """Validate the pair, compute its planes and the float64 reference MAP (band by band).

    ``reference=False`` skips the reference (``reference_map`` is None): enough to run the
    machine (``run_machine``, e.g. to measure its cycles), not to evaluate it."""
    validate_pair(left, right, model.dmax, model.margin)
    if gt is not None and gt.shape != left.shape:
        raise ValueError(f"ground truth shape {gt.shape} differs from the images' {left.shape}")
    if reference:
        warm_up(model)  # keep numba's cache load / compilation out of reference_seconds
    t0 = time.perf_counter()
    planes = (model_planes(left, model), model_planes(right, model))
    ref_map = reference_map(*planes, model) if reference else None
    seconds = time.perf_counter() - t0
    cut = gt_region(gt, model.dmax, model.margin) if gt is not None else None
    return Prepared(left, right, model, planes, ref_map, seconds, cut, gt)


def _want_progress(progress: bool | None) -> bool:
    return sys.stderr.isatty() if progress is None else progress


def _row_words(p: Pass, planes: tuple[Planes, Planes], machine: MachineParams, rows: slice,
               above: np.ndarray, results: Mapping[str, np.ndarray], carry: dict[str, object]) -> np.ndarray:
    """The words of pass ``p``'s map rows ``rows``, each column's from where it says: ``above`` (the pass's
    own MAP row above: -1 for none), ``results`` (the other passes' MAPs of these rows, by name), ``carry``
    (what its columns carry from the rows before: the pass's own, rows in order)."""
    return pass_words(p, *planes, machine, rows=rows, above=above, results=results, carry=carry)


def _row_by_row(p: Pass) -> bool:
    """Whether pass ``p`` runs one map row per call: a column fed by the machine's own results (its
    previous result, the row above) or by another pass's row."""
    return any(c.source.from_results for c in p.columns)


def _line_starts(machine: MachineParams, width: int) -> np.ndarray | None:
    """Each map row's first pixel flagged (no left neighbour), for a machine with a feedback column."""
    if not machine.feedback_columns:
        return None
    starts = np.zeros(width, bool)
    starts[0] = True
    return starts


class _PassRun:
    """One pass of a run on its own machine(s), map rows in order: its results so far."""

    def __init__(self, prepared: Prepared, p: Pass, machine: MachineParams, engine: str,
                 engine_options: dict[str, object] | None, machines: int = 1) -> None:
        self.p = p
        self.machine = machine
        self.planes = prepared.planes
        region = OutputRegion.of_features(prepared.planes[0].shape, p.model.dmax)
        self.width = pass_grid(p, region).width
        ho = region.shape[0]
        self.map = np.full((ho, self.width), -1, np.int16)  # the answers (disparities): -1 no match
        self.follow = np.full((ho, self.width), -1, np.int16)  # what neighbours follow: -1 for timeouts too
        self.cycles = np.zeros((ho, self.width), np.int64)
        self.timeout = np.zeros((ho, self.width), bool)
        self.seconds = self.words_seconds = 0.0
        self.wall: int | None = None
        self.carry: dict[str, object] = {}
        self.engines = [get_engine(engine, machine, **(engine_options or {})) for _ in range(machines)]

    def run(self, rows: slice, results: Mapping[str, np.ndarray]) -> MachineResult:
        """Run map rows ``rows`` (one, where the pass's columns need it) and keep their results;
        ``results``: the other passes' MAPs so far, by name."""
        t0 = time.perf_counter()
        y0 = rows.start
        above = np.full(self.width, -1, np.int16) if y0 == 0 else self.follow[y0 - 1]
        words = _row_words(self.p, self.planes, self.machine, rows, above,
                           {k: v[rows] for k, v in results.items()}, self.carry)
        starts = _line_starts(self.machine, self.width)
        t1 = time.perf_counter()
        eng = self.engines[y0 % len(self.engines)]
        res = eng.run(words) if starts is None else eng.run(words, line_start=starts)
        self.seconds += time.perf_counter() - t1
        self.words_seconds += t1 - t0
        n = rows.stop - rows.start
        self.map[rows] = res.disparities(self.machine).reshape(n, self.width)
        self.follow[rows] = res.neighbour_answers().reshape(n, self.width)
        self.cycles[rows] = np.asarray(res.cycles).reshape(n, self.width)
        self.timeout[rows] = np.asarray(res.timeout, bool).reshape(n, self.width)
        return res

    def close(self) -> None:
        self.wall = self.engines[0].wall_cycles if len(self.engines) == 1 else None
        for eng in self.engines:
            eng.close()  # the Verilator harness is a process: end it now, not at garbage collection

    def record(self) -> PassRecord:
        # A feeding pass's MAPs are what the passes it feeds followed (timeouts no information).
        return PassRecord(self.machine, self.follow, self.cycles, self.timeout, self.seconds, self.wall)


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

    Every pass the model declares runs on its own machine (:func:`~bayesmachine.models.pass_machine`,
    the same engine kind), each map row before the model's own pass takes it (module text).
    ``engine_options`` go to the engine's constructor (e.g. ``trace`` for ``verilator``).
    ``feed="pixels"``: the pair itself goes into the StereoMachine (front end on chip), through the
    pixel engine ``engine`` (``verilator``, or ``board``: :data:`~bayesmachine.sim.engines.PIXEL_ENGINES`).
    A pass with a column fed by results runs one map row per call whatever ``chunk_rows``.
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
    declared = model.passes[:-1]
    if feed == "pixels":
        return _run_pixels(prepared, machine, engine, engine_options, machines)
    if any(_row_by_row(p) for p in model.passes) or machines != 1:
        chunk_rows = 1  # rows fed by the row above or by another pass's row; rows dealt to machines
    runs = [_PassRun(prepared, p, pass_machine(model, machine, p.name), engine, engine_options, machines)
            for p in declared]
    own = _PassRun(prepared, model.passes[-1], machine, engine, engine_options, machines)
    counts = np.zeros((ho, wo, m), counts_dtype(machine.readout_max))
    nomatch = np.zeros((ho, wo), bool)
    try:
        with tqdm(total=ho * wo, unit="px", disable=not _want_progress(progress), desc=f"{engine}") as bar:
            for y0 in range(0, ho, chunk_rows):
                rows = slice(y0, min(ho, y0 + chunk_rows))
                for r in runs:
                    r.run(rows, {q.p.name: q.follow for q in runs})
                res = own.run(rows, {q.p.name: q.follow for q in runs})  # every declared pass's, by name
                n = rows.stop - rows.start
                counts[rows] = np.asarray(res.counts).reshape(n, wo, m)
                nomatch[rows] = np.asarray(res.nomatch).reshape(n, wo)
                bar.update(n * wo)
    finally:
        for r in (*runs, own):
            r.close()
    # own.map: a timeout is no match unless the machine answers it with its leading row (timeout_answer).
    return MachineRun(engine, machine, own.map, counts, own.cycles, nomatch, own.timeout, own.seconds,
                      own.words_seconds, own.wall, {r.p.name: r.record() for r in runs})


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
        wall, figures, pass_results = eng.wall_cycles, eng.figures, dict(eng.last_passes)
    finally:
        eng.close()
    ho, wo = prepared.shape
    m = model.hypotheses
    timeout = res.timeout.reshape(ho, wo)
    nomatch = res.nomatch.reshape(ho, wo)
    disp = disparities(res.map.reshape(ho, wo), nomatch, timeout, machine)
    # A board asked for the MAP alone sent no counts or cycles: absent, never made up.
    dtype = counts_dtype(machine.readout_max)
    counts = None if res.counts is None else res.counts.reshape(ho, wo, m).astype(dtype)
    cycles = None if res.cycles is None else res.cycles.reshape(ho, wo)
    passes = {}
    # The declared passes ran on chip beside the own one (their own machines, the same clock): they add no
    # wall cycles of their own, the frame's (first pixel in to last result out) are every pass's. A board
    # asked for the MAP alone sent no cycles: such a pass is left out, never made up.
    from bayesmachine.hdl.frontend.words import pass_params

    for name, r in pass_results.items():
        if r.cycles is None:
            continue
        w = r.map.size // ho
        passes[name] = PassRecord(pass_params(model, machine, name), r.neighbour_answers().reshape(ho, w),
                                  r.cycles.reshape(ho, w), r.timeout.reshape(ho, w), seconds, 0)
    return MachineRun(engine, machine, disp, counts, cycles, nomatch, timeout, seconds, 0.0, wall, passes,
                      figures)


def stereo_model(
    frames: list[tuple[np.ndarray, np.ndarray]], model: ModelParams, machine: MachineParams,
    machines: int = 1, engine: str = "model",
) -> dict[str, MachineResult]:
    """What ``StereoMachine(machines=K)`` streams out for ``frames`` (pairs, back to back), every pass's
    results by pass name, from engines fed with the host's words: map row y of a frame runs, in each pass,
    on that pass's machine y mod K, each machine an engine of its own from reset, so its random source
    (every on-chip kind: a ``sobol`` pixel's shift, the LFSRs) and its left neighbour's result run over its
    own rows only, frame after frame. Per map row each declared pass's row runs first, then the own pass's:
    an ABOVE column from the pass's row y - 1 (machine (y - 1) mod K), a PASS column from the row y of the
    pass it reads, and with a FEEDBACK column each row's first pixel is flagged ``line_start``. Results in
    raster order of each frame's rows of the pass (K = 1: the machine with one machine per pass)."""
    passes = model.passes
    params = {p.name: machine if p is passes[-1] else pass_machine(model, machine, p.name) for p in passes}
    engines = {name: [get_engine(engine, pp) for _ in range(machines)] for name, pp in params.items()}
    parts: dict[str, list[MachineResult]] = {p.name: [] for p in passes}
    try:
        for left, right in frames:
            planes = (model_planes(left, model), model_planes(right, model))
            region = OutputRegion.of_features(planes[0].shape, model.dmax)
            latest = {p.name: np.full(pass_grid(p, region).width, -1, np.int16) for p in passes}
            carry: dict[str, dict[str, object]] = {p.name: {} for p in passes}
            for y in range(region.shape[0]):
                for p in passes:
                    pp = params[p.name]
                    others = {k: v[None] for k, v in latest.items() if k != p.name}
                    words = _row_words(p, planes, pp, slice(y, y + 1), latest[p.name], others, carry[p.name])
                    starts = _line_starts(pp, latest[p.name].size)
                    eng = engines[p.name][y % machines]
                    res = eng.run(words) if starts is None else eng.run(words, line_start=starts)
                    latest[p.name] = res.neighbour_answers()
                    parts[p.name].append(res)
    finally:
        for eng in (e for lane in engines.values() for e in lane):
            eng.close()
    return {name: MachineResult.concatenate(parts[name], params[name].rows) for name in parts}


def machines_model(
    frames: list[tuple[np.ndarray, np.ndarray]], model: ModelParams, machine: MachineParams,
    machines: int = 1, engine: str = "model",
) -> MachineResult:
    """The own pass's results of :func:`stereo_model` (what ``StereoMachine(machines=K)`` streams out on
    ``result``)."""
    return stereo_model(frames, model, machine, machines, engine)[model.passes[-1].name]


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
    fill: str = DEFAULT_FILL,
) -> RunOutcome:
    """Run the machine on a gray pair and compare it with the reference (and gt, if given).

    ``prepared`` reuses an earlier ``prepare`` of the same pair (sweeps). ``sgbm``: also
    evaluate OpenCV StereoSGBM (default: when ground truth is given). ``confidence``: how the
    per-pixel confidence is read (:class:`~.confidence.ConfidenceParams`, default its defaults).
    ``fill``: how the pixels without a disparity are filled from their row (:mod:`.fill`: ``background``,
    ``left`` or ``none``); the machine's own map stays ``run.map``.
    """
    if prepared is None:
        prepared = prepare(left, right, model_params, gt)
    run = run_machine(prepared, machine_params, engine, progress, engine_options=engine_options, feed=feed,
                      machines=machines)
    filled = run_fill(prepared, run, fill)
    metrics = evaluate(prepared, run, sgbm=sgbm, confidence=confidence, fill=filled)
    return RunOutcome(prepared, run, metrics, filled if fill != "none" else None)
