"""The ``bayesmachine`` command. Each package registers its own subcommands."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    from bayesmachine.fpga.cli import register as register_fpga
    from bayesmachine.hdl.cli import register as register_hdl
    from bayesmachine.host.cli import register as register_host

    parser = argparse.ArgumentParser(
        prog="bayesmachine",
        description="Stochastic Bayesian machine for stereo disparity: emit its RTL, "
        "run it (model, Amaranth simulator, Verilator) on stereo pairs, compare with exact inference.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    register_hdl(sub)
    register_host(sub)
    register_fpga(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        # Bad input and impossible parameters end with one clear line, not a traceback.
        print(f"bayesmachine {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
