"""``bayesmachine emit``: write the machine's RTL as Verilog (``.v``) or RTLIL (``.il``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from bayesmachine.cliargs import add_dmax_option, add_machine_options, machine_params_from_args
from bayesmachine.outputs import atomic_write_text
from bayesmachine.params import MachineParams

__all__ = ["TOP_NAME", "emit", "register", "summary", "verilog_text"]

TOP_NAME = "bayesmachine"


def _ports(params: MachineParams) -> list[tuple[str, str, int]]:
    from amaranth.hdl import Shape

    from .machine import load_layout, result_layout

    ports = [
        ("in", "load__payload", Shape.cast(load_layout(params)).width),
        ("in", "load__valid", 1),
        ("out", "load__ready", 1),
        ("out", "result__payload", Shape.cast(result_layout(params)).width),
        ("out", "result__valid", 1),
        ("in", "result__ready", 1),
    ]
    if params.rng == "external":
        ports += [("in", "entropy", params.word_bits * params.operators), ("out", "entropy_ready", 1)]
    return ports


def summary(params: MachineParams) -> str:
    """A human-readable summary of the machine and its ports."""
    lines = [
        f"machine: {params.rows} rows x {params.operator_columns} operator columns = "
        f"{params.operators} operators ({'loaded' if params.prior == 'loaded' else 'uniform'} prior"
        f"{', last row no-match' if params.nomatch_row else ''}, tie rule {params.tie_break})",
        f"words: {params.word_bits}-bit comparators, {params.memory_word_width}-bit likelihood-memory words; "
        f"counter max {params.counter_max} ({params.counter_width}-bit overflow counters); "
        f"watchdog {params.max_cycles} cycles",
        f"random source: {params.rng}"
        + (f" (leap-forward LFSRs, L = {params.lfsr_bits}, seed {params.seed})"
           if params.rng == "lfsr" else " (W-bit numbers per operator on the 'entropy' port)"),
        f"load: {params.lanes} words per beat, {params.beats_per_pixel} beats per pixel",
        "ports (Verilog names; clk and rst as well):",
    ]
    lines += [f"  {d:3} {name:15} {width:6} bits" for d, name, width in _ports(params)]
    return "\n".join(lines)


def verilog_text(top: object) -> str:
    """Verilog of a component as the project emits it: top module ``bayesmachine``, no src attributes."""
    from amaranth.back import verilog

    return verilog.convert(top, name=TOP_NAME, emit_src=False)


def emit(params: MachineParams, path: str | Path) -> Path:
    """Write the machine as Verilog (``.v``/``.sv``) or RTLIL (``.il``), top module ``bayesmachine``."""
    from amaranth.back import rtlil

    from .machine import BayesianMachine

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".v", ".sv", ".il"):
        raise ValueError(
            f"cannot tell the output format from {path.name!r}: use a .v (Verilog) or .il (RTLIL) name"
        )
    top = BayesianMachine(params)
    if suffix == ".il":
        text = rtlil.convert(top, name=TOP_NAME)
    else:
        text = verilog_text(top)
    if not path.parent.exists():
        path.parent.mkdir(parents=True)
    return atomic_write_text(path, text)  # complete or absent, never a truncated file


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``emit`` subcommand."""
    p = subparsers.add_parser(
        "emit",
        help="write the machine's RTL (Verilog or RTLIL)",
        description="Elaborate the Bayesian machine with the given parameters and write it as "
        "Verilog (.v) or RTLIL (.il), top module 'bayesmachine'.",
    )
    g = p.add_argument_group("machine")
    add_dmax_option(g)
    add_machine_options(g, title=None)
    p.add_argument("-o", "--output", default="build/bayesmachine.v",
                   help="output file; .v for Verilog, .il for RTLIL (default build/bayesmachine.v)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    params = machine_params_from_args(args, args.dmax)
    path = emit(params, args.output)
    print(summary(params))
    print(f"wrote {path}")
    return 0
