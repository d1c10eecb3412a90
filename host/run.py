"""The run API: a rectified pair -> likelihood memories -> the machine -> a compared result.

``prepare`` computes what does not depend on the machine (features, the float64 reference,
ground truth cut to the output region); ``run_machine`` streams the likelihood memories
through an engine one chunk of map rows at a time (engines keep their LFSR state across
calls, so chunking does not change results); ``run_pair`` does both and the metrics.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import ENGINES, get_engine

from .features import FeatureSums, feature_sums
from .images import validate_pair
from .likelihoods import ModelParams, QuantizedTables, likelihood_tables, memory_words
from .metrics import RunMetrics, evaluate, gt_region
from .reference import Reference, reference_fast, warm_up

__all__ = ["ENGINES", "FEEDS", "Prepared", "MachineRun", "RunOutcome", "prepare", "run_machine", "run_pair"]

# How the machine is fed: the host's likelihood words (any engine), or the pixel pairs through the
# on-chip front end (the StereoMachine RTL, Verilator only).
FEEDS = ("words", "pixels")


@dataclass
class Prepared:
    """Everything about a pair that does not depend on the machine."""

    left: np.ndarray
    right: np.ndarray
    model: ModelParams
    features: tuple[FeatureSums, FeatureSums]
    reference: Reference
    reference_seconds: float
    gt: np.ndarray | None = None  # ground truth cut to the output region (map coordinates)
    gt_image: np.ndarray | None = None  # ground truth in image coordinates (for SGBM)

    @property
    def shape(self) -> tuple[int, int]:
        """Output region (rows, columns) in map pixels."""
        return self.reference.map.shape  # type: ignore[return-value]


@dataclass
class MachineRun:
    """Per-pixel machine results laid out over the output region."""

    engine: str
    machine: MachineParams
    map: np.ndarray  # (Ho, Wo) int16, -1 = no match (timeouts included)
    counts: np.ndarray  # (Ho, Wo, M) uint32
    cycles: np.ndarray  # (Ho, Wo) int64
    nomatch: np.ndarray  # (Ho, Wo) bool, the no-match row won
    timeout: np.ndarray  # (Ho, Wo) bool, the watchdog stopped the run
    seconds: float  # time inside the engine's run calls
    words_seconds: float  # time building likelihood memories
    wall_cycles: int | None = None  # RTL engines: clock cycles including loading (None: model)


@dataclass
class RunOutcome:
    prepared: Prepared
    run: MachineRun
    metrics: RunMetrics = field(repr=False)


def prepare(
    left: np.ndarray, right: np.ndarray, model: ModelParams, gt: np.ndarray | None = None
) -> Prepared:
    """Validate the pair, compute the features and the float64 reference."""
    validate_pair(left, right, model.dmax)
    if gt is not None and gt.shape != left.shape:
        raise ValueError(f"ground truth shape {gt.shape} differs from the images' {left.shape}")
    warm_up()  # keep numba's cache load / compilation out of reference_seconds
    t0 = time.perf_counter()
    feats = (feature_sums(left), feature_sums(right))
    ref = reference_fast(*feats, model)
    seconds = time.perf_counter() - t0
    cut = gt_region(gt, model.dmax) if gt is not None else None
    return Prepared(left, right, model, feats, ref, seconds, cut, gt)


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
) -> MachineRun:
    """Stream the output pixels (row-major) through ``engine``, ``chunk_rows`` map rows per call.

    ``engine_options`` go to the engine's constructor (e.g. ``trace`` for ``verilator``).
    ``feed="pixels"``: the pair itself goes into the StereoMachine (front end on chip; Verilator).
    """
    model = prepared.model
    if machine.rows != model.hypotheses:
        raise ValueError(
            f"machine rows ({machine.rows}) must be dmax + 2 = {model.hypotheses}; "
            f"build it with MachineParams.for_disparity({model.dmax}, ...)"
        )
    if feed not in FEEDS:
        raise ValueError(f"unknown feed {feed!r}: choose one of {', '.join(FEEDS)}")
    if feed == "pixels":
        return _run_pixels(prepared, machine, engine, engine_options)
    eng = get_engine(engine, machine, **(engine_options or {}))
    qtables = QuantizedTables(likelihood_tables(model), machine.word_bits)
    ho, wo = prepared.shape
    m = model.hypotheses
    counts = np.zeros((ho, wo, m), np.uint32)
    flat_map = np.zeros((ho, wo), np.int32)
    nomatch = np.zeros((ho, wo), bool)
    timeout = np.zeros((ho, wo), bool)
    cycles = np.zeros((ho, wo), np.int64)
    engine_s = words_s = 0.0
    left_f, right_f = prepared.features
    try:
        with tqdm(total=ho * wo, unit="px", disable=not _want_progress(progress), desc=f"{engine}") as bar:
            for y0 in range(0, ho, chunk_rows):
                rows = slice(y0, min(ho, y0 + chunk_rows))
                t0 = time.perf_counter()
                words = memory_words(left_f, right_f, model, machine, rows=rows, qtables=qtables)
                t1 = time.perf_counter()
                res = eng.run(words)  # type: ignore[attr-defined]
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
        wall = getattr(eng, "wall_cycles", None)
    finally:
        close = getattr(eng, "close", None)
        if close is not None:
            close()  # the Verilator harness is a process: end it now, not at garbage collection
    # Timeouts count as no match: the machine gave no answer within its watchdog.
    disp = np.where(nomatch | timeout, -1, flat_map).astype(np.int16)
    return MachineRun(engine, machine, disp, counts, cycles, nomatch, timeout, engine_s, words_s, wall)


def _run_pixels(
    prepared: Prepared, machine: MachineParams, engine: str, engine_options: dict[str, object] | None
) -> MachineRun:
    """The whole pair through the StereoMachine RTL: pixels in, one result per output pixel out."""
    if engine != "verilator":
        raise ValueError(f"--feed pixels runs the StereoMachine RTL under Verilator: use --engine verilator "
                         f"(got --engine {engine})")
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    model = prepared.model
    eng = StereoVerilatorEngine(machine, model, prepared.left.shape[1], **(engine_options or {}))
    try:
        t0 = time.perf_counter()
        res = eng.run(prepared.left, prepared.right)
        seconds = time.perf_counter() - t0
        wall = eng.wall_cycles
    finally:
        eng.close()
    ho, wo = prepared.shape
    m = model.hypotheses
    timeout = res.timeout.reshape(ho, wo)
    nomatch = res.nomatch.reshape(ho, wo)
    disp = np.where(nomatch | timeout, -1, res.map.reshape(ho, wo)).astype(np.int16)
    return MachineRun("verilator", machine, disp, res.counts.reshape(ho, wo, m), res.cycles.reshape(ho, wo),
                      nomatch, timeout, seconds, 0.0, wall)


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
) -> RunOutcome:
    """Run the machine on a gray pair and compare it with the reference (and gt, if given).

    ``prepared`` reuses an earlier ``prepare`` of the same pair (sweeps). ``sgbm``: also
    evaluate OpenCV StereoSGBM (default: when ground truth is given).
    """
    if prepared is None:
        prepared = prepare(left, right, model_params, gt)
    run = run_machine(prepared, machine_params, engine, progress, engine_options=engine_options, feed=feed)
    metrics = evaluate(prepared, run, sgbm=sgbm)
    return RunOutcome(prepared, run, metrics)
