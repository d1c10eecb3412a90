"""``bayesmachine reference``: the exact float64 posterior and MAP of a pair, written band by band."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bayesmachine.cliargs import (
    add_model_options,
    model_params_from_args,
    options_without_effect,
    output_path,
    pass_watchdogs,
)
from bayesmachine.extras import needs_host
from bayesmachine.models import all_options
from bayesmachine.outputs import NpzWriter, atomic_file, format_bytes, require_disk
from bayesmachine.region import OutputRegion

from ..features import model_planes
from ..images import validate_pair
from ..reference import reference_bands, warm_up
from .options import add_input_options, load_inputs


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``reference`` to the ``bayesmachine`` parser."""
    p = subparsers.add_parser(
        "reference",
        help="exact float64 posterior and MAP of every pixel",
        description="Compute the exact (float64) disparity posterior of a rectified pair: "
        "posterior (H-4)x(W-4-Dmax)x(Dmax+2), last index = no match, and the MAP (int16, -1 = no match). "
        "The posterior is written band by band (memory holds one band); the command refuses up front "
        "when the disk cannot hold it.",
    )
    add_input_options(p, optional=False)
    add_model_options(p, census=True)
    p.add_argument("-o", "--output", required=True, type=output_path, metavar="REF.npz",
                   help="output .npz file")
    p.add_argument("--quiet", action="store_true", help="no summary line")
    p.set_defaults(func=needs_host(_cmd_reference))


def _cmd_reference(args: argparse.Namespace) -> int:
    model = model_params_from_args(args)
    ignored = options_without_effect(args, set(all_options()) - pass_watchdogs())
    if ignored:  # as run refuses board options without --engine board
        raise ValueError(f"{', '.join(ignored)}: the watchdog of a machine's pass; reference computes the "
                         "exact float64 posterior and runs no machine")
    left, right, _, _ = load_inputs(args, with_gt=False)
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
