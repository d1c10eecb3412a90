"""The log integrator (``bayesmachine.hdl.log.LogIntegrator``, the log machine's) through Yosys
``synth_ecp5``: LUT4, carry cells, flip-flops per pipeline setting, and with ``--pnr`` its fmax from
nextpnr-ecp5 on the LFE5U-85F. ``--feedback``: with census-lr's feedback column (the left prior's
codes) as the machine has it.

Resources are the integrator's own: synthesized behind a register on every port bit
(``fpga.port_registers.PortRegisters``; Yosys 0.70's ABC9 step fails an assertion on the bare
integrator), those registers subtracted from the flip-flops. The fmax is the integrator behind the
pin-saving wrapper (``fpga.wrapper.PinWrapper``, the one ``bayesmachine synth`` uses: every port
registered, so the timing is the core's), placed and routed once per setting, one place and route at
a time. Every figure is printed with its setting; docs/integrators.md holds the ones measured with
the command it names.
"""

from __future__ import annotations

import itertools
import sys
import tempfile
import time
from pathlib import Path

from amaranth.back import rtlil

from bayesmachine.argtypes import float_in_range, int_in_range, value_list
from bayesmachine.cli import Parser, run_script
from bayesmachine.columns.energy import exp_table
from bayesmachine.fpga.flow import parse_nextpnr, place_and_route, synthesize
from bayesmachine.fpga.port_registers import PortRegisters
from bayesmachine.fpga.report import logic_cells, resources
from bayesmachine.fpga.targets import get_target
from bayesmachine.fpga.wrapper import PinWrapper
from bayesmachine.hdl.log import ArgminTree, LogIntegrator, LogParams, RowAdders, WeightStage
from bayesmachine.integrators.log import MAX_CODE_BITS
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import TIE_BREAKS

CELLS = ("LUT4", "CCU2C", "PFUMX", "L6MUX21", "TRELLIS_FF", "DP16KD", "TRELLIS_DPR16X4")


def block_costs(p: LogParams, levels: int, adder_levels: int, workdir: Path, quiet: bool) -> None:
    """Each block of the integrator synthesized on its own (behind port registers): where the cells go."""
    say = (lambda _msg: None) if quiet else print
    target = get_target("ecp5-85k")
    blocks = {"row adders": RowAdders(params=p, levels_per_stage=adder_levels),
              "argmin tree (sums carried)": ArgminTree(params=p, levels_per_stage=levels, pass_sums=True),
              "weights stage": WeightStage(params=p)}
    for name, block in blocks.items():
        ring = PortRegisters(block)
        out = workdir / name.split()[0]
        out.mkdir(parents=True, exist_ok=True)
        res = resources(target, synthesize(rtlil.convert(ring, name="top"), target, out, say))
        print(f"  {name:28} latency {block.latency}: {res['lut4']:6} LUT4 {res['carry']:5} CCU2C "
              f"{res['ff'] - ring.boundary_bits:6} FF", flush=True)


def census_lr_feedback() -> dict:
    """census-lr's feedback column as its log machine has it: ``LogIntegrator``'s feedback arguments."""
    machine = disparity_machine(ModelParams(name="census-lr"), integrator="log")
    return {"feedback_words": machine.feedback_words, "feedback_nomatch_word": machine.feedback_nomatch_word}


def measure(p: LogParams, levels: int, adder_levels: int, workdir: Path, pnr: bool, seed: int,
            quiet: bool, feedback: dict) -> dict:
    """Synthesis counts of the integrator alone and, with ``pnr``, the wrapped design's fmax."""
    say = (lambda _msg: None) if quiet else print
    target = get_target("ecp5-85k")

    def build() -> LogIntegrator:
        return LogIntegrator(params=p, levels_per_stage=levels, adder_levels_per_stage=adder_levels,
                             **feedback)

    core = build()
    latency = core.latency
    alone = workdir / "alone"
    alone.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    ring = PortRegisters(core)
    cells = synthesize(rtlil.convert(ring, name="top"), target, alone, say)
    res = resources(target, cells)
    res["ff"] -= ring.boundary_bits
    out = {"latency": latency, "synth_s": time.perf_counter() - t0, "cells": cells,
           "lut4": res["lut4"], "carry": res["carry"], "ff": res["ff"], "sites": logic_cells(target, res)}
    if pnr:
        placed = workdir / "placed"
        placed.mkdir(parents=True, exist_ok=True)
        wrapped = build()
        synthesize(rtlil.convert(PinWrapper(wrapped, pin_width=8), name="top"), target, placed, say)
        t0 = time.perf_counter()
        report = parse_nextpnr(place_and_route(target, placed, 150.0, seed, say))
        out.update(fmax=report["fmax_mhz"], pnr_s=time.perf_counter() - t0,
                   critical=report["critical_path"])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ints = value_list
    ap.add_argument("--rows", type=int_in_range(1, 4096), default=82,
                    help="M (default 82: Dmax 80 and the no-match row)")
    ap.add_argument("--codes", type=ints(int_in_range(1, 64), "N"), default=[4, 7],
                    help="N values, comma-separated (default 4,7)")
    ap.add_argument("--code-bits", type=ints(int_in_range(1, MAX_CODE_BITS), "width"), default=[6, 7, 8],
                    help="code widths (default 6,7,8)")
    ap.add_argument("--levels", type=ints(int_in_range(1, 64), "level count"), default=[1, 2, 3, 7],
                    help="argmin-tree levels per register stage (default 1,2,3,7)")
    ap.add_argument("--adder-levels", type=ints(int_in_range(1, 64), "level count"), default=[1],
                    help="adder-tree levels per stage (default 1)")
    ap.add_argument("--weight-bits", type=int_in_range(1, 15), default=8,
                    help="exp table: X[0] = 2^bits (default 8)")
    ap.add_argument("--step", type=float_in_range(1e-3, 16.0), default=1 / 16,
                    help="exp table: nats per code (default 1/16)")
    ap.add_argument("--tie-break", default="nomatch-first", choices=TIE_BREAKS)
    ap.add_argument("--feedback", action="store_true",
                    help="with census-lr's feedback column, the last of the N codes per row (its codes "
                         "need 6 bits or more)")
    ap.add_argument("--pnr", action="store_true", help="also place and route for fmax (minutes each)")
    ap.add_argument("--seed", type=int_in_range(0, (1 << 31) - 1), default=1, help="nextpnr seed")
    ap.add_argument("--blocks", action="store_true", help="also each block alone, per setting")
    ap.add_argument("--verbose", action="store_true", help="the tools' progress lines")
    args = ap.parse_args(argv)
    table = exp_table(args.weight_bits, args.step)
    feedback = census_lr_feedback() if args.feedback else {}
    title = "LogIntegrator with a feedback column" if feedback else "LogIntegrator"
    print(f"{title}, {args.rows} rows, exp table {len(table)} entries of {args.weight_bits + 1} bits "
          f"(step {args.step:g} nat), {args.tie_break}; Yosys synth_ecp5 (LFE5U-85F)"
          + ("; fmax: nextpnr-ecp5 behind PinWrapper, seed " + str(args.seed) if args.pnr else ""))
    print(f"{'N':>3} {'bits':>4} {'lvl':>3} {'add':>3} {'lat':>3} {'LUT4':>7} {'CCU2C':>6} {'sites':>7} "
          f"{'FF':>7} {'fmax':>7}  critical path")
    with tempfile.TemporaryDirectory(dir=Path.home()) as tmp:  # YoWASP sees the home directory
        for codes, bits, levels, adder in itertools.product(args.codes, args.code_bits, args.levels,
                                                             args.adder_levels):
            p = LogParams(rows=args.rows, codes=codes, code_bits=bits, weights=table,
                          tie_break=args.tie_break)
            r = measure(p, levels, adder, Path(tmp) / f"n{codes}-b{bits}-l{levels}-a{adder}", args.pnr,
                        args.seed, not args.verbose, feedback)
            fmax = f"{r['fmax']:7.2f}" if "fmax" in r else f"{'-':>7}"
            crit = r.get("critical", {})
            path = (f"{crit['start_net']} -> {crit['end_net']} ({crit['logic_ns']} ns logic, "
                    f"{crit['routing_ns']} ns routing)" if crit else "")
            print(f"{codes:3} {bits:4} {levels:3} {adder:3} {r['latency']:3} {r['lut4']:7} {r['carry']:6} "
                  f"{r['sites']:7} {r['ff']:7} {fmax}  {path}", flush=True)
            if args.blocks:
                block_costs(p, levels, adder, Path(tmp) / f"blocks-n{codes}-b{bits}-l{levels}-a{adder}",
                            not args.verbose)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
