"""``bayesmachine emit --top stereo``: the options and the summary of the ``StereoMachine`` top."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from bayesmachine.host.likelihoods import ModelParams

from . import DEFAULT_FIFO_PIXELS, MAX_WIDTH

if TYPE_CHECKING:
    from .stereo import StereoMachine

__all__ = ["add_options", "build", "summary"]

_DEFAULT = ModelParams()


def add_options(p: argparse.ArgumentParser) -> None:
    """The ``--top stereo`` options (the model's parameters, the image width, the FIFO)."""
    g = p.add_argument_group("stereo top (--top stereo): pixels in, results out")
    g.add_argument("--width", type=int, default=640,
                   help=f"image width in pixels, dmax + 5 .. {MAX_WIDTH} (default 640)")
    g.add_argument("--p0", type=float, default=_DEFAULT.p0,
                   help=f"base match likelihood (default {_DEFAULT.p0})")
    g.add_argument("--sigma", type=float, default=None, help="sigma of all three features (default 10)")
    for f in ("m", "gh", "gv"):
        g.add_argument(f"--sigma-{f}", type=float, default=None, help=f"sigma of the {f} feature")
    g.add_argument("--p-nm0", type=float, default=_DEFAULT.p_nm0,
                   help=f"base no-match probability (default {_DEFAULT.p_nm0})")
    g.add_argument("--sigma-nm", type=float, default=_DEFAULT.sigma_nm,
                   help=f"no-match sigma (default {_DEFAULT.sigma_nm})")
    g.add_argument("--fifo-pixels", type=int, default=DEFAULT_FIFO_PIXELS,
                   help=f"pixels' worth of load beats the FIFO holds (default {DEFAULT_FIFO_PIXELS})")


def _model(args: argparse.Namespace) -> ModelParams:
    def sigma(f: str) -> float:
        v = getattr(args, f"sigma_{f}")
        if v is not None:
            return v
        return args.sigma if args.sigma is not None else getattr(_DEFAULT, f"sigma_{f}")

    return ModelParams(dmax=args.dmax, p0=args.p0, sigma_m=sigma("m"), sigma_gh=sigma("gh"),
                       sigma_gv=sigma("gv"), p_nm0=args.p_nm0, sigma_nm=args.sigma_nm)


def build(args: argparse.Namespace, machine_options: dict[str, object]) -> StereoMachine:
    """The ``StereoMachine`` the options describe (lanes default to the front end's: 6 rows per beat)."""
    from .stereo import StereoMachine, stereo_machine_params

    params = stereo_machine_params(args.dmax, **machine_options)
    return StereoMachine(params, _model(args), args.width, fifo_pixels=args.fifo_pixels)


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
