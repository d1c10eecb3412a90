"""The host commands' shared option plumbing: the input pair, the machine options (the random
sources the host can drive), the ground truth and the outputs, and the machine a model needs."""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from bayesmachine.cliargs import (
    add_machine_options,
    argument_type,
    input_path,
    machine_params_from_args,
    output_path,
    positive_float_at_most,
    runnable_sources,
)
from bayesmachine.models import ModelParams
from bayesmachine.outputs import require_memory
from bayesmachine.params import DEFAULT_RNG, MachineParams
from bayesmachine.region import OutputRegion

from ..fill import DEFAULT_FILL, FILLS
from ..images import Crop, bundled_pair, crop_image, load_gt, load_image, parse_crop
from ..run import result_bytes

MAX_GT_SCALE = 65536.0  # --gt-scale: past it every 16-bit stored disparity is below one pixel


def add_input_options(p: argparse.ArgumentParser, optional: bool) -> None:
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


def load_inputs(
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


def host_rng_help() -> str:
    return f"random source; the host runs the kinds it can drive: {', '.join(runnable_sources())}"


def _check_host_rng(machine: MachineParams) -> None:
    """The host drives on-chip sources and off-chip ones with a device model; not bare ``external``."""
    if machine.source is not None and machine.rng not in runnable_sources():
        raise ValueError(
            f"--rng {machine.rng}: the machine takes its random numbers on the entropy port and "
            f"this source has no model the host can run; use it with 'bayesmachine emit'"
        )


def add_host_machine_options(p: argparse.ArgumentParser, help: dict[str, str] | None = None,
                              **changes: dict[str, object]) -> argparse._ArgumentGroup:
    """The machine options of a host command (``cliargs.add_machine_options``; ``--rng`` names the
    sources the host can drive), their group returned for the command's engine options."""
    helps = {
        "rng": host_rng_help() + f" (default {DEFAULT_RNG})",
        **(help or {}),
    }
    return add_machine_options(p, skip=("columns",), help=helps, **changes)


def add_gt_options(p: argparse.ArgumentParser, scale_note: str = "") -> None:
    """``--gt`` and ``--gt-scale`` (``scale_note`` ends the latter's help)."""
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
        + scale_note,
    )


RUN_FILL_OUTPUTS = "result.npz keeps the machine's own map beside filled_map; report.json gives both maps' " \
    "figures (filled_*)"


def add_fill_option(g: argparse._ActionsContainer, what: str = RUN_FILL_OUTPUTS) -> None:
    """``--fill``: :mod:`..fill`'s rule for the pixels without a disparity (``what``: its figures' place)."""
    g.add_argument("--fill", choices=FILLS, default=DEFAULT_FILL,
                   help="give the pixels the machine calls no match, or whose MAP the left-right test "
                   "rejects, a disparity from their row: background, the lower of the nearest matched ones "
                   "left and right; left, the nearest matched one to the left; none (default "
                   f"{DEFAULT_FILL}). {what}")


def add_output_options(p: argparse.ArgumentParser) -> None:
    """``--no-sgbm``, ``--quiet`` and ``-o OUT/``: the options a run and a sweep end with."""
    p.add_argument("--no-sgbm", action="store_true", help="skip the OpenCV StereoSGBM comparison")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("-o", "--output", required=True, type=output_path, metavar="OUT/",
                   help="output directory; only files bayesmachine wrote there are ever replaced or removed, "
                   "and one run at a time may write into it")


def machine_params(
    args: argparse.Namespace, model: ModelParams, counter_max: int | None = None, rng: str | None = None
) -> MachineParams:
    """The machine ``model`` needs (``disparity_machine``: the census model's neighbour prior) from the
    machine options."""
    overrides: dict[str, object] = {} if counter_max is None else {"counter_max": counter_max}
    if rng is not None:
        overrides["rng"] = rng
    machine = machine_params_from_args(args, model.dmax, model=model, **overrides)
    if getattr(args, "feed", "words") == "pixels" and args.words_per_beat is None:
        # The front end writes one feature per lane: lanes a multiple of the loaded columns.
        from bayesmachine.params import stereo_words_per_beat

        machine = dataclasses.replace(machine, words_per_beat=stereo_words_per_beat(machine))
    _check_host_rng(machine)
    return machine


def check_fits(region: OutputRegion, machine: MachineParams) -> None:
    """Refuse up front when the per-pixel results cannot be held (they are what result.npz holds)."""
    require_memory(
        result_bytes(region, machine),
        f"the results of {region.shape[0]}x{region.shape[1]} output pixels x {machine.rows} counters",
        "use --crop or a smaller --dmax",
    )

