"""``bayesmachine run``: the machine on a stereo pair beside the reference, with its report, results,
figures and (with a calibration) depth and point cloud; on the model, pysim, Verilator, the on-chip front
end (``--feed pixels``) or a board."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bayesmachine.cliargs import (
    BAUD_RANGE,
    DEFAULT_BAUD,
    MAX_SILENCE_S,
    add_model_options,
    argument_type,
    float_arg,
    input_path,
    int_arg,
    int_in_range,
    model_params_from_args,
    positive_float_at_most,
)
from bayesmachine.extras import needs_host
from bayesmachine.hdl.frontend import MAX_MACHINES
from bayesmachine.integrators import integrator_kind
from bayesmachine.models import BOARD_MODEL, DEFAULT_MODEL, ModelParams
from bayesmachine.outputs import OutputDir
from bayesmachine.params import DEFAULT_INTEGRATOR
from bayesmachine.region import OutputRegion
from bayesmachine.sim.engines import check_pixel_engine_options

from ..calib import (
    BUNDLED_CALIB,
    KITTI_CAMERAS,
    StereoCalibration,
    bundled_calibration_path,
    read_calibration,
)
from ..confidence import DEFAULT_T, DEFAULT_WINDOW, MAX_T, MAX_WINDOW, ConfidenceParams
from ..images import Crop
from ..run import ENGINES, FEEDS, RunOutcome, run_pair
from .options import (
    add_fill_option,
    add_gt_options,
    add_host_machine_options,
    add_input_options,
    add_output_options,
    check_fits,
    load_inputs,
    machine_params,
)

__all__ = ["register", "RUN_OUTPUTS"]

# Every file a run can write into OUT/, the report first (it is removed first and committed last: its
# presence means the rest is complete and from the same run).
RUN_OUTPUTS = ("report.json", "result.npz", "disparity.png", "confidence.png", "calibration.png", "depth.npy",
               "cloud.ply", "waves.vcd")


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``run`` to the ``bayesmachine`` parser."""
    p = subparsers.add_parser(
        "run",
        help="run the machine on a stereo pair and compare it with the reference",
        description="Run the machine (stochastic; --integrator log: the logarithmic one) on a rectified "
        "pair (default: the bundled Motorcycle pair "
        "with its ground truth); write OUT/report.json, OUT/result.npz, OUT/disparity.png and "
        "OUT/confidence.png (each pixel's confidence; with ground truth also OUT/calibration.png), "
        "OUT/depth.npy and OUT/cloud.ply with --calib, OUT/waves.vcd with --waves. The files of an earlier "
        "run into OUT (as "
        "OUT/.bayesmachine-manifest.json lists them) are removed first, nothing else there; report.json is "
        "written last, so its presence means the run is complete. A second run into the same OUT is refused "
        "while the first is writing.",
    )
    add_input_options(p, optional=True)
    add_model_options(p, census=True, default=f"{DEFAULT_MODEL}; {BOARD_MODEL} with --engine board, the "
                      "model of board build's default design")
    _add_run_options(p)
    p.set_defaults(func=needs_host(_cmd_run))


def _add_run_options(p: argparse.ArgumentParser) -> None:
    """The machine options and the engine's (the board's, the feed, the machines, the trace), the ground
    truth, the confidence and the outputs of a run."""
    g = add_host_machine_options(p)
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
                   "list of map, counts (the counters, or a log machine's weights), cycles (default all "
                   "three; the MAP and its flags always come). --board-fields map cuts the results' bytes "
                   "on the link; result.npz then has no counts or cycles and report.json's figures of them "
                   "are null")
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
        "StereoMachine with K machines; --feed words: K engines dealt the rows the same way; not "
        "census-sgm, whose paths continue from the row above: K > 1 with --model census-lr)",
    )
    g.add_argument(
        "--waves",
        metavar="FIRST:LAST",
        default=None,
        help="with --engine verilator: write OUT/waves.vcd while output pixels FIRST..LAST "
        "(row-major over the output region, from 0) are in the machine",
    )
    add_fill_option(g)
    add_gt_options(p)
    _add_confidence_options(p)
    add_output_options(p)


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
        "operator_samples_per_pixel": run.operator_samples_per_pixel,
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
    from ..metrics import json_safe

    path.write_text(json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n")


def _machine_label(r: dict[str, object]) -> list[str]:
    """What a summary line says of a report's machine: its integrator unless the default one, its kind's
    fields."""
    kind = integrator_kind(str(r.get("integrator", DEFAULT_INTEGRATOR)))
    return [*([f"integrator={kind.name}"] if kind.named else []), *kind.label_parts(r)]


def _summary(r: dict[str, object]) -> str:
    def f(key: str, fmt: str = ".4f") -> str:
        v = r.get(key)
        return "n/a" if v is None else format(v, fmt)

    line = (
        f"{r['engine']} model={r['model_name']} "
        + " ".join(_machine_label(r))
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
        from ..metrics import NO_KNOWN_GT

        line += f"\n  {NO_KNOWN_GT}"
    elif r.get("machine_bad2") is not None or r.get("ground_truth"):
        line += (
            f"\n  bad-2 (matched / no-match bad): "
            f"machine {f('machine_bad2')} / {f('machine_bad2_nomatch_bad')}, "
            f"reference {f('reference_bad2')} / {f('reference_bad2_nomatch_bad')}"
        )
        if "sgbm_bad2" in r:
            line += f", SGBM {f('sgbm_bad2')} / {f('sgbm_bad2_nomatch_bad')}"
        if "sgbm_tuned_bad2" in r:
            line += f", tuned SGBM {f('sgbm_tuned_bad2')} / {f('sgbm_tuned_bad2_nomatch_bad')}"
        if "bm_bad2" in r:
            line += f", StereoBM {f('bm_bad2')} / {f('bm_bad2_nomatch_bad')}"
        if r.get("machine_nomatch_occluded") is not None:
            line += f"\n  no-match calls on occluded pixels: machine {f('machine_nomatch_occluded', '.3f')}"
            if r.get("sgbm_nomatch_occluded") is not None:
                line += f", SGBM {f('sgbm_nomatch_occluded', '.3f')}"
    if r.get("fill") is not None:
        line += (f"\n  {r['fill']} fill of {r['fill_holes']} pixels ({r['filled_pixels']} filled)")
        if r.get("filled_bad2") is not None:
            line += f": bad-2 {f('filled_bad2')} / {f('filled_bad2_nomatch_bad')}"
        if r.get("filled_confidence_ece") is not None:
            line += (f", confidence ECE {f('filled_confidence_ece')}, AUC {f('filled_confidence_auc')} "
                     f"(random {f('filled_confidence_auc_random')})")
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
    machine = machine_params(args, model)
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
    left, right, gt, source = load_inputs(args, with_gt=True)
    region = OutputRegion.of_model(left.shape, model)
    _check_waves(waves, region.pixels)
    check_fits(region, machine)
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
            fill=args.fill,
        )
        report = _report(outcome, source, args.crop)
        report["feed"] = args.feed
        report["machines"] = machines
        if outcome.run.engine_figures is not None:
            report[args.engine] = outcome.run.engine_figures  # the board's link: wall time, bytes, attempts
        if report.get("ground_truth_pixels") == 0 and args.quiet:  # the summary says it otherwise
            from ..metrics import NO_KNOWN_GT

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
    from ..plots import save_calibration_figure, save_confidence_figure, save_disparity_figure

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
    fill = outcome.fill
    if fill is not None:  # the machine's own map and no-match flags stay beside the filled map
        extra.update(filled_map=fill.map, filled=fill.filled, nomatch=run.nomatch)
        if metrics.fill_maps is not None:
            extra["filled_confidence"] = metrics.fill_maps.confidence.astype(np.float32)
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
    panels: list[tuple] = [("Reference (float64)", prep.reference_map), (title, shown)]
    if fill is not None:
        panels.append((f"Machine, {fill.rule} fill (filled pixels veiled)", fill.map, fill.filled))
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
    from ..confidence import BAD_THRESHOLD
    from ..metrics import bad_rates

    kept = shown >= 0
    figures: dict[str, object] = {"threshold": threshold, "density": float(kept.mean()),
                                  "pixels": int(kept.sum())}
    if gt is not None:
        figures[f"bad{BAD_THRESHOLD}"] = bad_rates(shown, gt, BAD_THRESHOLD)["matched"]
    return figures


def _write_cloud(out: OutputDir, args: argparse.Namespace, report: dict[str, object], region: OutputRegion,
                 shown: np.ndarray, maps: object, calib: StereoCalibration) -> None:
    """depth.npy (metres, NaN: no match or blanked, inf: at infinity) and cloud.ply of ``shown``."""
    from ..cloud import left_colours, point_cloud, write_ply

    depth = calib.depth(shown).astype(np.float32)
    colours = left_colours(args.left, args.crop)
    conf = None if maps is None else maps.confidence  # type: ignore[attr-defined]
    points = point_cloud(depth, calib, region, colours, conf)
    out.write("depth.npy", lambda path: np.save(path, depth))
    comments = (f"bayesmachine run: depth = fx * baseline / (d + doffs), calibration {calib.source}",)
    out.write("cloud.ply", lambda path: write_ply(path, points, comments))
    report["calibration"] = calib.to_dict()
    report["cloud_points"] = len(points)

