"""``bayesmachine synth``: the machine (``--top machine``) or the camera-fed StereoMachine (``--top
stereo``: front end + FIFO + machine) through Yosys and nextpnr, with a report of what it costs and
how fast it runs (see docs/fpga.md)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from bayesmachine.cliargs import add_dmax_option, add_machine_options, machine_params_from_args
from bayesmachine.hdl.frontend import DEFAULT_FIFO_PIXELS
from bayesmachine.likelihood import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sources import source_kind

from .targets import TARGETS, get_target

__all__ = ["register", "measure_cycles", "synth"]


def measure_cycles(params: MachineParams, progress: bool = True,
                   model: ModelParams | None = None) -> dict[str, object]:
    """Compute and wall cycles per pixel of ``params`` on the bundled pair (the model's cycles, and the
    RTL's per-pixel timing ``pixel_wall_cycles`` on top: loading included). ``model``: the disparity
    model whose words the machine runs on (default: the paper's, Dmax = rows - 2)."""
    from bayesmachine.hdl.machine import pixel_wall_cycles
    from bayesmachine.host.images import bundled_pair
    from bayesmachine.host.run import prepare, run_machine

    if not (params.nomatch_row and params.columns == 3):
        raise ValueError("throughput is measured on a stereo pair: it needs a disparity machine "
                         "(3 columns and a no-match row); pass --no-throughput")
    left, right, _ = bundled_pair()
    if model is None:
        model = ModelParams(dmax=params.rows - 2)
    elif model.dmax != params.rows - 2:
        raise ValueError(f"model dmax {model.dmax} does not match the machine's {params.rows - 2}")
    # The cycles need the machine only: no float64 reference.
    prepared = prepare(left, right, model, reference=False)
    c = run_machine(prepared, params, "model", progress=progress, chunk_rows=32).cycles.reshape(-1)
    return {
        "pair": f"bundled Middlebury Motorcycle {left.shape[1]}x{left.shape[0]}, model engine",
        "pixels": int(c.size),
        "compute_cycles_per_pixel": round(float(c.mean()), 3),
        "wall_cycles_per_pixel": round(float(pixel_wall_cycles(params, c).mean()), 3),
    }


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``synth`` subcommand."""
    p = subparsers.add_parser(
        "synth",
        help="synthesize, place and route the machine for an FPGA (Yosys + nextpnr) and report",
        description="Put the machine (or several, --machines), or with --top stereo the camera-fed "
        "StereoMachine (front end + FIFO + machine, pixel pairs in), behind the pin-saving wrapper, run "
        "Yosys and nextpnr (PyPI WebAssembly wheels: pip install 'bayesmachine[fpga]'), and write "
        "OUT/report.json and OUT/report.md: resources (block RAM included), fmax, critical path, lanes "
        "that fit and the throughput measured on the bundled pair. The first call of each tool compiles "
        "it (about a minute); nextpnr takes minutes on a full machine.",
    )
    p.add_argument("--target", required=True, choices=sorted(TARGETS), help="FPGA device")
    p.add_argument("--top", choices=("machine", "stereo"), default="machine",
                   help="machine: the machine alone, likelihood words in (default); stereo: the "
                   "StereoMachine, rectified pixel pairs in, the front end and its FIFO on chip "
                   "(docs/frontend.md); takes --width, --fifo-pixels and the model options")
    g = p.add_argument_group("machine (the options of emit; --rng: an on-chip source)")
    add_dmax_option(g)
    add_machine_options(g, title=None)
    from bayesmachine.hdl.frontend.cli import add_options as add_stereo_options

    add_stereo_options(p)
    p.add_argument("--machines", type=int, default=1,
                   help="machines side by side behind one load and one result stream (default 1; "
                   "--top machine only)")
    p.add_argument("--pin-width", type=int, default=8, help="wrapper chunk width in pins (default 8)")
    p.add_argument("--freq", type=float, default=150.0, help="nextpnr clock target in MHz (default 150)")
    p.add_argument("--pnr-seed", type=int, default=1, help="nextpnr placement seed (default 1)")
    p.add_argument("--router", choices=("router1", "router2"), default="router2",
                   help="nextpnr router (default router2: much faster than router1 on a full machine)")
    p.add_argument("--synth-only", action="store_true",
                   help="stop after Yosys: resources only, no fmax (for designs too big to route here)")
    p.add_argument("--no-throughput", action="store_true",
                   help="skip the model run on the bundled pair (no pixels/s in the report)")
    p.add_argument("-o", "--output", default=None,
                   help="output directory (default build/synth-TARGET, build/synth-stereo-TARGET with "
                   "--top stereo)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    params = machine_params_from_args(args, args.dmax)
    stereo: dict[str, object] = {}
    if args.top == "stereo":
        from bayesmachine.cliargs import model_params_from_args
        from bayesmachine.hdl.frontend.cli import stereo_params

        params = stereo_params(args, params)
        stereo = {"width": args.width, "model": model_params_from_args(args), "fifo_pixels": args.fifo_pixels}
    name = f"synth-stereo-{args.target}" if stereo else f"synth-{args.target}"
    out = Path(args.output or f"build/{name}")
    synth(params, args.target, out, machines=args.machines, pin_width=args.pin_width, freq_mhz=args.freq,
          pnr_seed=args.pnr_seed, place=not args.synth_only, measure=not args.no_throughput,
          router=args.router, **stereo)  # type: ignore[arg-type]
    return 0


def synth(params: MachineParams, target_name: str, out: Path, *, machines: int = 1, pin_width: int = 8,
          freq_mhz: float = 150.0, pnr_seed: int = 1, place: bool = True, measure: bool = True,
          progress: bool = True, router: str = "router2", width: int | None = None,
          model: ModelParams | None = None, fifo_pixels: int = DEFAULT_FIFO_PIXELS) -> dict:
    """The whole flow; returns the report (also written to ``out/report.json`` and ``out/report.md``).

    With ``width`` (pixels per image line) the design is the camera-fed ``StereoMachine`` of the
    machine ``params``, the disparity ``model`` (default: the paper's, Dmax = rows - 2) and a FIFO
    of ``fifo_pixels``, instead of the machine alone; one StereoMachine (``machines`` = 1).
    Every parameter is checked before any file is written."""
    from amaranth.back import rtlil
    from amaranth.lib import wiring

    from bayesmachine.hdl.emit import summary
    from bayesmachine.hdl.frontend.stereo import StereoMachine, check_stereo_machine
    from bayesmachine.hdl.lanes import MachineLanes
    from bayesmachine.hdl.machine import BayesianMachine
    from bayesmachine.outputs import atomic_write_text

    from . import report as rep
    from .flow import parse_nextpnr, place_and_route, synthesize
    from .wrapper import PinWrapper

    target = get_target(target_name)
    if isinstance(machines, bool) or not isinstance(machines, int) or machines < 1:
        raise ValueError(f"machines must be a positive integer, got {machines!r}")
    if not freq_mhz > 0:
        raise ValueError(f"freq must be > 0 MHz, got {freq_mhz}")
    if not source_kind(params.rng).on_chip:
        raise ValueError(f"synth needs an on-chip random source, not {params.rng!r} (numbers on a port "
                         "as wide as the matrix): --rng lfsr, lfsr-shared or sobol")
    if measure and not (params.nomatch_row and params.columns == 3):
        raise ValueError("throughput is measured on a stereo pair: it needs a disparity machine "
                         "(3 columns and a no-match row); pass --no-throughput")
    if width is None and model is not None:
        raise ValueError("a disparity model is for the stereo top: give the image width too")
    if width is not None and machines != 1:
        raise ValueError(f"--top stereo is one StereoMachine (its front end feeds one machine), not "
                         f"--machines {machines}")
    if width is not None:
        model = model if model is not None else ModelParams(dmax=params.rows - 2)
        check_stereo_machine(params, model, width, fifo_pixels)
    if isinstance(pin_width, bool) or not isinstance(pin_width, int) or not 1 <= pin_width <= 64:
        raise ValueError(f"pin_width must be an integer in [1, 64], got {pin_width!r}")
    # Every parameter is valid: build (a component whose constructor failed would warn as unused).
    core: wiring.Component
    if width is not None:
        core = StereoMachine(params=params, model=model, width=width, fifo_pixels=fifo_pixels)
    else:
        core = (BayesianMachine(params=params) if machines == 1
                else MachineLanes(params=params, machines=machines))
    top = PinWrapper(core, pin_width=pin_width)
    t0 = time.monotonic()

    def say(msg: str) -> None:
        if progress:
            print(f"[{time.monotonic() - t0:6.0f} s] {msg}", file=sys.stderr, flush=True)

    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").unlink(missing_ok=True)  # never leave a stale report beside new work files
    if width is not None:
        say(f"elaborating the StereoMachine ({width}-pixel lines, {params.operators} operators) for "
            f"{target.device}")
    else:
        say(f"elaborating {machines} machine(s) of {params.operators} operators for {target.device}")
    text = rtlil.convert(top, name="top")
    cells = synthesize(text, target, out, say)
    res = rep.resources(target, cells)
    report: dict = {
        "target": target.name,
        "device": target.device,
        "machine": params.to_dict(),
        "machine_summary": f"Dmax {params.rows - 2}, N {params.columns}, counter max {params.counter_max}, "
        f"W {params.word_bits}, rng {params.rng}, {params.lanes} words per load beat",
        "top": "stereo" if width is not None else "machine",
        "stereo": None,
        "lanes": machines,
        "pin_width": pin_width,
        "cells": cells,
        "resources": res,
        "utilization": rep.utilization(target, res),
    }
    if width is not None:
        assert model is not None
        report["stereo"] = {
            "width": width,
            "fifo_pixels": fifo_pixels,
            "fifo_beats": fifo_pixels * params.beats_per_pixel,
            "beats_per_pixel": params.beats_per_pixel,
            "beat_bits": params.lanes * params.memory_word_width,
            "model": dataclasses.asdict(model),
            "input_bits": rep.PIXEL_BITS,
        }
    logic = rep.logic_cells(target, res)
    report["per_lane"] = {"lut4": logic / machines, "ff": res["ff"] / machines,
                          "bram": res["bram"] / machines, "dsp": res["dsp"] / machines}
    report["per_operator"] = {"lut4": round(logic / (machines * params.operators), 2),
                              "ff": round(res["ff"] / (machines * params.operators), 2)}
    report["lanes_fit"] = rep.lanes_that_fit(target, report["per_lane"], {})
    if place:
        pnr = parse_nextpnr(place_and_route(target, out, freq_mhz, pnr_seed, say, router))
        report.update(pnr)
        # Placed logic cells (a slice half or an iCE40 logic cell holds a LUT and a flip-flop) can
        # bind before LUTs or flip-flops alone do: count lanes against them too.
        for key in ("TRELLIS_COMB", "TRELLIS_FF", "ICESTORM_LC"):
            u = pnr["pnr_utilization"].get(key)
            if u and u["used"]:
                fit = int(0.9 * u["available"] // (u["used"] / machines))
                report["lanes_fit"] = min(report["lanes_fit"], fit)
        report["lanes_fit"] = max(report["lanes_fit"], machines)  # these just placed and routed
        what = "one StereoMachine" if width is not None else f"{machines} machine(s)"
        report["measured"] = (f"Yosys {target.yosys_synth} and nextpnr ({router}) place and route of "
                              f"{what}; lanes that fit from synthesis utilization "
                              f"(at most 90 % of each resource)")
    else:
        report.update({"fmax_mhz": None, "critical_path": {}})
        report["measured"] = f"Yosys {target.yosys_synth} only (no place and route: no fmax)"
    if measure:
        say("throughput: running the model on the bundled pair")
        cyc = measure_cycles(params, progress, model)
        tp: dict = dict(cyc)
        if width is not None:
            # Pixels in, results out: the front end hides loading (benchmarks/bench_frontend.py), so a
            # pixel takes the machine's own wall cycles; the input is every pixel pair of the frame.
            tp.update(rep.stereo_throughput(report["fmax_mhz"], cyc["wall_cycles_per_pixel"], width,
                                            params.rows - 2))
        elif report["fmax_mhz"]:
            beat_bits = params.lanes * params.memory_word_width
            tp.update(rep.throughput(report["fmax_mhz"], machines, cyc["wall_cycles_per_pixel"],
                                     params.beats_per_pixel, beat_bits))
            # The lanes that fit, each fed a pixel per beat (the load stream widened to keep up).
            fit = rep.throughput(report["fmax_mhz"], max(1, report["lanes_fit"]),
                                 cyc["wall_cycles_per_pixel"], 1,
                                 params.words_per_pixel * params.memory_word_width)
            tp["vga_fps_fit"] = fit["vga_fps"]
            tp["load_bits_per_second_fit"] = fit["load_bits_per_second"]
        report["throughput"] = tp
    report["seconds"] = round(time.monotonic() - t0, 1)
    atomic_write_text(out / "report.md", rep.markdown(report))
    atomic_write_text(out / "report.json", rep.dumps(report))  # last: its presence means a complete run
    say(f"wrote {out / 'report.json'} and {out / 'report.md'}")
    if progress:
        print(summary(params).splitlines()[0])
        print(rep.markdown(report))
    return report
