"""``bayesmachine emit``: write the machine's RTL as Verilog (``.v``) or RTLIL (``.il``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from bayesmachine.params import DEFAULT_LANES, DEFAULT_MAX_CYCLES, DEFAULT_WORD_BITS, MachineParams

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


def emit(params: MachineParams, path: str | Path, top: object | None = None) -> Path:
    """Write the machine (or ``top``, e.g. a ``StereoMachine``) as Verilog (``.v``/``.sv``) or RTLIL
    (``.il``), top module ``bayesmachine``."""
    from amaranth.back import rtlil

    from .machine import BayesianMachine

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".v", ".sv", ".il"):
        raise ValueError(
            f"cannot tell the output format from {path.name!r}: use a .v (Verilog) or .il (RTLIL) name"
        )
    if top is None:
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
    p.add_argument("--rng", choices=("lfsr", "external"), default="lfsr",
                   help="random numbers from on-chip LFSRs or an 'entropy' input port (default lfsr)")
    p.add_argument("--seed", type=_int, default=1,
                   help="machine seed for LFSR polynomials and states (default 1)")
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
    p.add_argument("--top", choices=("machine", "stereo"), default="machine",
                   help="machine: likelihood words in (default); stereo: pixel pairs in, the front end on "
                   "chip (docs/frontend.md)")
    from .frontend.cli import add_options as add_stereo_options

    add_stereo_options(p)
    p.add_argument("-o", "--output", default="build/bayesmachine.v",
                   help="output file; .v for Verilog, .il for RTLIL (default build/bayesmachine.v)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    lanes = {} if args.lanes is None else {"lanes": args.lanes}
    options = dict(
        columns=args.columns,
        word_bits=args.word_bits,
        counter_max=args.counter_max,
        rng=args.rng,
        seed=args.seed,
        max_cycles=args.max_cycles,
        tie_break=args.tie_break,
        prior=args.prior,
    )
    if args.top == "stereo":
        from .frontend.cli import build
        from .frontend.cli import summary as stereo_summary

        top = build(args, {**lanes, **options})
        path = emit(top.params, args.output, top)
        print(summary(top.params).split("\nports")[0])
        print(stereo_summary(top))
        print(f"wrote {path}")
        return 0
    params = MachineParams.for_disparity(args.dmax, **lanes, **options)
    path = emit(params, args.output)
    print(summary(params))
    print(f"wrote {path}")
    return 0
