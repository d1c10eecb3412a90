"""Design-space sweeps: every (pair x grid point) one task, in this process or on a Dask cluster.

The grid is the product of the list-valued options (``--model``, ``--rng``, every machine option
given as ``A,B,...``: ``--counter-max``, ``--word-bits``, ``--seed``...); :func:`sweep_points`
builds and validates every point before anything runs. A task (:class:`Task`) holds paths and
parameters only: the worker loads its own pair (:func:`~.datasets.load_pair`) and keeps the last
pairs and their prepared features and float64 reference in a per-process cache keyed by the pair,
the crop and the model (:func:`run_task`), so the points of one pair and model that land on one
worker prepare it once. Each task writes ``OUT/runs/<pair>/<point>/result.json`` atomically,
with a fingerprint of everything that determines it; ``--resume`` keeps the results whose
fingerprint matches and runs the rest. A task that raises (a bad pair, out of memory, a worker
that died) is reported with its pair and point and the others finish. :func:`run_sweep` then
pools the results per point (mean and std over the pairs, as the paper reports its 126 frames)
into ``OUT/sweep.json`` and plots ``OUT/sweep.png``.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import logging
import math
import os
import re
import sys
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bayesmachine.cliargs import (
    MACHINE_OPTIONS,
    MachineOption,
    counter_max_list,
    machine_default,
    machine_params_from_args,
    model_names_from_args,
    model_params_from_args,
    pass_watchdogs,
    refuse_unread_options,
    rng_list,
)
from bayesmachine.integrators import KIND_FIELDS, IntegratorKind, integrator_kind, unread_fields
from bayesmachine.models import ModelParams
from bayesmachine.outputs import OutputDir, require_ours
from bayesmachine.params import DEFAULT_INTEGRATOR, MachineParams

from .datasets import PairSpec, load_pair
from .fill import DEFAULT_FILL
from .images import Crop
from .run import prepare, run_pair
from .scheduler import connect

__all__ = [
    "SWEEP_OUTPUTS",
    "RUNS_DIR",
    "RESULT_NAME",
    "TIMING_KEYS",
    "list_option_changes",
    "Point",
    "Task",
    "TaskFailure",
    "SweepConfig",
    "SweepOutcome",
    "sweep_points",
    "make_tasks",
    "run_task",
    "run_sweep",
    "strip_timings",
]

SWEEP_OUTPUTS = ("sweep.json", "sweep.png")
RUNS_DIR = "runs"
RESULT_NAME = "result.json"
RESULT_VERSION = 1
# Measured times: they differ between two runs of the same sweep (strip_timings drops them).
TIMING_KEYS = frozenset({"seconds", "words_seconds", "reference_seconds", "total_seconds"})
# Grid order: these axes first (as the one-pair sweep always did), the counter max innermost.
_LEADING = ("model", "rng")
_SKIP = ("columns",)  # the model decides its columns
# Options a sweep always has as an axis (of their default when not given), as its grid has recorded them.
_AXES_OF_ONE = ("rng", "lfsr_bits", "seed")


# --- the grid ---------------------------------------------------------------------------------


class DefaultAxis(list):
    """The values of an axis whose option was not given (its default): a sweep refuses an option that no
    point's integrator reads only when it is given."""


def _value_list(option: MachineOption) -> Callable[[str], Any]:
    """``A,B,...`` of one machine option: each converted (or checked against its choices), no repeats.
    One value stays a value (the same as ``run`` reads), several are a list: a grid axis."""

    def parse(text: str) -> Any:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"give at least one {option.flag} value")
        values = []
        for p in parts:
            if option.choices is not None:
                if p not in option.choices:
                    raise argparse.ArgumentTypeError(f"invalid choice {p!r} (choose from "
                                                     f"{', '.join(option.choices)})")
                values.append(p)
            else:
                values.append(option.type(p))
        if len(set(values)) != len(values):
            raise argparse.ArgumentTypeError(f"a value is listed twice: {text!r}")
        return values if len(values) > 1 else values[0]

    parse.__name__ = option.field
    return parse


def list_option_changes(counter_max_default: list[int]) -> dict[str, dict[str, Any]]:
    """argparse changes making every machine option a comma-separated list (for ``sweep``).

    ``--counter-max`` is sorted with repeats removed (:func:`counter_max_list`), ``--rng`` takes the
    sources the host can run (:func:`rng_list`), a yes/no option ``on,off`` as well as ``--x`` and
    ``--no-x`` (:func:`~bayesmachine.cliargs.on_off_list`); any other option keeps its type per value. An
    option given once is a grid axis of one value."""
    changes: dict[str, dict[str, Any]] = {}
    for name, option in MACHINE_OPTIONS.items():
        if name in _SKIP:
            continue
        if option.is_flag:  # --x (on), --no-x (off), --x on,off (a grid axis of both)
            changes[name] = {"values": True}
            continue
        metavar = f"{option.metavar or 'V'},..." if option.choices is None else f"{name.upper()},..."
        if name == "counter_max":
            changes[name] = {"type": counter_max_list, "default": DefaultAxis(counter_max_default),
                             "metavar": "N,N,..."}
        elif name == "rng":
            changes[name] = {"type": rng_list, "choices": None, "metavar": "KIND,KIND,..."}
        else:
            changes[name] = {"type": _value_list(option), "choices": None, "metavar": metavar}
        if name in _AXES_OF_ONE:
            changes[name]["default"] = DefaultAxis([machine_default(name)])
    return changes


@dataclass
class Point:
    """One grid point: its model and machine, the value of each axis, a file-system-safe id."""

    index: int
    id: str
    model: ModelParams
    machine: MachineParams
    values: dict[str, Any]


def _safe(text: str) -> str:
    """A name safe as one path component: no separator, never ``.`` or ``..``, not hidden."""
    return re.sub(r"[^A-Za-z0-9._+-]+", "-", text).strip("-.") or "x"


def sweep_axes(args: argparse.Namespace) -> dict[str, list[Any]]:
    """The grid's axes in order (model, rng, the other machine options, counter max last)."""
    axes: dict[str, list[Any]] = {"model": model_names_from_args(args)}
    fields = [f for f in MACHINE_OPTIONS if f not in _SKIP]
    for name in [*(f for f in _LEADING if f in fields), *(f for f in fields if f not in _LEADING
                                                          and f != "counter_max"), "counter_max"]:
        value = getattr(args, name, None)
        if value is not None:
            axes[name] = list(value) if isinstance(value, list) else [value]
    return axes


def _unread_args(args: argparse.Namespace, kind: IntegratorKind) -> argparse.Namespace:
    """``args`` without the options ``kind``'s machine does not read (another kind's fields, a declared
    pass's watchdog where it has none): its points over their axes are one point."""
    unread = set(unread_fields([kind]))
    if "max_cycles" in unread:
        unread |= pass_watchdogs()
    return argparse.Namespace(**{k: None if k in unread else v for k, v in vars(args).items()})


def sweep_points(args: argparse.Namespace) -> list[Point]:
    """Every grid point, built and validated (a ParameterError names the option) before any run.

    Points whose model and machine equal an earlier one's (a device option of ``--rng smtj`` on a
    point of another source; a log machine's over the stochastic machine's options, the fields its
    integrator kind does not read) are one point. An option that no point's integrator reads is
    refused, as ``run`` refuses it."""
    axes = sweep_axes(args)
    kinds = [integrator_kind(name) for name in axes.get("integrator", [DEFAULT_INTEGRATOR])]
    given = {f: getattr(args, f, None) for f in KIND_FIELDS}
    refuse_unread_options(args, {f: None if isinstance(v, DefaultAxis) else v[0] if isinstance(v, list) else v
                                 for f, v in given.items()}, kinds)
    models = {name: model_params_from_args(args, name) for name in axes["model"]}
    varying = [a for a, v in axes.items() if len(v) > 1 and a not in ("model", "rng", "counter_max")]
    points: list[Point] = []
    seen: set[str] = set()
    names = list(axes)
    own_args = {kind.name: _unread_args(args, kind) for kind in kinds}
    for combo in itertools.product(*axes.values()):
        values = dict(zip(names, combo, strict=True))
        model = models[values["model"]]
        kind = integrator_kind(values.get("integrator", DEFAULT_INTEGRATOR))
        overrides = {k: v for k, v in values.items() if k != "model" and (k in kind.fields
                                                                          or k not in KIND_FIELDS)}
        machine = machine_params_from_args(own_args[kind.name], model.dmax, model=model, **overrides)
        mdict = machine.to_dict(complete=True)  # every resolved value (normalize off, not left out)
        key = json.dumps([model.name, model.to_dict(), mdict], sort_keys=True, default=str)
        if key in seen:
            continue
        seen.add(key)
        parts = [model.name, *([kind.name] if kind.named and "integrator" not in varying else []),
                 *kind.id_parts(machine), *(f"{a}{mdict[a]}" for a in varying if a in mdict)]
        # None: not this point's option (another source's, or another integrator's)
        own = {a: mdict.get(a) for a in names if a != "model"}
        points.append(Point(len(points), _safe("_".join(str(p) for p in parts)), model, machine,
                            {"model": model.name, **own}))
    if len({p.id for p in points}) != len(points):  # an option value that _safe maps onto another's
        for p in points:
            p.id = f"{p.index:04d}_{p.id}"
    return points


# --- tasks (run on a worker) --------------------------------------------------------------------


@dataclass(frozen=True)
class Task:
    """One (pair, point): everything a worker needs, as paths and parameters."""

    pair: PairSpec
    point: Point = field(compare=False)
    crop: Crop | None
    engine: str
    sgbm: bool
    result: str  # OUT/runs/<pair>/<point>/result.json
    fingerprint: str
    fill: str = DEFAULT_FILL  # host.fill's rule for the pixels without a disparity


def _fingerprint(pair: PairSpec, point: Point, crop: Crop | None, engine: str, sgbm: bool, fill: str) -> str:
    blob = json.dumps(
        {"version": RESULT_VERSION, "pair": pair.to_dict(), "crop": str(crop) if crop else None,
         "model": point.model.to_dict(), "machine": point.machine.to_dict(), "engine": engine, "sgbm": sgbm,
         "fill": fill},
        sort_keys=True, default=str,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def pair_dir_name(name: str) -> str:
    """A pair's directory under ``runs/``: its name with path separators kept as ``__``, anything else
    unsafe in a path (``..``, a leading dot, a character outside ``A-Za-z0-9._+-``) replaced."""
    return _safe(name.replace("/", "__"))


def make_tasks(pairs: list[PairSpec], points: list[Point], out: Path, crop: Crop | None, engine: str,
               sgbm: bool, fill: str = DEFAULT_FILL) -> list[Task]:
    """Pair-major tasks (a worker meets a pair's points together: its cache serves them); OpenCV's
    SGBM / StereoBM figures with the first point of each pair only; every task's map filled by ``fill``
    (:mod:`.fill`)."""
    dirs = [pair_dir_name(p.name) for p in pairs]
    if len({d.casefold() for d in dirs}) != len(dirs):  # two names made one (or one on a case-blind disk)
        dirs = [f"{i:04d}_{d}" for i, d in enumerate(dirs)]
    tasks = []
    for pair, d in zip(pairs, dirs, strict=True):
        for point in points:
            first = sgbm and point.index == 0
            tasks.append(Task(pair, point, crop, engine, first,
                              str(out / RUNS_DIR / d / point.id / RESULT_NAME),
                              _fingerprint(pair, point, crop, engine, first, fill), fill))
    return tasks


# A worker process's cache: the last pairs and prepared (features + reference) pairs. Small: the
# tasks arrive pair-major, so a pair's points follow each other.
_CACHE: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 4
CACHE_STATS = {"pair_loads": 0, "prepares": 0, "hits": 0}


def _cached(key: tuple[Any, ...], make: Callable[[], Any]) -> Any:
    with _CACHE_LOCK:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            CACHE_STATS["hits"] += 1
            return _CACHE[key]
    value = make()
    with _CACHE_LOCK:
        _CACHE[key] = value
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return value


def seed_cache(pair: PairSpec, crop: Crop | None,
               loaded: tuple[np.ndarray, np.ndarray, np.ndarray | None]) -> None:
    """Put a pair the client has already loaded (the one-pair sweep checks it first) into the cache."""
    with _CACHE_LOCK:
        _CACHE[("pair", pair, crop)] = loaded


def clear_cache() -> None:
    with _CACHE_LOCK:
        _CACHE.clear()
        for k in CACHE_STATS:
            CACHE_STATS[k] = 0


def _load(pair: PairSpec, crop: Crop | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    CACHE_STATS["pair_loads"] += 1
    return load_pair(pair, crop)


def _prepare(left: np.ndarray, right: np.ndarray, model: ModelParams, gt: np.ndarray | None) -> Any:
    CACHE_STATS["prepares"] += 1
    return prepare(left, right, model, gt)


def _task_report(outcome: Any) -> dict[str, Any]:
    run, prep = outcome.run, outcome.prepared
    return {
        **outcome.metrics.to_report(),
        "operator_samples_per_pixel": run.operator_samples_per_pixel,
        "frame_cycles": int(run.cycles.sum()),
        "wall_cycles": run.wall_cycles,
        "wall_cycles_per_pixel": None if run.wall_cycles is None else run.wall_cycles / run.cycles.size,
        "seconds": run.seconds,
        "words_seconds": run.words_seconds,
        "reference_seconds": prep.reference_seconds,
    }


def run_task(task: Task) -> dict[str, Any]:
    """Run one task where it lands (a Dask worker or this process) and write its result.json."""
    left, right, gt = _cached(("pair", task.pair, task.crop), lambda: _load(task.pair, task.crop))
    model = task.point.model
    prep = _cached(("prepared", task.pair, task.crop, model), lambda: _prepare(left, right, model, gt))
    outcome = run_pair(left, right, model, task.point.machine, engine=task.engine, prepared=prep,
                       progress=False, sgbm=task.sgbm, fill=task.fill)
    record = {
        "version": RESULT_VERSION,
        "pair": task.pair.name,
        "point": task.point.id,
        "fingerprint": task.fingerprint,
        "image_shape": list(left.shape),
        "output_shape": list(prep.shape),
        "ground_truth": gt is not None,
        "report": _task_report(outcome),
    }
    path = Path(task.result)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Its own manifest: a result.json no sweep wrote is never replaced (run_sweep refuses it up front).
    with OutputDir(path.parent, (RESULT_NAME,), last=RESULT_NAME) as out:
        text = json.dumps(record, indent=1, allow_nan=False) + "\n"
        out.write(RESULT_NAME, lambda tmp: tmp.write_text(text))
        out.commit()
    return record


def _existing(task: Task) -> dict[str, Any] | None:
    """A complete earlier result of exactly this task (--resume), else None."""
    try:
        record = json.loads(Path(task.result).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or record.get("fingerprint") != task.fingerprint \
            or not isinstance(record.get("report"), dict):
        return None
    return record


# --- executing -----------------------------------------------------------------------------------


@dataclass
class TaskFailure:
    pair: str
    point: str
    error: str

    def to_dict(self) -> dict[str, str]:
        return {"pair": self.pair, "point": self.point, "error": self.error}


def _describe(exc: BaseException) -> str:
    name = type(exc).__name__
    if name == "KilledWorker":
        return "the worker running it died (out of memory?) more than the allowed number of times"
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror or exc}"
    if isinstance(exc, MemoryError):
        return "out of memory" + (f" ({exc})" if str(exc) else "")
    text = " ".join(str(exc).split())
    return text if isinstance(exc, (ValueError, OSError)) and text else f"{name}: {text}"


def _local_cluster(workers: int, processes: bool = True) -> Any:
    from distributed import Client, LocalCluster

    # ":0": its HTTP server on a free port (None means 8787, with a warning when another cluster has it).
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                           dashboard_address=":0", silence_logs=logging.CRITICAL)
    return Client(cluster, set_as_default=False), cluster


Done = tuple[Task, dict[str, Any] | None, TaskFailure | None]


def _serial(tasks: list[Task]) -> Iterator[tuple[Done, int]]:
    for i, task in enumerate(tasks):
        running = 1 if i + 1 < len(tasks) else 0  # the next one
        try:
            yield (task, run_task(task), None), running
        except Exception as exc:  # a bad pair, out of memory: reported, the others go on
            yield (task, None, TaskFailure(task.pair.name, task.point.id, _describe(exc))), running


def _on_dask(tasks: list[Task], client: Any) -> Iterator[tuple[Done, int]]:
    from distributed import as_completed

    token = hashlib.sha256(f"{os.getpid()} {time.time()}".encode()).hexdigest()[:8]
    futures = {client.submit(run_task, t, key=f"bayesmachine-sweep-{token}-{i}", pure=False): t
               for i, t in enumerate(tasks)}
    threads = max(1, sum(client.nthreads().values()))
    try:
        for fut in as_completed(list(futures), loop=client.loop):
            task = futures.pop(fut)
            if fut.status == "finished":
                done: Done = (task, fut.result(), None)
            else:
                exc = fut.exception() if fut.status == "error" else None
                why = _describe(exc) if exc is not None else f"the task ended as {fut.status}"
                done = (task, None, TaskFailure(task.pair.name, task.point.id, why))
            fut.release()
            yield done, min(threads, len(futures))
    finally:
        if futures:  # interrupted: a shared cluster must not go on with our tasks
            client.cancel(list(futures))


# --- the sweep -----------------------------------------------------------------------------------


@dataclass
class SweepConfig:
    """What ``bayesmachine sweep`` runs. ``workers``: 0 runs the tasks in this process; N > 0 on a
    LocalCluster of N worker processes (``processes=False``: threads); ``scheduler``: on that
    cluster instead."""

    pairs: list[PairSpec]
    points: list[Point]
    output: Path
    engine: str = "model"
    crop: Crop | None = None
    sgbm: bool = True
    fill: str = DEFAULT_FILL
    resume: bool = False
    workers: int = 0
    processes: bool = True
    scheduler: str | None = None
    connect_timeout: float = 5.0
    progress: bool = False
    input: str = ""
    dataset: dict[str, Any] | None = None


@dataclass
class SweepOutcome:
    sweep: dict[str, Any]
    failures: list[TaskFailure]
    written: list[Path]
    ran: int
    resumed: int


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def pool(reports: list[dict[str, Any]]) -> tuple[dict[str, float | None], dict[str, float | None]]:
    """Mean and std (over the pairs, ddof 0) of every numeric figure of per-pair reports; a figure
    some pair lacks (None: e.g. no ground truth) is pooled over the pairs that have it."""
    keys = list(dict.fromkeys(k for r in reports for k, v in r.items() if _number(v) or v is None))
    mean: dict[str, float | None] = {}
    std: dict[str, float | None] = {}
    for k in keys:
        vals = [float(r[k]) for r in reports if _number(r.get(k))]
        mean[k] = float(np.mean(vals)) if vals else None
        std[k] = float(np.std(vals)) if vals else None
    return mean, std


def strip_timings(obj: Any) -> Any:
    """``obj`` without its measured times (:data:`TIMING_KEYS`): what two runs of one sweep share."""
    if isinstance(obj, dict):
        return {k: strip_timings(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [strip_timings(v) for v in obj]
    return obj


def _pair_entries(config: SweepConfig, records: dict[tuple[str, str], dict[str, Any]]
                  ) -> tuple[list[dict[str, Any]], dict[str, float]]:
    """Each pair's entry of sweep.json (its figures per point) and the reference's seconds per model."""
    points, pairs = config.points, config.pairs
    ref_seconds: dict[str, float] = {}
    pair_entries = []
    for pr in pairs:
        results = {}
        info: dict[str, Any] = {}
        for point in points:
            rec = records.get((pr.name, point.id))
            if rec is None:
                continue
            results[point.id] = rec["report"]
            if not info:
                info = {k: rec[k] for k in ("image_shape", "output_shape", "ground_truth")}
            elif rec["output_shape"] != info["output_shape"]:
                # A model of another margin (census 7x7) has its own output region.
                results[point.id] = {**rec["report"], "output_shape": rec["output_shape"]}
            # The reference is computed once per pair and model: count it once.
            key = f"{pr.name}\0{point.model.name}"
            if key not in ref_seconds:
                ref_seconds[key] = rec["report"].get("reference_seconds") or 0.0
        pair_entries.append({**pr.to_dict(), **info, "results": results})
    by_model: dict[str, float] = {}
    for key, s in ref_seconds.items():
        name = key.split("\0", 1)[1]
        by_model[name] = by_model.get(name, 0.0) + s
    return pair_entries, by_model


def _aggregate(config: SweepConfig, records: dict[tuple[str, str], dict[str, Any]],
               failures: list[TaskFailure], seconds: float) -> dict[str, Any]:
    points, pairs = config.points, config.pairs
    own = ("counter_max", "rng", "smtj_dwell", "smtj_spread", "smtj_share")
    dicts = [p.machine.to_dict(complete=True) for p in points]  # what ran, every value resolved
    common = {k: v for k, v in dicts[0].items() if k not in own and all(d.get(k) == v for d in dicts)}
    failed: dict[str, int] = {}
    for f in failures:
        failed[f.point] = failed.get(f.point, 0) + 1
    out_points = []
    for point, mdict in zip(points, dicts, strict=True):
        reports = [records[(pr.name, point.id)]["report"] for pr in pairs if (pr.name, point.id) in records]
        mean, std = pool(reports)
        entry: dict[str, Any] = {"id": point.id, "engine": config.engine, "rng": point.machine.rng,
                                 "counter_max": point.machine.counter_max, "model_name": point.model.name,
                                 "grid": point.values, "pairs": len(reports),
                                 "failed": failed.get(point.id, 0)}
        entry.update(mean)
        entry["std"] = std
        if len(pairs) == 1:  # a model of another margin (census 7x7) has its own output region
            shapes = [records[(pairs[0].name, p.id)]["output_shape"] for p in points
                      if (pairs[0].name, p.id) in records]
            rec = records.get((pairs[0].name, point.id))
            if rec is not None and rec["output_shape"] != shapes[0]:
                entry["output_shape"] = rec["output_shape"]
        entry["model"] = point.model.to_dict()
        device = {k: v for k, v in mdict.items() if k.startswith("smtj_")}
        if device:  # the device options are the smtj points' own
            entry["device"] = device
        mine = {k: v for k, v in mdict.items() if k not in own and k not in common}
        if mine:
            entry["machine"] = mine
        out_points.append(entry)
    pair_entries, by_model = _pair_entries(config, records)
    axes: dict[str, list[Any]] = {}
    for p in points:
        for k, v in p.values.items():
            axes.setdefault(k, [])
            if v not in axes[k]:
                axes[k].append(v)
    return {
        "engine": config.engine,
        "input": config.input,
        "dataset": config.dataset,
        "crop": str(config.crop) if config.crop is not None else None,
        "fill": config.fill,
        "output_shape": pair_entries[0].get("output_shape") if len(pairs) == 1 else None,
        "ground_truth": any(e.get("ground_truth") for e in pair_entries),
        "reference_seconds": by_model,
        "total_seconds": seconds,
        "models": axes["model"],
        "rng": axes.get("rng", []),
        "grid": axes,
        "machine": common,
        "points": out_points,
        "pairs": pair_entries,
        "tasks": len(pairs) * len(points),
        "failures": [f.to_dict() for f in failures],
    }


def _plot(path: Path, sweep: dict[str, Any]) -> None:
    from .plots import save_dataset_sweep_figure, save_sweep_figure

    points = [p for p in sweep["points"] if p["pairs"]]  # a point whose every task failed has no figures
    if len(sweep["pairs"]) > 1:
        save_dataset_sweep_figure(path, points)
        return
    # One pair: the paper's Fig 6 (cycles with their spread over pixels); several models: one colour
    # per model and source.
    several = len(sweep["models"]) > 1
    # A series per random source, or per integrator where a machine has none (a log machine).
    series = [dict(p, rng=p["rng"] if p["rng"] is not None else p["grid"].get("integrator")) for p in points]
    save_sweep_figure(path, [dict(p, rng=f"{p['model_name']} {p['rng']}") if several else p for p in series])


def run_sweep(config: SweepConfig, client: Any = None) -> SweepOutcome:
    """Run (or, ``resume``, finish) the sweep into ``config.output``; ``client``: a Dask client to use
    (else one per ``config``: this process, a LocalCluster, or ``--scheduler``'s cluster)."""
    # Absolute: a worker elsewhere (--scheduler) has its own working directory.
    tasks = make_tasks(config.pairs, config.points, config.output.absolute(), config.crop, config.engine,
                       config.sgbm, config.fill)
    records: dict[tuple[str, str], dict[str, Any]] = {}
    failures: list[TaskFailure] = []
    with OutputDir(config.output, SWEEP_OUTPUTS, last="sweep.json") as out:
        for task in tasks:  # before any work: a result.json no sweep wrote is the user's
            require_ours(task.result)
        pending = []
        for task in tasks:
            old = _existing(task) if config.resume else None
            if old is not None:
                records[(task.pair.name, task.point.id)] = old
            else:
                pending.append(task)
        resumed = len(records)
        t0 = time.perf_counter()
        own_client = own_cluster = None
        if pending and client is None and config.scheduler is not None:
            client = own_client = connect(config.scheduler, config.connect_timeout)
        elif pending and client is None and config.workers > 0:
            own_client, own_cluster = _local_cluster(config.workers, config.processes)
            client = own_client
        try:
            stream = _serial(pending) if client is None else _on_dask(pending, client)
            with tqdm(total=len(tasks), initial=resumed, unit="task", disable=not config.progress,
                      desc="sweep", file=sys.stderr) as bar:
                ok = bad = 0
                for (task, record, failure), running in stream:
                    if record is not None:
                        records[(task.pair.name, task.point.id)] = record
                        ok += 1
                    else:
                        failures.append(failure)  # type: ignore[arg-type]
                        bad += 1
                    bar.update(1)
                    bar.set_postfix_str(f"done {resumed + ok}, failed {bad}, running {running}")
        finally:
            if own_client is not None:
                own_client.close()
            if own_cluster is not None:
                own_cluster.close()
                if config.engine == "verilator":
                    # Its workers are gone; any killed mid-compile left a temporary build directory.
                    from bayesmachine.sim.verilator.build import remove_stale_builds

                    remove_stale_builds()
        order = {(t.pair.name, t.point.id): i for i, t in enumerate(tasks)}
        failures.sort(key=lambda f: order[(f.pair, f.point)])
        sweep = _aggregate(config, records, failures, time.perf_counter() - t0)
        if records:  # every task failed: sweep.json lists why, and there is nothing to plot
            out.write("sweep.png", lambda path: _plot(path, sweep))
        out.write("sweep.json",
                  lambda path: path.write_text(json.dumps(sweep, indent=2, allow_nan=False) + "\n"))
        written = out.commit()
    return SweepOutcome(sweep, failures, written, len(pending), resumed)
