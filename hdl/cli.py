"""``bayesmachine emit``: write the machine's RTL as Verilog (``.v``) or RTLIL (``.il``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from bayesmachine.params import DEFAULT_LANES, DEFAULT_MAX_CYCLES, DEFAULT_WORD_BITS, RNG_KINDS, MachineParams
from bayesmachine.sources import SOURCE_KINDS
from bayesmachine.sources.options import add_rng_options, rng_kwargs

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
    if not SOURCE_KINDS[params.rng].on_chip:
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
        f"random source: {params.rng} ({_source_summary(params)})",
        f"load: {params.lanes} words per beat, {params.beats_per_pixel} beats per pixel",
        "ports (Verilog names; clk and rst as well):",
    ]
    lines += [f"  {d:3} {name:15} {width:6} bits" for d, name, width in _ports(params)]
    return "\n".join(lines)


def _source_summary(params: MachineParams) -> str:
    if params.rng == "lfsr":
        return f"leap-forward LFSRs, L = {params.lfsr_bits}, seed {params.seed}"
    text = "W-bit numbers per operator on the 'entropy' port"
    if params.rng == "smtj":
        from bayesmachine.sources.smtj import smtj_device_count

        text += (f"; simulated by {smtj_device_count(params)} SMTJ devices, {params.word_bits} per "
                 f"{params.smtj_share}: dwell {params.smtj_dwell:g} cycles, spread {params.smtj_spread:g}, "
                 f"seed {params.seed}")
    return text


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
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _int(text: str) -> int:
    return int(text, 0)  # accepts 0x... for seeds


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``emit`` subcommand."""
    p = subparsers.add_parser(
        "emit",
        help="write the machine's RTL (Verilog or RTLIL)",
        description="Elaborate the Bayesian machine with the given parameters and write it as "
        "Verilog (.v) or RTLIL (.il), top module 'bayesmachine'.",
    )
    p.add_argument("--dmax", type=int, default=80, help="largest disparity: rows = dmax + 2 (default 80)")
    p.add_argument("--columns", type=int, default=3, help="data-term operator columns N (default 3)")
    p.add_argument("--word-bits", type=int, default=DEFAULT_WORD_BITS,
                   help=f"comparator resolution W; memory words are W+1 bits (default {DEFAULT_WORD_BITS})")
    p.add_argument("--counter-max", type=int, default=16,
                   help="n_max: a counter overflows on its (n_max+1)-th 1 (default 16)")
    add_rng_options(p, RNG_KINDS)
    p.add_argument("--seed", type=_int, default=1,
                   help="machine seed for LFSR polynomials and states, or the SMTJ devices (default 1)")
    p.add_argument("--lanes", type=int, default=None,
                   help=f"likelihood-memory words per load beat (default {DEFAULT_LANES}, or one "
                   "pixel's words if fewer)")
    p.add_argument("--max-cycles", type=_int, default=DEFAULT_MAX_CYCLES,
                   help=f"watchdog: cycles before a run stops with timeout (default {DEFAULT_MAX_CYCLES})")
    p.add_argument("--tie-break", choices=("nomatch-first", "lowest-index"), default="nomatch-first",
                   help="MAP encoder rule when several counters overflow in one cycle "
                   "(default nomatch-first)")
    p.add_argument("--prior", choices=("uniform", "loaded"), default="uniform",
                   help="uniform prior (always-on 1s) or a loaded prior operator column (default uniform)")
    p.add_argument("-o", "--output", default="build/bayesmachine.v",
                   help="output file; .v for Verilog, .il for RTLIL (default build/bayesmachine.v)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    lanes = {} if args.lanes is None else {"lanes": args.lanes}
    params = MachineParams.for_disparity(
        args.dmax,
        **lanes,
        columns=args.columns,
        word_bits=args.word_bits,
        counter_max=args.counter_max,
        **rng_kwargs(args),
        seed=args.seed,
        max_cycles=args.max_cycles,
        tie_break=args.tie_break,
        prior=args.prior,
    )
    path = emit(params, args.output)
    print(summary(params))
    print(f"wrote {path}")
    return 0
