"""``bayesmachine sweep``: the machine over a grid of designs, on one pair or a whole dataset (Dask)."""

from __future__ import annotations

import argparse
import os
import sys

from bayesmachine.cliargs import (
    MACHINE_OPTIONS,
    add_model_options,
    argument_type,
    input_path,
    positive_float_at_most,
)
from bayesmachine.extras import needs_host
from bayesmachine.integrators import integrator_kind
from bayesmachine.params import DEFAULT_INTEGRATOR, DEFAULT_RNG
from bayesmachine.region import OutputRegion

from ..datasets import PairSpec, bundled_spec, files_spec, resolve_dataset
from ..run import ENGINES
from ..scheduler import parse_scheduler
from ..sweep import Point, SweepConfig, list_option_changes, run_sweep, seed_cache, sweep_points
from .options import (
    add_fill_option,
    add_gt_options,
    add_host_machine_options,
    add_input_options,
    add_output_options,
    check_fits,
    host_rng_help,
    load_inputs,
)

SWEEP_COUNTER_MAX = [1, 2, 4, 8, 16, 32]
MAX_CONNECT_S = 600.0  # --connect-timeout: a cluster that takes longer to answer is not coming


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``sweep`` to the ``bayesmachine`` parser."""
    p = subparsers.add_parser(
        "sweep",
        help="paper Fig 6 over a grid of designs, on one pair or a whole dataset (Dask)",
        description="Run the machine over a grid of designs -- the product of every option given as a "
        "comma-separated list (--model, --rng, --counter-max, --word-bits, --seed, ...) -- on one pair "
        "(LEFT RIGHT, or the bundled pair) or on every pair of a dataset (--dataset: Middlebury, KITTI, "
        "a list file, frame directories or videos). Every (pair, point) is one task: in this process "
        "(one pair, by default), on a local Dask cluster of --workers processes (a dataset, by default "
        "one per core) or on a Dask cluster (--scheduler). Each task writes OUT/runs/<pair>/<point>/"
        "result.json; --resume keeps the complete ones. OUT/sweep.json (written last) holds each point's "
        "figures as the mean (and std) over the pairs, each pair's figures and the failed tasks; "
        "OUT/sweep.png plots accuracy and cycles per pixel against counter max. Exit code 1 when a task "
        "failed (each reported with its pair and point; the others complete).",
    )
    add_input_options(p, optional=True)
    add_model_options(p, census=True, sweep=True)
    _add_sweep_options(p)
    d = p.add_argument_group("dataset and cluster")
    d.add_argument("--dataset", nargs="+", metavar="PATH", default=None, type=input_path,
                   help="a dataset directory (Middlebury 2001-2006 or 2014/2021/MiddEval3 scenes, KITTI "
                   "2012/2015, left/ and right/ frame directories; searched recursively), a list file "
                   "('left right [gt [gt_scale]]' per line), or two frame directories or two video files")
    d.add_argument("--pairs", type=argument_type(_parse_slice, "pairs"), default=None,
                   metavar="START:STOP[:STEP]",
                   help="run these of the dataset's pairs (Python slice, in the layout's order), e.g. "
                   "0:6300:50 for every 50th frame")
    d.add_argument("--kitti-gt", choices=("noc", "occ"), default=None,
                   help="KITTI ground truth: disp_noc (non-occluded pixels, default) or disp_occ (all); "
                   "refused for a dataset without KITTI pairs")
    d.add_argument("--workers", type=argument_type(_parse_workers, "workers"), default=None, metavar="N",
                   help=f"local Dask worker processes, 0 to twice the cores ({_max_workers()} here) "
                   "(default: one per core with --dataset, 0 = in this process for one pair)")
    d.add_argument("--scheduler", type=argument_type(parse_scheduler, "scheduler"), default=None,
                   metavar="ADDRESS",
                   help="run the tasks on the Dask cluster whose scheduler is at ADDRESS (tcp://HOST:PORT, "
                   "e.g. tcp://head:8786); the workers need this package, the dataset and OUT at the same "
                   "paths")
    d.add_argument("--connect-timeout", type=positive_float_at_most(MAX_CONNECT_S), default=5.0, metavar="S",
                   help=f"give up on --scheduler after S seconds (at most {MAX_CONNECT_S:g}, default 5; "
                   "at once when nothing listens at a local address)")
    d.add_argument("--resume", action="store_true",
                   help="keep the tasks whose OUT/runs/.../result.json is complete and of the same pair and "
                   "point (an interrupted or partly failed sweep); run the rest")
    p.set_defaults(func=needs_host(_cmd_sweep))


def _add_sweep_options(p: argparse.ArgumentParser) -> None:
    """The machine options, each a comma-separated list (a grid axis), and the engine, ground truth and
    outputs of a sweep."""
    helps = {
        "rng": "comma-separated random sources to compare side by side, each over every counter max; "
        + host_rng_help() + f" (default {DEFAULT_RNG})",
        "counter_max": "comma-separated counter max values, run in ascending order with repeats removed "
        f"(default {','.join(map(str, SWEEP_COUNTER_MAX))})",
    }
    for name, option in MACHINE_OPTIONS.items():
        if name not in ("rng", "counter_max", "columns") and not option.is_flag:  # a list, a grid axis
            helps[name] = helps.get(name, option.help_text) + "; A,B,... sweeps it (a grid axis)"
    g = add_host_machine_options(p, help=helps, **list_option_changes(SWEEP_COUNTER_MAX))
    g.add_argument(
        "--engine", choices=ENGINES, default="model", help="how to run the machine (default model)"
    )
    add_fill_option(g, "Each result.json and sweep.json give both maps' figures (filled_*)")
    add_gt_options(p, scale_note="; with --dataset it replaces the layout's scale")
    add_output_options(p)


def _parse_slice(text: str) -> slice:
    """``START:STOP[:STEP]`` (any part may be empty), as a Python slice of the dataset's pairs."""
    parts = text.split(":")
    if not 2 <= len(parts) <= 3:
        raise ValueError(f"--pairs takes START:STOP[:STEP], got {text!r}")
    try:
        values = [int(v) if v.strip() else None for v in parts]
    except ValueError:
        raise ValueError(f"--pairs takes integers START:STOP[:STEP], got {text!r}") from None
    if len(values) == 3 and values[2] is not None and values[2] <= 0:
        raise ValueError(f"--pairs: STEP must be > 0, got {values[2]}")
    return slice(*values)


def _max_workers() -> int:
    """Local worker processes at most: twice the cores (more only compete for them, and each holds
    its own pairs and compiled kernels in memory)."""
    return 2 * (os.cpu_count() or 1)


def _parse_workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise ValueError(f"expected a number of workers, got {text!r}") from None
    if not 0 <= n <= _max_workers():
        raise ValueError(f"expected 0 (this process) to {_max_workers()} (twice this machine's cores) "
                         f"workers, got {n}")
    return n



def _sweep_pairs(
    args: argparse.Namespace, points: list[Point]
) -> tuple[list[PairSpec], str, dict[str, object] | None]:
    """The pairs of a sweep: ``--dataset``'s, or the one pair of LEFT RIGHT (or the bundled one),
    which is loaded and sized here first so that a bad input is one error line, as for ``run``."""
    if args.dataset is None:
        given = [f for f, v in (("--pairs", args.pairs), ("--kitti-gt", args.kitti_gt)) if v is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: options of --dataset (a sweep of one pair has no others)")
        left, right, gt, source = load_inputs(args, with_gt=True)
        for point in points:  # each model on its own output region (OutputRegion.of_model)
            check_fits(OutputRegion.of_model(left.shape, point.model), point.machine)
        if args.left is None:
            spec = bundled_spec()
        else:
            spec = files_spec(os.path.abspath(args.left), os.path.abspath(args.right),
                              os.path.abspath(args.gt) if args.gt else None, args.gt_scale)
        seed_cache(spec, args.crop, (left, right, gt))  # the in-process run does not load it again
        return [spec], source, None
    if args.left is not None:
        raise ValueError("give LEFT RIGHT or --dataset, not both")
    if args.gt:
        raise ValueError("--gt: the dataset's layout names each pair's ground truth (--gt-scale replaces "
                         "its scale)")
    # Absolute paths: a worker elsewhere (--scheduler) has its own working directory.
    dataset = resolve_dataset([os.path.abspath(p) for p in args.dataset], gt_scale=args.gt_scale,
                              occluded=args.kitti_gt == "occ")
    if args.kitti_gt is not None and "kitti" not in dataset.layout.split("+"):
        raise ValueError(f"--kitti-gt {args.kitti_gt}: the dataset has no KITTI pairs (its layout: "
                         f"{dataset.layout})")
    pairs = dataset.pairs[args.pairs] if args.pairs is not None else dataset.pairs
    if not pairs:
        raise ValueError(f"--pairs {_slice_text(args.pairs)} selects none of the dataset's "
                         f"{len(dataset.pairs)} pairs")
    described: dict[str, object] = {"path": dataset.path, "layout": dataset.layout,
                                    "pairs_found": len(dataset.pairs)}
    if dataset.skipped:
        described["skipped"] = dataset.skipped
    for why in dataset.skipped:  # never skipped without a word, --quiet or not
        print(f"note: skipped {why}", file=sys.stderr)
    return pairs, " ".join(args.dataset), described


def _slice_text(s: slice | None) -> str:
    return "(all)" if s is None else ":".join("" if v is None else str(v) for v in (s.start, s.stop, s.step))


def _cmd_sweep(args: argparse.Namespace) -> int:
    if args.workers is not None and args.scheduler is not None:
        raise ValueError("--workers sizes a local cluster and --scheduler names another one: "
                         "give one of them")
    points = sweep_points(args)  # every point validated before any input is read
    pairs, source, dataset = _sweep_pairs(args, points)
    workers = args.workers
    if workers is None:  # one pair: this process (its points share one prepared pair); a dataset: all cores
        workers = 0 if dataset is None and args.scheduler is None else (os.cpu_count() or 1)
    progress = not args.quiet and sys.stderr.isatty()
    if not args.quiet:
        for pair in pairs:
            if pair.note and dataset is not None:
                print(f"note: {pair.name}: {pair.note}", file=sys.stderr)
            if pair.dmax_hint is not None and pair.dmax_hint > args.dmax:
                print(f"note: {pair.name}: the dataset says disparities reach {pair.dmax_hint}, above --dmax "
                      f"{args.dmax} (nearer surfaces will not match)", file=sys.stderr)
        where = (f"on the Dask cluster at {args.scheduler}" if args.scheduler else
                 f"on a local Dask cluster of {workers} worker process(es)" if workers else "in this process")
        print(f"sweep: {len(pairs)} pair(s) x {len(points)} point(s) = {len(pairs) * len(points)} tasks "
              f"{where}", flush=True)
    config = SweepConfig(pairs=pairs, points=points, output=args.output, engine=args.engine, crop=args.crop,
                         sgbm=not args.no_sgbm, fill=args.fill, resume=args.resume, workers=workers,
                         scheduler=args.scheduler, connect_timeout=args.connect_timeout, progress=progress,
                         input=source, dataset=dataset)
    outcome = run_sweep(config)
    if not args.quiet:
        if outcome.resumed:
            print(f"resumed: {outcome.resumed} task(s) complete from an earlier run, {outcome.ran} run now")
        for point in outcome.sweep["points"]:
            varying = [k for k, v in outcome.sweep["grid"].items()
                       if len(v) > 1 and k not in ("model", "rng", "counter_max")]
            print(_pooled_summary(point, len(pairs), varying), flush=True)
        print("wrote " + ", ".join(str(p) for p in outcome.written))
    for f in outcome.failures:
        print(f"bayesmachine sweep: task failed: pair {f.pair}, point {f.point}: {f.error}", file=sys.stderr)
    if outcome.failures:
        tasks, failed = len(pairs) * len(points), len(outcome.failures)
        what = (f"all {tasks} tasks failed; their reasons are" if failed == tasks
                else f"{failed} of {tasks} tasks failed; the others are")
        print(f"bayesmachine sweep: {what} in {args.output / 'sweep.json'} (rerun with --resume to retry the "
              "failed ones)", file=sys.stderr)
        return 1
    return 0


def _pooled_summary(p: dict[str, object], pairs: int, varying: list[str]) -> str:
    """One point of a sweep: its figures (the mean over the pairs, +- std over them with several)."""
    std = p.get("std") or {}

    def f(key: str, fmt: str = ".4f") -> str:
        v = p.get(key)
        if v is None:
            return "n/a"
        s = std.get(key) if pairs > 1 else None  # type: ignore[union-attr]
        return format(v, fmt) + ("" if s is None else f" +- {format(s, fmt)}")

    kind = integrator_kind(p["grid"].get("integrator", DEFAULT_INTEGRATOR))  # type: ignore[union-attr]
    line = (f"{p['engine']} model={p['model_name']}"
            + (f" integrator={kind.name}" if kind.named and "integrator" not in varying else "")
            + "".join(f" {part}" for part in kind.label_parts(p))
            + "".join(f" {k}={p['grid'][k]}" for k in varying)  # type: ignore[index]
            + (f" ({p['pairs']} pairs)" if pairs > 1 else "")
            + f": {f('cycles_per_pixel_mean', '.2f')} cycles/px, RMS {f('rms_error')}, "
            f"no-match F1 {f('nomatch_f1')}, MAP agreement {f('map_agreement')}")
    if p.get("machine_bad2_nomatch_bad") is not None:
        line += f", bad-2 {f('machine_bad2_nomatch_bad')} (reference {f('reference_bad2_nomatch_bad')})"
    if p.get("machine_confidence_auc") is not None:
        line += (f", confidence ECE {f('machine_confidence_ece')}, sparsification AUC "
                 f"{f('machine_confidence_auc')} (random {f('machine_confidence_auc_random')})")
    if p.get("failed"):
        line += f"; {p['failed']} pair(s) failed"
    return line

