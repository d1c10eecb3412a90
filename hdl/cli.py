"""``bayesmachine emit``: write the machine's RTL as Verilog (``.v``) or RTLIL (``.il``)."""

from __future__ import annotations

import argparse

from bayesmachine.params import DEFAULT_LANES, DEFAULT_MAX_CYCLES, DEFAULT_WORD_BITS, MachineParams

from .emit import emit, summary

__all__ = ["register"]


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
        rng=args.rng,
        seed=args.seed,
        max_cycles=args.max_cycles,
        tie_break=args.tie_break,
        prior=args.prior,
    )
    path = emit(params, args.output)
    print(summary(params))
    print(f"wrote {path}")
    return 0
