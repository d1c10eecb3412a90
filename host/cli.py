"""Host subcommands of ``bayesmachine``: reference, run, sweep.

``bayesmachine/cli.py`` calls :func:`register`; every ValueError raised here (bad input,
impossible parameters) ends as one error line there.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bayesmachine.params import MachineParams

from .images import Crop, bundled_pair, crop_image, load_gt, load_image, parse_crop
from .likelihoods import ModelParams
from .run import ENGINES, FEEDS, RunOutcome, prepare, run_pair

__all__ = ["register"]

DEFAULTS = ModelParams()


def _add_model_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("model (paper table 1 defaults)")
    g.add_argument(
        "--dmax", type=int, default=DEFAULTS.dmax, help="largest disparity Dmax (default %(default)s)"
    )
    g.add_argument(
        "--p0", type=float, default=DEFAULTS.p0, help="base match likelihood p0 (default %(default)s)"
    )
    g.add_argument("--sigma", type=float, default=None, help="sigma of all three features (default 10)")
    for f, name in (("m", "mean"), ("gh", "horizontal gradient"), ("gv", "vertical gradient")):
        g.add_argument(f"--sigma-{f}", type=float, default=None, help=f"sigma of the {name} feature")
    g.add_argument(
        "--p-nm0", type=float, default=DEFAULTS.p_nm0, help="base no-match probability (%(default)s)"
    )
    g.add_argument("--sigma-nm", type=float, default=DEFAULTS.sigma_nm, help="no-match sigma (%(default)s)")


def _model_params(args: argparse.Namespace) -> ModelParams:
    def sigma(f: str) -> float:
        v = getattr(args, f"sigma_{f}")
        if v is not None:
            return v
        return args.sigma if args.sigma is not None else getattr(DEFAULTS, f"sigma_{f}")

    return ModelParams(
        dmax=args.dmax,
        p0=args.p0,
        sigma_m=sigma("m"),
        sigma_gh=sigma("gh"),
        sigma_gv=sigma("gv"),
        p_nm0=args.p_nm0,
        sigma_nm=args.sigma_nm,
    )


def _add_input_options(p: argparse.ArgumentParser, optional: bool) -> None:
    nargs = "?" if optional else None
    extra = " (omit both for the bundled Middlebury Motorcycle pair)" if optional else ""
    p.add_argument("left", nargs=nargs, help=f"rectified left image{extra}")
    p.add_argument("right", nargs=nargs, help="rectified right image")
    p.add_argument(
        "--crop",
        type=parse_crop,
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
    if with_gt and getattr(args, "gt", None):
        gt = load_gt(args.gt)
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in shape: {left.shape} vs {right.shape}")
    if gt is not None and gt.shape != left.shape:
        raise ValueError(f"ground truth shape {gt.shape} differs from the images' {left.shape}")
    crop: Crop | None = args.crop
    left, right = crop_image(left, crop), crop_image(right, crop)
    if gt is not None:
        gt = crop_image(gt, crop)
    return np.ascontiguousarray(left), np.ascontiguousarray(right), gt, source


def _add_machine_options(p: argparse.ArgumentParser, sweep: bool) -> None:
    g = p.add_argument_group("machine")
    g.add_argument(
        "--engine", choices=ENGINES, default="model", help="how to run the machine (default model)"
    )
    if sweep:
        g.add_argument(
            "--counter-max",
            default="1,2,4,8,16,32",
            metavar="N,N,...",
            help="comma-separated counter max values (default %(default)s)",
        )
    else:
        g.add_argument(
            "--counter-max",
            type=int,
            default=16,
            metavar="N",
            help="counter max n_max: a counter overflows on its (n_max+1)-th 1 (default 16)",
        )
    g.add_argument(
        "--word-bits", type=int, default=10, metavar="W", help="comparator resolution (default 10)"
    )
    g.add_argument(
        "--seed", type=int, default=1, help="machine seed: LFSR polynomials and states (default 1)"
    )
    g.add_argument(
        "--max-cycles",
        type=int,
        default=(1 << 20) - 1,
        help="watchdog: a pixel stops as a timeout after this many cycles (default 2^20-1)",
    )
    g.add_argument(
        "--tie-break",
        choices=("nomatch-first", "lowest-index"),
        default="nomatch-first",
        help="MAP encoder rule when rows overflow together (default nomatch-first)",
    )
    if not sweep:
        g.add_argument(
            "--feed",
            choices=FEEDS,
            default="words",
            help="words: the host computes each pixel's likelihood words (default); pixels: the pair "
            "goes into the on-chip front end + machine (StereoMachine RTL, --engine verilator)",
        )
        g.add_argument(
            "--waves",
            metavar="FIRST:LAST",
            default=None,
            help="with --engine verilator: write OUT/waves.vcd while output pixels FIRST..LAST "
            "(row-major over the output region, from 0) are in the machine",
        )
    p.add_argument(
        "--gt", default=None, help="ground-truth disparity (.pfm, .npy, or an image with 0 = unknown)"
    )
    p.add_argument("--no-sgbm", action="store_true", help="skip the OpenCV StereoSGBM comparison")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="OUT/", help="output directory")


def _machine_params(args: argparse.Namespace, model: ModelParams, counter_max: int) -> MachineParams:
    if getattr(args, "feed", "words") == "pixels":
        # The front end needs lanes that are a multiple of the operator columns (one feature per lane).
        from bayesmachine.hdl.frontend.stereo import stereo_machine_params

        return stereo_machine_params(
            model.dmax,
            counter_max=counter_max,
            word_bits=args.word_bits,
            seed=args.seed,
            max_cycles=args.max_cycles,
            tie_break=args.tie_break,
        )
    return MachineParams.for_disparity(
        model.dmax,
        counter_max=counter_max,
        word_bits=args.word_bits,
        seed=args.seed,
        max_cycles=args.max_cycles,
        tie_break=args.tie_break,
    )


def _report(outcome: RunOutcome, source: str, crop: Crop | None) -> dict[str, object]:
    prep, run = outcome.prepared, outcome.run
    report: dict[str, object] = {
        "engine": run.engine,
        "counter_max": run.machine.counter_max,
        **outcome.metrics.to_report(),
        "frame_cycles": int(run.cycles.sum()),
        # Compute cycles count the machine's runs only; wall cycles (RTL engines) add loading.
        "wall_cycles": run.wall_cycles,
        "wall_cycles_per_pixel": None if run.wall_cycles is None else run.wall_cycles / run.cycles.size,
        "seconds": run.seconds,
        "words_seconds": run.words_seconds,
        "reference_seconds": prep.reference_seconds,
        "input": source,
        "crop": str(crop) if crop is not None else None,
        "image_shape": list(prep.left.shape),
        "output_shape": list(prep.shape),
        "ground_truth": prep.gt is not None,
        "model": prep.model.to_dict(),
        "machine": run.machine.to_dict(),
    }
    return report


def _write_json(path: Path, obj: object) -> None:
    path.write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n")


def _summary(r: dict[str, object]) -> str:
    def f(key: str, fmt: str = ".4f") -> str:
        v = r.get(key)
        return "n/a" if v is None else format(v, fmt)

    line = (
        f"{r['engine']} counter_max={r['counter_max']}: {r['pixels']} px, "
        f"{f('cycles_per_pixel_mean', '.2f')} +- {f('cycles_per_pixel_std', '.2f')} cycles/px, "
        f"RMS {f('rms_error')}, no-match F1 {f('nomatch_f1')}, MAP agreement {f('map_agreement')}, "
        f"timeouts {r['timeouts']}, engine {f('seconds', '.2f')} s"
    )
    if r.get("wall_cycles_per_pixel") is not None:
        line += f"\n  wall cycles per pixel, loading included: {f('wall_cycles_per_pixel', '.2f')}"

    if r.get("machine_bad2") is not None or r.get("ground_truth"):
        line += (
            f"\n  bad-2 (matched / no-match bad): "
            f"machine {f('machine_bad2')} / {f('machine_bad2_nomatch_bad')}, "
            f"reference {f('reference_bad2')} / {f('reference_bad2_nomatch_bad')}"
        )
        if "sgbm_bad2" in r:
            line += f", SGBM {f('sgbm_bad2')} / {f('sgbm_bad2_nomatch_bad')}"
    return line


def _cmd_reference(args: argparse.Namespace) -> int:
    model = _model_params(args)
    left, right, _, _ = _load_inputs(args, with_gt=False)
    prep = prepare(left, right, model)
    out = Path(args.output)
    if out.suffix != ".npz":
        out = out.with_name(out.name + ".npz")  # what np.savez would write: say the real name
    if out.parent and not out.parent.exists():
        raise ValueError(f"output directory {out.parent} does not exist")
    np.savez(out, posterior=prep.reference.posterior, map=prep.reference.map)
    if not args.quiet:
        ref = prep.reference
        print(
            f"reference: {ref.map.shape[0]}x{ref.map.shape[1]} px x {model.hypotheses} hypotheses in "
            f"{prep.reference_seconds:.3f} s, {int(ref.nomatch.sum())} no match -> {out}"
        )
    return 0


def _waves_option(text: str | None, engine: str, out: Path) -> dict[str, object]:
    """``--waves FIRST:LAST`` as the Verilator engine's ``trace`` option."""
    if text is None:
        return {}
    if engine != "verilator":
        raise ValueError(f"--waves needs --engine verilator (got --engine {engine})")
    try:
        first, last = (int(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"--waves takes FIRST:LAST pixel indices, e.g. 0:9; got {text!r}") from None
    if not 0 <= first <= last:
        raise ValueError(f"--waves: need 0 <= FIRST <= LAST, got {first}:{last}")
    return {"trace": (first, last, str(out / "waves.vcd"))}


def _make_output_dir(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise ValueError(f"output {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)


def _cmd_run(args: argparse.Namespace) -> int:
    model = _model_params(args)
    machine = _machine_params(args, model, args.counter_max)
    left, right, gt, source = _load_inputs(args, with_gt=True)
    out: Path = args.output
    engine_options = _waves_option(args.waves, args.engine, out)
    if args.feed == "pixels" and engine_options:
        raise ValueError("--waves is not available with --feed pixels")
    _make_output_dir(out)
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
    )
    report = _report(outcome, source, args.crop)
    report["feed"] = args.feed
    _write_json(out / "report.json", report)
    run, ref = outcome.run, outcome.prepared.reference
    np.savez_compressed(
        out / "result.npz",
        map=run.map,
        counts=run.counts,
        cycles=run.cycles,
        timeout=run.timeout,
        reference_map=ref.map,
    )
    from .metrics import image_region
    from .plots import save_disparity_figure

    panels = [
        ("Reference (float64)", ref.map),
        (f"Machine ({run.engine}, counter max {machine.counter_max})", run.map),
    ]
    if gt is not None:
        panels.append(("Ground truth", image_region(gt, model.dmax)))
        if outcome.metrics.sgbm_map is not None:  # computed once, for the report's bad-pixel rates
            panels.append(("OpenCV StereoSGBM", outcome.metrics.sgbm_map))
    save_disparity_figure(out / "disparity.png", image_region(left, model.dmax), panels, model.dmax)
    if not args.quiet:
        print(_summary(report))
        print(f"wrote {out / 'report.json'}, {out / 'result.npz'}, {out / 'disparity.png'}")
    return 0


def _parse_counter_list(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--counter-max must be comma-separated integers, got {text!r}") from None
    if not values:
        raise ValueError("--counter-max needs at least one value")
    return values


def _cmd_sweep(args: argparse.Namespace) -> int:
    model = _model_params(args)
    counters = _parse_counter_list(args.counter_max)
    machines = [_machine_params(args, model, n) for n in counters]  # validate all before running
    left, right, gt, source = _load_inputs(args, with_gt=True)
    out: Path = args.output
    _make_output_dir(out)
    prep = prepare(left, right, model, gt)
    points = []
    t0 = time.perf_counter()
    for i, machine in enumerate(machines):
        outcome = run_pair(
            left,
            right,
            model,
            machine,
            engine=args.engine,
            prepared=prep,
            progress=False if args.quiet else None,
            sgbm=(not args.no_sgbm) and i == 0,
        )
        report = _report(outcome, source, args.crop)
        for key in ("input", "crop", "image_shape", "output_shape", "ground_truth", "model", "machine"):
            report.pop(key)
        points.append(report)
        if not args.quiet:
            print(_summary(report), flush=True)
    sweep = {
        "engine": args.engine,
        "input": source,
        "crop": str(args.crop) if args.crop is not None else None,
        "output_shape": list(prep.shape),
        "ground_truth": gt is not None,
        "reference_seconds": prep.reference_seconds,
        "total_seconds": time.perf_counter() - t0,
        "model": model.to_dict(),
        "machine": {k: v for k, v in machines[0].to_dict().items() if k != "counter_max"},
        "points": points,
    }
    _write_json(out / "sweep.json", sweep)
    from .plots import save_sweep_figure

    save_sweep_figure(out / "sweep.png", points)
    if not args.quiet:
        print(f"wrote {out / 'sweep.json'}, {out / 'sweep.png'}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the host subcommands to the ``bayesmachine`` parser."""
    p = subparsers.add_parser(
        "reference",
        help="exact float64 posterior and MAP of every pixel",
        description="Compute the exact (float64) disparity posterior of a rectified pair: "
        "posterior (H-4)x(W-4-Dmax)x(Dmax+2), last index = no match, and the MAP (int16, -1 = no match).",
    )
    _add_input_options(p, optional=False)
    _add_model_options(p)
    p.add_argument("-o", "--output", required=True, type=Path, metavar="REF.npz", help="output .npz file")
    p.add_argument("--quiet", action="store_true", help="no summary line")
    p.set_defaults(func=_cmd_reference)

    p = subparsers.add_parser(
        "run",
        help="run the machine on a stereo pair and compare it with the reference",
        description="Run the stochastic machine on a rectified pair (default: the bundled Motorcycle pair "
        "with its ground truth); write OUT/report.json, OUT/result.npz and OUT/disparity.png.",
    )
    _add_input_options(p, optional=True)
    _add_model_options(p)
    _add_machine_options(p, sweep=False)
    p.set_defaults(func=_cmd_run)

    p = subparsers.add_parser(
        "sweep",
        help="paper Fig 6: accuracy and cycles per pixel against counter max",
        description="Run the machine for several counter max values on one pair; write OUT/sweep.json "
        "and OUT/sweep.png (RMS error and no-match F1 vs counter max; cycles per pixel: mean, median, "
        "10-90 % band).",
    )
    _add_input_options(p, optional=True)
    _add_model_options(p)
    _add_machine_options(p, sweep=True)
    p.set_defaults(func=_cmd_sweep)


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use the bayesmachine command")
