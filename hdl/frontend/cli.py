"""``bayesmachine emit --top stereo``: the options and the summary of the ``StereoMachine`` top."""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING

from bayesmachine.cliargs import (
    add_model_options,
    int_arg,
    machine_parameters,
    model_names_from_args,
    model_params_from_args,
    options_without_effect,
)
from bayesmachine.params import MachineParams, stereo_words_per_beat

from . import DEFAULT_FIFO_PIXELS, DEFAULT_WIDTH, MAX_WIDTH

if TYPE_CHECKING:
    from .stereo import StereoMachine

__all__ = ["DEFAULT_WIDTH", "add_options", "build", "check_top", "fifo_pixels", "machines", "stereo_params",
           "summary", "width"]

# The stereo top's own options (dest, flag): left at None unless given, so that one given with
# --top machine, where it would do nothing, is refused (check_top), as are the model's options that
# change only the words the front end computes.
_STEREO_OPTIONS = (("width", "--width"), ("fifo_pixels", "--fifo-pixels"))


def add_options(p: argparse.ArgumentParser) -> None:
    """The ``--top stereo`` options: the model's parameters (shared with run/sweep), the image width,
    the FIFO."""
    add_model_options(p, dmax=False, title="model (--top stereo; paper table 1 defaults)")
    g = p.add_argument_group("stereo top (--top stereo): pixels in, results out")
    g.add_argument("--width", type=int_arg, default=None,
                   help=f"image width in pixels: dmax + 5 .. {MAX_WIDTH}, or dmax + 7 .. {MAX_WIDTH} with a "
                   f"7x7 census (default {DEFAULT_WIDTH})")
    g.add_argument("--fifo-pixels", type=int_arg, default=None,
                   help=f"pixels' worth of load beats the FIFO holds (default {DEFAULT_FIFO_PIXELS})")


def check_top(args: argparse.Namespace) -> None:
    """Refuse (ValueError) options of the stereo top given with ``--top machine``: they would be ignored
    (the top's own, and the model's that do not change the machine alone:
    :func:`~bayesmachine.cliargs.machine_parameters`)."""
    if args.top == "stereo":
        return
    given = [flag for dest, flag in _STEREO_OPTIONS if getattr(args, dest, None) is not None]
    model_params_from_args(args)  # an option of another model is refused as that first
    given += options_without_effect(args, machine_parameters(model_names_from_args(args)[0]))
    if given:
        what = (", the machine alone, which takes likelihood words, not pixels" if args.top == "machine"
                else ", which takes observed bins, not pixels")
        raise ValueError(f"{', '.join(given)}: only with --top stereo (got --top {args.top}{what})")


def width(args: argparse.Namespace) -> int:
    """``--width``, or its default."""
    return DEFAULT_WIDTH if args.width is None else int(args.width)


def fifo_pixels(args: argparse.Namespace) -> int:
    """``--fifo-pixels``, or its default."""
    return DEFAULT_FIFO_PIXELS if args.fifo_pixels is None else int(args.fifo_pixels)


def stereo_params(args: argparse.Namespace, params: MachineParams) -> MachineParams:
    """The machine ``params`` with the front end's words per beat
    (:func:`~bayesmachine.params.stereo_words_per_beat`) unless ``--words-per-beat`` was given."""
    if args.words_per_beat is not None:
        return params
    return dataclasses.replace(params, words_per_beat=stereo_words_per_beat(params))


def build(args: argparse.Namespace, params: MachineParams) -> StereoMachine:
    """The ``StereoMachine`` the options describe, around the machine ``params`` (whose words per beat default
    to the front end's, :func:`stereo_params`)."""
    from .stereo import StereoMachine, check_stereo_machine

    top_params, model = stereo_params(args, params), model_params_from_args(args)
    k = machines(args)
    # Checked first: a component whose constructor raises would be reported as never elaborated.
    check_stereo_machine(top_params, model, width(args), fifo_pixels(args), k)
    return StereoMachine(params=top_params, model=model, width=width(args), fifo_pixels=fifo_pixels(args),
                         machines=k)


def machines(args: argparse.Namespace) -> int:
    """``--machines`` (the stereo top's machines behind its feature pipeline), or 1."""
    k = getattr(args, "machines", None)
    return 1 if k is None else int(k)


def summary(top: StereoMachine) -> str:
    """What the stereo top is and its ports, for ``emit``'s output."""
    from ..emit import signature_ports
    from .layouts import declared_passes
    from .words import pass_params

    m, p = top.model, top.params
    lines = [
        f"stereo top: {top.width}-pixel lines, Dmax {m.dmax}, line buffer of {2 * m.margin} lines, output "
        f"region margin {m.margin}; FIFO of {top.fifo_pixels} pixels ({top.fifo_pixels * p.beats_per_pixel} "
        "beats)"
        + (f" per machine; {top.machines} machines (map row r on machine r mod {top.machines}, each with "
           "its own word generator)" if top.machines > 1 else ""),
    ]
    lines.append(f"the {m.name} model's columns in operator order, then its no-match rule:")
    for term in (*m.columns, m.nomatch):
        values = ", ".join(f"{k} {v}" for k, v in term.values.items())
        lines.append(f"  {term.name}" + (f": {values}" if values else ""))
    for declared in declared_passes(m):
        dp = pass_params(m, p, declared.name)
        # A machine's own random source and watchdog (the log machine has neither).
        own = "" if dp.seed is None else f", seed {dp.seed:#x}, watchdog {dp.max_cycles}"
        lines.append(
            f"{declared.name} pass: the {declared.model.name} model with the {declared.reference} image as "
            f"reference on a machine beside the own one ({dp.columns} data columns, {dp.words_per_beat} "
            f"words per beat{own}); its results on {declared.name}_result")
    lines += [
        "ports (Verilog names; clk and rst as well):",
    ]
    lines += [f"  {d:3} {name:15} {bits:6} bits" for d, name, bits in signature_ports(top.signature)]
    return "\n".join(lines)
