"""Host subcommands of ``bayesmachine``: reference, run, sweep.

``bayesmachine/cli.py`` calls :func:`register`; every ValueError or OSError raised here
(bad input, impossible parameters, file-system problems) ends as one error line there.
Machine options come from the shared helper :mod:`bayesmachine.cliargs`; outputs are
written through :mod:`bayesmachine.outputs` (complete or absent, the report last).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from bayesmachine.cliargs import (
    BAUD_RANGE,
    DEFAULT_BAUD,
    MACHINE_OPTIONS,
    MAX_SILENCE_S,
    add_machine_options,
    add_model_options,
    argument_type,
    float_arg,
    input_path,
    int_arg,
    int_in_range,
    machine_params_from_args,
    model_params_from_args,
    options_without_effect,
    output_path,
    pass_watchdogs,
    positive_float_at_most,
    refuse_log_integrator,
    runnable_sources,
)
from bayesmachine.extras import needs_host
from bayesmachine.hdl.frontend import MAX_MACHINES
from bayesmachine.models import ModelParams, all_options
from bayesmachine.outputs import (
    NpzWriter,
    OutputDir,
    atomic_file,
    format_bytes,
    require_disk,
    require_memory,
)
from bayesmachine.params import DEFAULT_RNG, MachineParams
from bayesmachine.region import OutputRegion
from bayesmachine.sim.engines import check_pixel_engine_options

from .calib import BUNDLED_CALIB, KITTI_CAMERAS, StereoCalibration, bundled_calibration_path, read_calibration
from .confidence import DEFAULT_T, DEFAULT_WINDOW, MAX_T, MAX_WINDOW, ConfidenceParams
from .datasets import PairSpec, bundled_spec, files_spec, resolve_dataset
from .features import model_planes
from .images import Crop, bundled_pair, crop_image, load_gt, load_image, parse_crop, validate_pair
from .reference import reference_bands, warm_up
from .run import ENGINES, FEEDS, RunOutcome, result_bytes, run_pair
from .sweep import (
    SWEEP_OUTPUTS,
    Point,
    SweepConfig,
    list_option_changes,
    parse_scheduler,
    run_sweep,
    seed_cache,
    sweep_points,
)

__all__ = ["register", "RUN_OUTPUTS", "SWEEP_OUTPUTS"]

# Every file each command can write into OUT/, the report first (it is removed first and
# committed last: its presence means the rest is complete and from the same run).
RUN_OUTPUTS = ("report.json", "result.npz", "disparity.png", "confidence.png", "calibration.png", "depth.npy",
               "cloud.ply", "waves.vcd")
SWEEP_COUNTER_MAX = [1, 2, 4, 8, 16, 32]
MAX_CONNECT_S = 600.0  # --connect-timeout: a cluster that takes longer to answer is not coming
MAX_GT_SCALE = 65536.0  # --gt-scale: past it every 16-bit stored disparity is below one pixel


def _add_input_options(p: argparse.ArgumentParser, optional: bool) -> None:
    nargs = "?" if optional else None
    extra = " (omit both for the bundled Middlebury Motorcycle pair)" if optional else ""
    p.add_argument("left", nargs=nargs, type=input_path, help=f"rectified left image{extra}")
    p.add_argument("right", nargs=nargs, type=input_path, help="rectified right image")
    p.add_argument(
        "--crop",
        type=argument_type(parse_crop, "crop"),
        default=None,
        metavar="X,Y,W,H",
        help="cut this rectangle (input-image pixels) out of both images (and gt) first",
    )


def _load_inputs(
    args: argparse.Namespace, with_gt: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, str]:
    """Gray left, right, optional gt (all cropped) and a description of the input."""
    gt = None
    if args.left is None and args.right is None:
        left, right, bundled_gt = bundled_pair()
        source = "bundled Middlebury 2014 Motorcycle (scikit-image)"
        if with_gt:
            gt = bundled_gt
    elif args.left is None or args.right is None:
        raise ValueError("give both LEFT and RIGHT images, or neither for the bundled pair")
    else:
        left, right = load_image(args.left), load_image(args.right)
        source = f"{args.left} {args.right}"
    if getattr(args, "gt_scale", None) is not None and not getattr(args, "gt", None):
        raise ValueError("--gt-scale: it scales the --gt file; give --gt too")
    if with_gt and getattr(args, "gt", None):
        gt = load_gt(args.gt, scale=args.gt_scale)
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in shape: {left.shape} vs {right.shape}")
    if gt is not None and gt.shape != left.shape:
        raise ValueError(f"ground truth shape {gt.shape} differs from the images' {left.shape}")
    crop: Crop | None = args.crop
    args.input_shape = left.shape  # before the crop: what a calibration file's image size is checked against
    left, right = crop_image(left, crop), crop_image(right, crop)
    if gt is not None:
        gt = crop_image(gt, crop)
    return np.ascontiguousarray(left), np.ascontiguousarray(right), gt, source


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


def _host_rng_help() -> str:
    return f"random source; the host runs the kinds it can drive: {', '.join(runnable_sources())}"


def _check_host_rng(machine: MachineParams) -> None:
    """The host drives on-chip sources and off-chip ones with a device model; not bare ``external``."""
    if machine.rng not in runnable_sources():
        raise ValueError(
            f"--rng {machine.rng}: the machine takes its random numbers on the entropy port and "
            f"this source has no model the host can run; use it with 'bayesmachine emit'"
        )


def _add_machine_options(p: argparse.ArgumentParser, sweep: bool) -> None:
    changes: dict[str, dict[str, object]] = {}
    helps = {
        "rng": _host_rng_help() + " (default %(default)s)",
    }
    if sweep:
        changes = list_option_changes(SWEEP_COUNTER_MAX)
        helps["rng"] = (
            "comma-separated random sources to compare side by side, each over every counter max; "
            + _host_rng_help() + f" (default {DEFAULT_RNG})"
        )
        helps["counter_max"] = (
            "comma-separated counter max values, run in ascending order with repeats removed "
            f"(default {','.join(map(str, SWEEP_COUNTER_MAX))})"
        )
        for name, option in MACHINE_OPTIONS.items():
            if name not in ("rng", "counter_max", "columns") and not option.is_flag:  # a list, a grid axis
                helps[name] = helps.get(name, option.help_text) + "; A,B,... sweeps it (a grid axis)"
    g = add_machine_options(p, skip=("columns",), help=helps, **changes)
    if sweep:
        g.add_argument(
            "--engine", choices=ENGINES, default="model", help="how to run the machine (default model)"
        )
    else:
        g.add_argument(
            "--engine", choices=(*ENGINES, "board"), default="model",  # board: a pixel engine
            help="how to run the machine (default model); board: the StereoMachine on a board (or "
            "`bayesmachine board simulate`) over a serial port, --port (docs/board.md)",
        )
        g.add_argument("--port", default=None, type=input_path,
                       help="with --engine board: the serial port (/dev/ttyUSB0, or the path board simulate "
                       "printed)")
        g.add_argument("--baud", type=int_in_range(*BAUD_RANGE), default=None,
                       help="with --engine board: the baud rate the bitstream was built for "
                       f"({BAUD_RANGE[0]} to {BAUD_RANGE[1]}, default {DEFAULT_BAUD})")
        g.add_argument("--board-fields", default=None, metavar="LIST",
                       help="with --engine board: the result fields the board sends, a comma-separated "
                       "list of map, counts, cycles (default all three; the MAP and its flags always "
                       "come). --board-fields map cuts the results' bytes on the link; result.npz then "
                       "has no counts or cycles and report.json's figures of them are null")
        g.add_argument("--board-timeout", type=positive_float_at_most(MAX_SILENCE_S), default=None,
                       metavar="S", help="with --engine board: seconds of silence before the board is deemed "
                       f"not to answer (at most {MAX_SILENCE_S:g}, default 2)")
        g.add_argument(
            "--feed",
            choices=FEEDS,
            default=None,
            help="words: the host computes each pixel's likelihood words (default); pixels: the pair "
            "goes into the on-chip front end + machine (StereoMachine RTL, --engine verilator; what "
            "--engine board runs)",
        )
        g.add_argument(
            "--machines", type=int_in_range(1, MAX_MACHINES), default=None,
            help=f"machines behind the one front end (1 .. {MAX_MACHINES}, default 1): map row r runs on "
            "machine r mod K, each with its own random source and left neighbour (--feed pixels: the "
            "StereoMachine with K machines; --feed words: K engines dealt the rows the same way)",
        )
        g.add_argument(
            "--waves",
            metavar="FIRST:LAST",
            default=None,
            help="with --engine verilator: write OUT/waves.vcd while output pixels FIRST..LAST "
            "(row-major over the output region, from 0) are in the machine",
        )
    p.add_argument(
        "--gt", default=None, type=input_path,
        help="ground-truth disparity: .pfm (floats, inf = unknown), .npy (numbers, non-finite = unknown) "
        "or a one-channel image (0 = unknown; 8-bit at face value, 16-bit only with --gt-scale); "
        "negative disparities are refused",
    )
    p.add_argument(
        "--gt-scale", type=positive_float_at_most(MAX_GT_SCALE), default=None, metavar="S",
        help="the --gt file stores disparity x S: divide by S (256 for KITTI's 16-bit PNGs; 4 for "
        f"Middlebury 2003's quarter-size disp*.png), at most {MAX_GT_SCALE:g}; default 1, required for "
        "16-bit images"
        + ("; with --dataset it replaces the layout's scale" if sweep else ""),
    )
    if not sweep:
        _add_confidence_options(p)
    p.add_argument("--no-sgbm", action="store_true", help="skip the OpenCV StereoSGBM comparison")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("-o", "--output", required=True, type=output_path, metavar="OUT/",
                   help="output directory; only files bayesmachine wrote there are ever replaced or removed, "
                   "and one run at a time may write into it")


def _parse_probability(text: str) -> float:
    value = float_arg(text)
    if not 0.0 < value <= 1.0:
        raise ValueError(f"expected a probability in (0, 1], got {text!r}")
    return value


def _confidence_parameter(name: str):  # noqa: ANN202
    """``--confidence-t`` / ``--confidence-window``: an integer ConfidenceParams takes (its bounds)."""

    def parse(text: str) -> int:
        value = int_arg(text)
        ConfidenceParams(**{name: value})
        return value

    return parse


def _parse_cameras(text: str) -> tuple[int, int]:
    try:
        left, right = (int(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"expected two camera numbers L,R (e.g. 2,3), got {text!r}") from None
    if not (0 <= left <= 3 and 0 <= right <= 3) or left == right:
        raise ValueError(f"expected two different KITTI cameras 0..3, got {text!r}")
    return left, right


def _add_confidence_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("confidence and depth (docs/confidence.md)")
    g.add_argument("--confidence-t", type=argument_type(_confidence_parameter("t"), "t"), default=DEFAULT_T,
                   metavar="T", help="a pixel's confidence is the mass of its distribution within +-T "
                   f"disparities of its MAP: it predicts |d - gt| <= T; 0 .. {MAX_T} (default {DEFAULT_T})")
    g.add_argument("--confidence-window", type=argument_type(_confidence_parameter("window"), "window"),
                   default=DEFAULT_WINDOW, metavar="W",
                   help="pool (average) the distributions of the WxW pixels around a pixel before reading "
                   f"that mass; odd, 1 (the pixel's own) .. {MAX_WINDOW} (default {DEFAULT_WINDOW})")
    g.add_argument("--min-confidence", type=argument_type(_parse_probability, "probability"), default=None,
                   metavar="P", help="blank the machine's disparity in disparity.png, depth.npy and "
                   "cloud.ply where its confidence is below P; report.json gives the density kept "
                   "(result.npz keeps every MAP)")
    g.add_argument("--calib", default=None, type=input_path, metavar="FILE",
                   help="camera calibration: a Middlebury calib.txt (baseline in mm), a KITTI calib/*.txt "
                   "or calib_cam_to_cam.txt, or JSON {fx, fy, cx, cy, baseline (metres)[, doffs, width, "
                   f"height]}}; '{BUNDLED_CALIB}': the bundled pair's. Writes depth.npy (metres) and "
                   "cloud.ply")
    g.add_argument("--calib-cameras", type=argument_type(_parse_cameras, "cameras"), default=None,
                   metavar="L,R", help="with a KITTI --calib: the left and right cameras' matrices "
                   f"(default {KITTI_CAMERAS[0]},{KITTI_CAMERAS[1]}, the colour pair; 0,1 for the gray one)")


def _machine_params(
    args: argparse.Namespace, model: ModelParams, counter_max: int | None = None, rng: str | None = None
) -> MachineParams:
    """The machine ``model`` needs (``disparity_machine``: the census model's neighbour prior) from the
    machine options."""
    overrides: dict[str, object] = {} if counter_max is None else {"counter_max": counter_max}
    if rng is not None:
        overrides["rng"] = rng
    machine = machine_params_from_args(args, model.dmax, model=model, **overrides)
    if getattr(args, "engine", "model") == "board" or getattr(args, "feed", "words") != "words":
        refuse_log_integrator(machine, f"--engine {args.engine} --feed {getattr(args, 'feed', 'words')}")
    if getattr(args, "feed", "words") == "pixels" and args.words_per_beat is None:
        # The front end writes one feature per lane: lanes a multiple of the loaded columns.
        from bayesmachine.params import stereo_words_per_beat

        machine = dataclasses.replace(machine, words_per_beat=stereo_words_per_beat(machine))
    _check_host_rng(machine)
    return machine


def _check_fits(region: OutputRegion, machine: MachineParams) -> None:
    """Refuse up front when the per-pixel results cannot be held (they are what result.npz holds)."""
    require_memory(
        result_bytes(region, machine),
        f"the results of {region.shape[0]}x{region.shape[1]} output pixels x {machine.rows} counters",
        "use --crop or a smaller --dmax",
    )


def _report(outcome: RunOutcome, source: str, crop: Crop | None) -> dict[str, object]:
    prep, run = outcome.prepared, outcome.run
    declared = run.passes.values()  # the passes before the own one (census-lr's right): cycles count too
    frame = None if run.cycles is None else (
        int(run.cycles.sum()) + sum(int(r.cycles.sum()) for r in declared))
    wall = run.wall_cycles
    if wall is not None and any(r.wall_cycles is None for r in declared):
        wall = None
    elif wall is not None:
        wall += sum(r.wall_cycles for r in declared)
    report: dict[str, object] = {
        "engine": run.engine,
        "integrator": run.machine.integrator,
        "rng": run.machine.rng,
        "counter_max": run.machine.counter_max,
        # The cycles below are clocks: B random samples per operator and clock (results: B = 1's).
        "samples_per_clock": run.machine.samples_per_clock,
        **outcome.metrics.to_report(),
        "frame_cycles": frame,
        # Compute cycles count the machine's runs only; wall cycles (RTL engines) add loading.
        "wall_cycles": wall,
        "wall_cycles_per_pixel": None if wall is None else wall / run.map.size,
        "seconds": run.seconds,
        "words_seconds": run.words_seconds,
        "reference_seconds": prep.reference_seconds,
        "input": source,
        "crop": str(crop) if crop is not None else None,
        "image_shape": list(prep.left.shape),
        "output_shape": list(prep.shape),
        "ground_truth": prep.gt is not None,
        "model_name": prep.model.name,
        "model": prep.model.to_dict(),
        # Every pass in order, the own one last: a declared pass's figures are its name's "NAME_pass_*".
        "passes": [p.name for p in prep.model.passes],
        "machine": run.machine.to_dict(complete=True),  # every resolved value
    }
    for name, r in run.passes.items():
        report[f"{name}_pass_machine"] = r.machine.to_dict(complete=True)
        report[f"{name}_pass_seconds"] = r.seconds
    return report


def _write_json(path: Path, obj: object) -> None:
    from .metrics import json_safe

    path.write_text(json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n")


def _summary(r: dict[str, object]) -> str:
    def f(key: str, fmt: str = ".4f") -> str:
        v = r.get(key)
        return "n/a" if v is None else format(v, fmt)

    line = (
        f"{r['engine']} model={r['model_name']} "
        + ("integrator=log" if r.get("integrator") == "log"
           else f"rng={r['rng']} counter_max={r['counter_max']}")
        + (f" samples_per_clock={r['samples_per_clock']}" if r.get("samples_per_clock", 1) != 1 else "")
        + f": {r['pixels']} px, "
        f"{f('cycles_per_pixel_mean', '.2f')} +- {f('cycles_per_pixel_std', '.2f')} cycles/px, "
        f"RMS {f('rms_error')}, no-match F1 {f('nomatch_f1')}, MAP agreement {f('map_agreement')}, "
        f"timeouts {r['timeouts']}, engine {f('seconds', '.2f')} s"
    )
    *declared, own = r.get("passes") or [None]
    if declared:
        line += (f"\n  {r['model_name']}: cycles/px over all passes {f('cycles_per_pixel_mean', '.2f')}: "
                 f"{own} pass {f(f'{own}_pass_cycles_per_pixel_mean', '.2f')}" + "".join(
                     f", {n} pass {r[f'{n}_pass_pixels']} px at "
                     f"{f(f'{n}_pass_cycles_per_pixel_mean', '.2f')} (timeouts {r[f'{n}_pass_timeouts']})"
                     for n in declared))
    if r.get("wall_cycles_per_pixel") is not None:
        line += f"\n  wall cycles per pixel, loading included: {f('wall_cycles_per_pixel', '.2f')}"

    if r.get("ground_truth_pixels") == 0:
        from .metrics import NO_KNOWN_GT

        line += f"\n  {NO_KNOWN_GT}"
    elif r.get("machine_bad2") is not None or r.get("ground_truth"):
        line += (
            f"\n  bad-2 (matched / no-match bad): "
            f"machine {f('machine_bad2')} / {f('machine_bad2_nomatch_bad')}, "
            f"reference {f('reference_bad2')} / {f('reference_bad2_nomatch_bad')}"
        )
        if "sgbm_bad2" in r:
            line += f", SGBM {f('sgbm_bad2')} / {f('sgbm_bad2_nomatch_bad')}"
        if "bm_bad2" in r:
            line += f", StereoBM {f('bm_bad2')} / {f('bm_bad2_nomatch_bad')}"
        if r.get("machine_nomatch_occluded") is not None:
            line += f"\n  no-match calls on occluded pixels: machine {f('machine_nomatch_occluded', '.3f')}"
            if r.get("sgbm_nomatch_occluded") is not None:
                line += f", SGBM {f('sgbm_nomatch_occluded', '.3f')}"
    return line + _confidence_summary(r, f)


def _confidence_summary(r: dict[str, object], f) -> str:  # noqa: ANN001
    conf = r.get("confidence")
    if not isinstance(conf, dict):
        return ""
    if conf.get("machine", {}) is None:
        return "\n  confidence: none (the board sent no counts)"
    line = f"\n  confidence (mass within +-{conf['t']}, {conf['window']}x{conf['window']} pooled): mean " \
           f"{f('mean_confidence', '.3f')}"
    if r.get("machine_confidence_ece") is not None:
        line += (f", ECE {f('machine_confidence_ece')}, sparsification AUC {f('machine_confidence_auc')} "
                 f"(random {f('machine_confidence_auc_random')}, "
                 f"perfect {f('machine_confidence_auc_perfect')}; reference {f('reference_confidence_auc')}")
        line += f", SGBM left-right check {f('sgbm_lr_auc')})" if r.get("sgbm_lr_auc") is not None else ")"
    kept = r.get("min_confidence")
    if isinstance(kept, dict):
        line += f"\n  confidence >= {kept['threshold']:g}: density {kept['density']:.3f}"
        if kept.get("bad2") is not None:
            line += f", bad-2 of the kept pixels {kept['bad2']:.4f}"
    if r.get("cloud_points") is not None:
        line += f"\n  cloud.ply: {r['cloud_points']} points"
    return line


def _cmd_reference(args: argparse.Namespace) -> int:
    model = model_params_from_args(args)
    ignored = options_without_effect(args, set(all_options()) - pass_watchdogs())
    if ignored:  # as run refuses board options without --engine board
        raise ValueError(f"{', '.join(ignored)}: the watchdog of a machine's pass; reference computes the "
                         "exact float64 posterior and runs no machine")
    left, right, _, _ = _load_inputs(args, with_gt=False)
    region = OutputRegion.of_model(left.shape, model)
    out = Path(args.output)
    if out.suffix != ".npz":
        out = out.with_name(out.name + ".npz")  # what np.savez would write: say the real name
    shape = (*region.shape, model.hypotheses)
    volume = int(np.prod(shape)) * 8
    # The posterior goes to disk band by band: memory holds one band, the disk the whole volume.
    require_disk(
        out, volume + region.pixels * 2 + 4096,
        f"the posterior volume ({shape[0]}x{shape[1]}x{shape[2]} float64, {format_bytes(volume)})",
        "use --crop or a smaller --dmax",
    )
    validate_pair(left, right, model.dmax, model.margin)
    warm_up(model)  # numba's cache load stays out of the timing
    t0 = time.perf_counter()
    planes = (model_planes(left, model), model_planes(right, model))
    ref_map = np.empty(region.shape, np.int16)

    def bands():  # the posterior of each band, in order; the MAP is kept on the way
        for rows, band in reference_bands(*planes, model):
            ref_map[rows] = band.map
            yield band.posterior

    with atomic_file(out) as tmp, NpzWriter(tmp) as npz:
        npz.add_stream("posterior", shape, np.float64, bands())
        npz.add("map", ref_map)
    if not args.quiet:
        print(
            f"reference ({model.name} model): {shape[0]}x{shape[1]} px x {model.hypotheses} hypotheses "
            f"({format_bytes(volume)} of posterior) in {time.perf_counter() - t0:.3f} s, "
            f"{int((ref_map < 0).sum())} no match -> {out}"
        )
    return 0


def _parse_waves(text: str | None, engine: str) -> tuple[int, int] | None:
    """``--waves FIRST:LAST`` (output pixel indices), checked before any input is read."""
    if text is None:
        return None
    if engine != "verilator":
        raise ValueError(f"--waves needs --engine verilator (got --engine {engine})")
    try:
        first, last = (int(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"--waves takes FIRST:LAST pixel indices, e.g. 0:9; got {text!r}") from None
    if not 0 <= first <= last:
        raise ValueError(f"--waves: need 0 <= FIRST <= LAST, got {first}:{last}")
    return first, last


def _check_waves(waves: tuple[int, int] | None, pixels: int) -> None:
    """A range past the last output pixel would trace nothing: say so before any work."""
    if waves is not None and waves[1] >= pixels:
        raise ValueError(
            f"--waves {waves[0]}:{waves[1]}: the output region has {pixels} pixels (0..{pixels - 1}); "
            f"LAST must be below {pixels}"
        )


def _check_board_args(args: argparse.Namespace, model: ModelParams) -> None:
    """``--engine board`` and its options: together, and with a model the board computes."""
    given = [flag for flag, v in (("--port", args.port), ("--baud", args.baud),
                                  ("--board-timeout", args.board_timeout),
                                  ("--board-fields", args.board_fields)) if v is not None]
    if args.engine != "board":
        if given:
            raise ValueError(f"{', '.join(given)}: only with --engine board")
        args.feed = args.feed or "words"
        return
    if args.port is None:
        raise ValueError("--engine board needs --port (the board's serial port, or the path "
                         "`bayesmachine board "
                         "simulate` printed)")
    if args.waves is not None:
        raise ValueError("--waves is not available with --engine board")
    if args.feed == "words":
        raise ValueError("--engine board --feed words: the board takes the pair itself into its on-chip "
                         "front end (--feed pixels, which it runs); leave --feed out")
    args.feed = "pixels"  # the board takes the pair itself: its machine has the front end's lanes
    check_pixel_engine_options("board", **_board_options(args))  # before any work


def _board_options(args: argparse.Namespace) -> dict[str, object]:
    """The board engine's options given (the engine's own defaults for the others)."""
    given = {"baud": args.baud, "timeout": args.board_timeout, "fields": args.board_fields,
             "progress": False if args.quiet else None}
    return {"port": args.port, **{k: v for k, v in given.items() if v is not None}}


def _cmd_run(args: argparse.Namespace) -> int:
    model = model_params_from_args(args)
    _check_board_args(args, model)
    machine = _machine_params(args, model)
    waves = _parse_waves(args.waves, args.engine)
    if args.feed == "pixels" and waves is not None:
        raise ValueError("--waves is not available with --feed pixels")
    machines = 1 if args.machines is None else args.machines
    if machines != 1:
        from bayesmachine.hdl.frontend.stereo import check_machines

        if args.engine == "board":
            raise ValueError("--machines: the board carries one machine (--engine board)")
        if waves is not None:
            raise ValueError("--waves is not available with --machines")
        check_machines(machines, machine, model)
    _check_confidence_args(args)
    calib = _run_calibration(args)  # read and checked before any input is read
    left, right, gt, source = _load_inputs(args, with_gt=True)
    region = OutputRegion.of_model(left.shape, model)
    _check_waves(waves, region.pixels)
    _check_fits(region, machine)
    if calib is not None:  # its image size checked against the input's, its principal point cropped
        calib = calib.for_input(args.input_shape, args.crop)
    params = ConfidenceParams(t=args.confidence_t, window=args.confidence_window)
    # What this run writes (a user's file under another of the names stays, and does not stop it).
    optional = {"waves.vcd": waves is not None, "calibration.png": gt is not None,
                "depth.npy": calib is not None, "cloud.ply": calib is not None}
    writes = [n for n in RUN_OUTPUTS if optional.get(n, True)]
    with OutputDir(args.output, RUN_OUTPUTS, last="report.json", writes=writes) as out:
        # The harness writes the trace under its temporary name; commit() renames it with the rest.
        engine_options = {} if waves is None else {"trace": (*waves, str(out.path("waves.vcd")))}
        if args.engine == "board":
            engine_options = _board_options(args)
        outcome = run_pair(
            left,
            right,
            model,
            machine,
            engine=args.engine,
            gt=gt,
            progress=False if args.quiet else None,
            sgbm=not args.no_sgbm,
            engine_options=engine_options,
            feed=args.feed,
            machines=machines,
            confidence=params,
        )
        report = _report(outcome, source, args.crop)
        report["feed"] = args.feed
        report["machines"] = machines
        if outcome.run.engine_figures is not None:
            report[args.engine] = outcome.run.engine_figures  # the board's link: wall time, bytes, attempts
        if report.get("ground_truth_pixels") == 0 and args.quiet:  # the summary says it otherwise
            from .metrics import NO_KNOWN_GT

            print(f"bayesmachine run: note: {NO_KNOWN_GT}", file=sys.stderr)
        _write_run_outputs(out, args, outcome, report, left, calib)
        out.write("report.json", lambda path: _write_json(path, report))
        written = out.commit()
    if not args.quiet:
        print(_summary(report))
        print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _check_confidence_args(args: argparse.Namespace) -> None:
    """Options that need the counts, or the bundled pair, refused before anything runs."""
    fields = {name.strip() for name in (args.board_fields or "counts").split(",")}  # checked with the board's
    no_counts = args.engine == "board" and "counts" not in fields
    if no_counts and args.min_confidence is not None:
        raise ValueError("--min-confidence: the board sends no counts with these --board-fields, so there is "
                         "no confidence to threshold (add counts)")
    if args.calib == BUNDLED_CALIB and args.left is not None:
        raise ValueError(f"--calib {BUNDLED_CALIB} is the bundled Motorcycle pair's calibration: give the "
                         "calibration of LEFT RIGHT")
    if args.calib_cameras is not None and args.calib is None:
        raise ValueError("--calib-cameras: it picks a KITTI --calib file's matrices; give --calib too")


def _run_calibration(args: argparse.Namespace) -> StereoCalibration | None:
    """``--calib``'s calibration (its image size is checked against the input's by ``for_input``)."""
    if args.calib is None:
        return None
    path = bundled_calibration_path() if args.calib == BUNDLED_CALIB else Path(args.calib)
    return read_calibration(path, args.calib_cameras)


def _write_run_outputs(out: OutputDir, args: argparse.Namespace, outcome: RunOutcome,
                       report: dict[str, object], left: np.ndarray, calib: StereoCalibration | None) -> None:
    """Stage result.npz and the figures (and depth.npy, cloud.ply with a calibration); add the
    thresholded density and the cloud's figures to ``report``."""
    from .plots import save_calibration_figure, save_confidence_figure, save_disparity_figure

    run, prep, metrics = outcome.run, outcome.prepared, outcome.metrics
    region, dmax = prep.region, prep.model.dmax
    maps = metrics.maps
    # A declared pass's MAPs, cycles and timeouts too (over its own columns), by its name (census-lr's
    # right_map, right_cycles, right_timeout).
    extra = {f"{name}_{field}": getattr(r, field) for name, r in run.passes.items()
             for field in ("map", "cycles", "timeout")}
    if maps is not None:  # a board asked for MAPs only sent no counts: no confidence, none made up
        extra.update(maps.arrays())
    if metrics.reference_maps is not None:
        extra["reference_confidence"] = metrics.reference_maps.confidence.astype(np.float32)
    if prep.gt is not None:
        extra["gt"] = prep.gt.astype(np.float32)
    out.write(
        "result.npz",
        lambda path: np.savez_compressed(
            path,
            map=run.map,
            # a board asked for MAPs only (--board-fields map) sent no counts or cycles
            **({} if run.counts is None else {"counts": run.counts}),
            **({} if run.cycles is None else {"cycles": run.cycles}),
            timeout=run.timeout,
            reference_map=prep.reference_map,
            **extra,
        ),
    )
    shown, title = run.map, f"Machine ({run.engine}, counter max {run.machine.counter_max})"
    if args.min_confidence is not None and maps is not None:
        # On the confidence as result.npz holds it (float32), so that a user's threshold there agrees.
        kept = maps.confidence.astype(np.float32) >= np.float32(args.min_confidence)
        shown = np.where(kept, run.map, np.int16(-1))
        title += f", confidence >= {args.min_confidence:g}"
        report["min_confidence"] = _kept_figures(shown, prep.gt, args.min_confidence)
    panels = [("Reference (float64)", prep.reference_map), (title, shown)]
    if prep.gt is not None:
        panels.append(("Ground truth", prep.gt))
        if metrics.sgbm_map is not None:  # computed once, for the report's bad-pixel rates
            panels.append(("OpenCV StereoSGBM", metrics.sgbm_map))
    cut_left = region.cut(left)
    out.write("disparity.png", lambda path: save_disparity_figure(path, cut_left, panels, dmax))
    if maps is not None:
        label = f"Machine confidence (mass within +-{args.confidence_t}, {args.confidence_window}x" \
                f"{args.confidence_window} pooled)"
        out.write("confidence.png", lambda path: save_confidence_figure(path, cut_left, maps, run.map, label))
    conf = report.get("confidence")
    if prep.gt is not None and isinstance(conf, dict) and "reference" in conf:  # figures of known pixels
        out.write("calibration.png", lambda path: save_calibration_figure(path, conf))
    if calib is not None:
        _write_cloud(out, args, report, region, shown, maps, calib)


def _kept_figures(shown: np.ndarray, gt: np.ndarray | None, threshold: float) -> dict[str, object]:
    """``--min-confidence``: the density kept (pixels with a disparity over all output pixels) and,
    with ground truth, bad-2 of the kept pixels."""
    from .confidence import BAD_THRESHOLD
    from .metrics import bad_rates

    kept = shown >= 0
    figures: dict[str, object] = {"threshold": threshold, "density": float(kept.mean()),
                                  "pixels": int(kept.sum())}
    if gt is not None:
        figures[f"bad{BAD_THRESHOLD}"] = bad_rates(shown, gt, BAD_THRESHOLD)["matched"]
    return figures


def _write_cloud(out: OutputDir, args: argparse.Namespace, report: dict[str, object], region: OutputRegion,
                 shown: np.ndarray, maps: object, calib: StereoCalibration) -> None:
    """depth.npy (metres, NaN: no match or blanked, inf: at infinity) and cloud.ply of ``shown``."""
    from .cloud import left_colours, point_cloud, write_ply

    depth = calib.depth(shown).astype(np.float32)
    colours = left_colours(args.left, args.crop)
    conf = None if maps is None else maps.confidence  # type: ignore[attr-defined]
    points = point_cloud(depth, calib, region, colours, conf)
    out.write("depth.npy", lambda path: np.save(path, depth))
    comments = (f"bayesmachine run: depth = fx * baseline / (d + doffs), calibration {calib.source}",)
    out.write("cloud.ply", lambda path: write_ply(path, points, comments))
    report["calibration"] = calib.to_dict()
    report["cloud_points"] = len(points)


def _sweep_pairs(
    args: argparse.Namespace, points: list[Point]
) -> tuple[list[PairSpec], str, dict[str, object] | None]:
    """The pairs of a sweep: ``--dataset``'s, or the one pair of LEFT RIGHT (or the bundled one),
    which is loaded and sized here first so that a bad input is one error line, as for ``run``."""
    if args.dataset is None:
        given = [f for f, v in (("--pairs", args.pairs), ("--kitti-gt", args.kitti_gt)) if v is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: options of --dataset (a sweep of one pair has no others)")
        left, right, gt, source = _load_inputs(args, with_gt=True)
        for point in points:  # each model on its own output region (OutputRegion.of_model)
            _check_fits(OutputRegion.of_model(left.shape, point.model), point.machine)
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
                         sgbm=not args.no_sgbm, resume=args.resume, workers=workers,
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

    line = (f"{p['engine']} model={p['model_name']} rng={p['rng']} counter_max={p['counter_max']}"
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


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the host subcommands to the ``bayesmachine`` parser."""
    p = subparsers.add_parser(
        "reference",
        help="exact float64 posterior and MAP of every pixel",
        description="Compute the exact (float64) disparity posterior of a rectified pair: "
        "posterior (H-4)x(W-4-Dmax)x(Dmax+2), last index = no match, and the MAP (int16, -1 = no match). "
        "The posterior is written band by band (memory holds one band); the command refuses up front "
        "when the disk cannot hold it.",
    )
    _add_input_options(p, optional=False)
    add_model_options(p, census=True)
    p.add_argument("-o", "--output", required=True, type=output_path, metavar="REF.npz",
                   help="output .npz file")
    p.add_argument("--quiet", action="store_true", help="no summary line")
    p.set_defaults(func=needs_host(_cmd_reference))

    p = subparsers.add_parser(
        "run",
        help="run the machine on a stereo pair and compare it with the reference",
        description="Run the stochastic machine on a rectified pair (default: the bundled Motorcycle pair "
        "with its ground truth); write OUT/report.json, OUT/result.npz, OUT/disparity.png and "
        "OUT/confidence.png (each pixel's confidence; with ground truth also OUT/calibration.png), "
        "OUT/depth.npy and OUT/cloud.ply with --calib, OUT/waves.vcd with --waves. The files of an earlier "
        "run into OUT (as "
        "OUT/.bayesmachine-manifest.json lists them) are removed first, nothing else there; report.json is "
        "written last, so its presence means the run is complete. A second run into the same OUT is refused "
        "while the first is writing.",
    )
    _add_input_options(p, optional=True)
    add_model_options(p, census=True, board_engine=True)
    _add_machine_options(p, sweep=False)
    p.set_defaults(func=needs_host(_cmd_run))

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
    _add_input_options(p, optional=True)
    add_model_options(p, census=True, sweep=True)
    _add_machine_options(p, sweep=True)
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use the bayesmachine command")
