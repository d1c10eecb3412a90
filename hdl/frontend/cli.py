"""``bayesmachine emit --top stereo``: the options and the summary of the ``StereoMachine`` top."""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING

from bayesmachine.cliargs import add_model_options, int_arg, model_params_from_args
from bayesmachine.params import MachineParams, stereo_lanes

from . import DEFAULT_FIFO_PIXELS, MAX_WIDTH

if TYPE_CHECKING:
    from .stereo import StereoMachine

__all__ = ["add_options", "build", "stereo_params", "summary"]


def add_options(p: argparse.ArgumentParser) -> None:
    """The ``--top stereo`` options: the model's parameters (shared with run/sweep), the image width,
    the FIFO."""
    add_model_options(p, dmax=False)
    g = p.add_argument_group("stereo top (--top stereo): pixels in, results out")
    g.add_argument("--width", type=int_arg, default=640,
                   help=f"image width in pixels, dmax + 5 .. {MAX_WIDTH} (default 640)")
    g.add_argument("--fifo-pixels", type=int_arg, default=DEFAULT_FIFO_PIXELS,
                   help=f"pixels' worth of load beats the FIFO holds (default {DEFAULT_FIFO_PIXELS})")


def stereo_params(args: argparse.Namespace, params: MachineParams) -> MachineParams:
    """The machine ``params`` with the front end's lanes (:func:`~bayesmachine.params.stereo_lanes`)
    unless ``--lanes`` was given."""
    return dataclasses.replace(params, lanes=stereo_lanes(params)) if args.lanes is None else params


def build(args: argparse.Namespace, params: MachineParams) -> StereoMachine:
    """The ``StereoMachine`` the options describe, around the machine ``params`` (whose lanes default
    to the front end's, :func:`stereo_params`)."""
    from .stereo import StereoMachine

    return StereoMachine(stereo_params(args, params), model_params_from_args(args), args.width,
                         fifo_pixels=args.fifo_pixels)


def summary(top: StereoMachine) -> str:
    """What the stereo top is and its ports, for ``emit``'s output."""
    from amaranth.hdl import Shape
    from amaranth.lib import wiring

    m, p = top.model, top.params
    lines = [
        f"stereo top: {top.width}-pixel lines, Dmax {m.dmax}, p0 {m.p0}, sigmas m/gh/gv "
        f"{m.sigma_m}/{m.sigma_gh}/{m.sigma_gv}, p_nm0 {m.p_nm0}, sigma_nm {m.sigma_nm}; "
        f"FIFO of {top.fifo_pixels} pixels ({top.fifo_pixels * p.beats_per_pixel} beats)",
        "ports (Verilog names; clk and rst as well):",
    ]
    for path, member, _ in top.signature.flatten(top):
        width = Shape.cast(member.shape).width
        lines.append(f"  {'in' if member.flow == wiring.In else 'out':3} {'__'.join(map(str, path)):15} "
                     f"{width:6} bits")
    return "\n".join(lines)
