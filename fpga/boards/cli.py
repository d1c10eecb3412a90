"""``bayesmachine board build|simulate``: the ULX3S bitstream, and its design simulated behind a
pseudo-terminal (see docs/board.md)."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from bayesmachine.cliargs import (
    BAUD_RANGE,
    DEFAULT_BAUD,
    add_dmax_option,
    add_machine_options,
    add_model_options,
    float_in_range,
    int_arg,
    int_in_range,
    machine_params_from_args,
    model_params_from_args,
    output_path,
)
from bayesmachine.fpga.flow import ROUTERS
from bayesmachine.hdl.frontend import DEFAULT_WIDTH
from bayesmachine.models import BOARD_MODEL, DEFAULT_MODEL

from .build import DEFAULT_BOARD_ROUTER, DEFAULT_BOARD_SEED
from .devices import BOARDS
from .link import record_design

__all__ = ["register"]


def _design_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--board", choices=sorted(BOARDS), default="ulx3s-85f", help="the ULX3S's FPGA (default ulx3s-85f)"
    )
    p.add_argument(
        "--top",
        choices=("stereo",),
        default="stereo",
        help="stereo: the camera-fed StereoMachine (front end + machine), pixel pairs in (the only top "
        "so far)",
    )
    p.add_argument(
        "--width",
        type=int_arg,
        default=DEFAULT_WIDTH,
        help=f"pixels per line of every frame the board takes (default {DEFAULT_WIDTH}); "
        "run --engine board needs pairs (or crops) of this width",
    )
    g = p.add_argument_group("machine (the options of emit; --rng: an on-chip source)")
    add_dmax_option(g)
    add_machine_options(g, title=None)
    add_model_options(p, dmax=False, census=True, title="model (paper table 1 defaults)",
                      default=f"{BOARD_MODEL}, the board's: its StereoMachine meets the ULX3S-85F's 45 MHz "
                      f"clock; {DEFAULT_MODEL}'s, every other command's default, does not (docs/board.md)")


def _design(args: argparse.Namespace):  # noqa: ANN202
    """(machine, model, width) the options describe, checked (one clear error)."""
    import dataclasses

    from bayesmachine.params import stereo_words_per_beat

    from .core import check_board

    model = model_params_from_args(args)
    machine = machine_params_from_args(args, args.dmax, model=model)
    if args.words_per_beat is None:
        machine = dataclasses.replace(machine, words_per_beat=stereo_words_per_beat(machine))
    check_board(machine, model, args.width)
    return machine, model, args.width


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``board build`` and ``board simulate``."""
    p = subparsers.add_parser(
        "board",
        help="a ULX3S bitstream with a serial host link, and its simulation on a pseudo-terminal",
        description="The camera-fed StereoMachine on a ULX3S board behind a UART (the board's FTDI"
        " USB-serial link), driven by `bayesmachine run --engine board --port PORT`. See docs/board.md.",
    )
    sub = p.add_subparsers(dest="board_command", metavar="SUBCOMMAND", required=True)

    b = sub.add_parser(
        "build",
        help="build the bitstream (Yosys, nextpnr-ecp5, ecppack from PyPI)",
        description="Build OUT/top.bit and OUT/top.svf for a ULX3S: the board's 25 MHz clock through the"
        " ECP5 PLL, the UART on the FTDI pins, status on the LEDs, FIRE1 as reset. Writes OUT/nextpnr.log"
        " (timing "
        "report) and OUT/report.json (resources, fmax, the clock asked for, timing_met, the command to "
        "program it) last. Place and route takes 10+ minutes for the default design.",
    )
    _design_options(b)
    b.add_argument(
        "--clock",
        type=float_in_range(10, 200),
        default=None,
        metavar="MHZ",
        help="the design's clock from the PLL, 10 .. 200 MHz (default 45: 3 Mbaud in 15 clocks per bit)",
    )
    b.add_argument("--baud", type=int_in_range(*BAUD_RANGE), default=None,
                   help=f"UART baud rate, {BAUD_RANGE[0]} .. {BAUD_RANGE[1]} (default {DEFAULT_BAUD})")
    b.add_argument("--pnr-seed", type=int_in_range(0, 2**31 - 1), default=DEFAULT_BOARD_SEED,
                   help=f"nextpnr placement seed, 0 to 2^31 - 1 (default {DEFAULT_BOARD_SEED})")
    b.add_argument("--router", choices=ROUTERS, default=DEFAULT_BOARD_ROUTER,
                   help=f"nextpnr router (default {DEFAULT_BOARD_ROUTER}, the one that routes the census "
                   "design on the ULX3S-85F: docs/board.md, timing closure)")
    b.add_argument(
        "-o", "--output", type=output_path, default=None, help="output directory (default build/BOARD)"
    )
    b.set_defaults(func=_build)

    s = sub.add_parser(
        "simulate",
        help="run the board's design under Verilator behind a pseudo-terminal",
        description="Simulate the board's design (UART at bit level, protocol, StereoMachine) under"
        " Verilator, its UART bridged to a pseudo-terminal. The first line of output is the pseudo-terminal's"
        " path: give it to `bayesmachine run --engine board --port PATH`. Serves until interrupted (Ctrl-C,"
        " SIGTERM); SIGUSR1 "
        "resets the simulated board. Use a small --width and --dmax: every bit of the UART is simulated.",
    )
    _design_options(s)
    s.add_argument(
        "--sim-clocks-per-bit",
        type=int_in_range(4, 1 << 16),
        default=4,
        help="simulated clock cycles per UART bit, 4 .. 65536 (default 4: the pty has no baud rate)",
    )
    s.add_argument(
        "--sim-timeout-bits",
        type=int_in_range(16, 1 << 30),
        default=None,
        help="the board's receive timeout in bit times, 16 .. 2^30 (default 131072: simulated time runs only "
        "while the harness has the CPU, so shorter ones may fire while a loaded host is still sending)",
    )
    s.add_argument("--quiet", action="store_true", help="only the path")
    s.add_argument("-o", "--output", type=output_path, default=None, metavar="OUT/",
                   help="also write OUT/report.json: the design simulated (machine, model, width, "
                   "fingerprint), the options `run --engine board` must match")
    s.set_defaults(func=_simulate)


def _build(args: argparse.Namespace) -> int:
    from .build import DEFAULT_CLOCK_MHZ, board_build

    machine, model, width = _design(args)
    out = Path(args.output or f"build/{args.board}")
    report = board_build(
        machine,
        model,
        width,
        args.board,
        out,
        clock_mhz=DEFAULT_CLOCK_MHZ if args.clock is None else args.clock,
        baud=DEFAULT_BAUD if args.baud is None else args.baud,
        seed=args.pnr_seed,
        router=args.router,
    )
    print(
        f"{out / 'top.bit'}: {report['fmax_mhz']} MHz achieved, {report['constraint_mhz']:g} MHz asked: "
        f"timing {'met' if report['timing_met'] else 'NOT met'}; {report['baud']} baud"
    )
    print(f"program it: {report['program']}  (or: {report['program_alternative']})")
    record_design(machine, model, width)
    return 0


def _simulation_report(out, args: argparse.Namespace, machine, model, width: int, port: str,  # noqa: ANN001
                       timeout_bits: int) -> None:
    """``board simulate -o OUT``: OUT/report.json, the design as ``board build``'s report gives it."""
    import json

    from . import protocol as pr
    from .simulate import DEFAULT_SIM_RX_FIFO_LOG2

    report = {
        "board": args.board, "top": "stereo", "simulated": True, "port": port, "width": width,
        "model": model.to_dict(), "machine": machine.to_dict(),
        "fingerprint": f"{pr.board_fingerprint(machine.to_dict(), model.to_dict(), width):08x}",
        "protocol_version": pr.PROTOCOL_VERSION, "clocks_per_bit": args.sim_clocks_per_bit,
        "rx_fifo_bytes": 1 << DEFAULT_SIM_RX_FIFO_LOG2, "timeout_bits": timeout_bits,
    }
    out.write("report.json", lambda path: path.write_text(json.dumps(report, indent=2) + "\n"))
    out.commit()


def _simulate(args: argparse.Namespace) -> int:
    import contextlib

    from bayesmachine.outputs import OutputDir

    from .simulate import DEFAULT_SIM_TIMEOUT_BITS, BoardSimulation

    machine, model, width = _design(args)
    timeout_bits = DEFAULT_SIM_TIMEOUT_BITS if args.sim_timeout_bits is None else args.sim_timeout_bits
    with contextlib.ExitStack() as stack:
        # OUT first: a report.json there that is not ours is refused before the harness is built.
        out = None if args.output is None else stack.enter_context(
            OutputDir(args.output, ("report.json",), last="report.json"))
        sim = stack.enter_context(BoardSimulation(
            machine, model, width, clocks_per_bit=args.sim_clocks_per_bit, timeout_bits=timeout_bits,
            verbose=not args.quiet))
        record_design(machine, model, width)
        if out is not None:
            _simulation_report(out, args, machine, model, width, sim.port, timeout_bits)
        print(sim.port, flush=True)
        if not args.quiet:
            print(
                f"board simulate: {args.board} design (Dmax {model.dmax}, width {width}) on {sim.port}, "
                f"{args.sim_clocks_per_bit} cycles per bit; Ctrl-C to stop",
                file=sys.stderr,
                flush=True,
            )
        previous = signal.signal(signal.SIGUSR1, lambda *_: sim.reset())
        try:
            while sim.running:
                sim.wait(0.5)
        finally:
            signal.signal(signal.SIGUSR1, previous)
    # Reached only when the harness ended by itself (an interruption ends the command above).
    raise RuntimeError("the simulated board's harness ended unexpectedly")
