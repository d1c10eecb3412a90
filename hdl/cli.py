"""``bayesmachine emit``: write the machine's RTL as Verilog (``.v``) or RTLIL (``.il``)."""

from __future__ import annotations

import argparse

from bayesmachine.cliargs import (
    add_census_options,
    add_dmax_option,
    add_machine_options,
    int_in_range,
    machine_params_from_args,
    model_params_from_args,
    output_path,
)

from .emit import emit, summary
from .frontend import MAX_MACHINES

__all__ = ["register"]


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
    p.add_argument("--top", choices=("machine", "stereo", "classifier"), default="machine",
                   help="machine: likelihood words in (default); stereo: pixel pairs in, the front end on "
                   "chip (docs/frontend.md); classifier: feature bins in, each feature's likelihood memory "
                   "read at its bin, its tables loaded on a stream (--classes, --features, --bins; "
                   "docs/classifier.md)")
    from .classifier_cli import add_emit_options as add_classifier_options
    from .frontend.cli import add_options as add_stereo_options

    add_stereo_options(p)
    add_classifier_options(p)
    p.add_argument("--machines", type=int_in_range(1, MAX_MACHINES), default=None,
                   help="--top stereo: machines behind the one feature pipeline, map rows dealt to them "
                   f"(1 .. {MAX_MACHINES}, default 1; docs/frontend.md)")
    # --model (default DEFAULT_MODEL, cliargs.default_model): the machine the model needs.
    add_census_options(p, title="model (the model's machine; with --top stereo its front end too)")
    p.add_argument("-o", "--output", type=output_path, default="build/bayesmachine.v",
                   help="output file; .v for Verilog, .il for RTLIL (default build/bayesmachine.v)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from .frontend.cli import check_top

    check_top(args)  # stereo options with --top machine would do nothing: refused
    if args.machines is not None and args.top != "stereo":
        raise ValueError(f"--machines: only with --top stereo (got --top {args.top})")
    from .classifier_cli import build_from_args

    classifier = build_from_args(args)  # None for another top (its options refused there)
    if classifier is not None:
        path = emit(classifier.params, args.output, classifier)
        print(summary(classifier.params).split("\nports")[0])
        print(f"classifier: {classifier.features} likelihood memories of {classifier.bins} rows x "
              f"{classifier.params.rows} classes' energy codes, read at the observed bins")
        print(f"wrote {path}")
        return 0
    model = model_params_from_args(args)
    params = machine_params_from_args(args, args.dmax, model=model)
    if args.top == "stereo":
        from .frontend.cli import build
        from .frontend.cli import summary as stereo_summary

        top = build(args, params)
        path = emit(top.params, args.output, top)
        print(summary(top.params).split("\nports")[0])
        print(stereo_summary(top))
        print(f"wrote {path}")
        return 0
    path = emit(params, args.output)
    print(summary(params))
    print(f"wrote {path}")
    return 0
