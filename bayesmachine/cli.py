"""The ``bayesmachine`` command. Each package registers its own subcommands.

Every failure ends as one line on stderr: bad arguments and bad input (ValueError),
impossible runs (RuntimeError), file-system problems (any OSError, naming the path) and
exhausted memory give exit code 2; Ctrl-C gives exit code 130 and SIGTERM 143, after the
same cleanup (SIGTERM is raised as :class:`Terminated`, a KeyboardInterrupt). Commands write
their files through :mod:`bayesmachine.outputs` and run tools through
:mod:`bayesmachine.tools`, so none of these leaves a partial output or a tool running.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any, NoReturn

from bayesmachine.errors import ParameterError


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is so that it cleans up as after Ctrl-C."""


class Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (the usage is one ``--help`` away): every command's, and
    every script's of ``benchmarks/``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # An argument starting with "-" and a digit is a value, not an option (as in Python 3.13's
        # argparse): ``--crop -1,0,20,20`` reaches the crop's own check instead of "expected one
        # argument". No option of the project's is spelled like a number.
        self._negative_number_matcher = re.compile(r"-\.?\d")

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    from bayesmachine.fpga.classifier_synth import ClassifierTask
    from bayesmachine.fpga.cli import register as register_fpga
    from bayesmachine.hdl.cli import register as register_hdl
    from bayesmachine.host import classification
    from bayesmachine.host.cli import register as register_host
    from bayesmachine.host.throughput import measure_cycles

    parser = Parser(
        prog="bayesmachine",
        description="Stochastic Bayesian machine for stereo disparity: emit its RTL, "
        "run it (model, Amaranth simulator, Verilator) on stereo pairs, compare with exact inference.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    register_hdl(sub)
    register_host(sub)
    classifier = ClassifierTask(classification.BUNDLED_DATASETS, classification.held_out,
                                classification.top_cycles)
    # the one place that hands host's work to fpga
    register_fpga(sub, measure=measure_cycles, classifier=classifier)
    return parser


def describe_os_error(exc: OSError) -> str:
    """``path: problem`` for an OSError (both paths of a failed rename)."""
    problem = exc.strerror or str(exc)
    if exc.filename is not None:
        where = str(exc.filename)
        if exc.filename2 is not None:
            where += f" -> {exc.filename2}"
        return f"{where}: {problem}"
    return str(exc) if str(exc) else problem


def _one_line(text: str) -> str:
    return " ".join(text.split()) if "\n" in text else text


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """While a command runs, SIGTERM raises :class:`Terminated` (once: a second one does not
    interrupt the cleanup)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise Terminated

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def handled(prefix: str, command: Callable[[], int | None]) -> int:
    """Run ``command``; every failure ends as one line on stderr starting with ``prefix``, and its exit
    code (the module's docstring): the one rule of the commands and of the benchmark scripts."""
    try:
        with _sigterm_raises():
            return int(command() or 0)
    except Terminated:
        print(f"{prefix}: terminated (SIGTERM); no output was left half-written, no tool left running",
              file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print(f"{prefix}: interrupted; no output was left half-written", file=sys.stderr)
        return 130
    except OSError as exc:
        print(f"{prefix}: error: {_one_line(describe_os_error(exc))}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] == "bayesmachine":
            raise  # a broken install of this package is a bug to see whole
        print(f"{prefix}: error: this needs the module {exc.name!r}, which is not installed (pip install "
              "bayesmachine installs the RTL's, 'bayesmachine[host]' the host's)", file=sys.stderr)
        return 2
    except MemoryError as exc:
        detail = f" ({exc})" if str(exc) else ""
        print(f"{prefix}: error: out of memory{detail}; try --crop or a smaller --dmax", file=sys.stderr)
        return 2
    except (ValueError, RuntimeError) as exc:
        # Bad input and impossible parameters end with one clear line, not a traceback; a parameter the
        # library names is said with the command's flag for it.
        if isinstance(exc, ParameterError):
            from bayesmachine.cliargs import with_flag

            exc = with_flag(exc)
        print(f"{prefix}: error: {_one_line(str(exc))}", file=sys.stderr)
        return 2


def run_script(prog: str, main: Callable[[list[str] | None], int | None],
               argv: list[str] | None = None) -> int:
    """A ``benchmarks/`` script's entry point: ``main(argv)`` (which parses with :class:`Parser`) under
    :func:`handled`, so that bad input is one line and exit code 2, as for the commands."""
    try:
        return handled(prog, lambda: main(argv))
    except SystemExit as exc:  # --help, or a usage error already printed on one line
        return exc.code if isinstance(exc.code, int) else 2


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error already printed on one line
        return exc.code if isinstance(exc.code, int) else 2
    return handled(f"bayesmachine {args.command}", lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
