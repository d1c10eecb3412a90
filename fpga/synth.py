"""The synthesis flow behind ``bayesmachine synth``: the machine (or the camera-fed StereoMachine)
behind the pin-saving wrapper, through Yosys and nextpnr, and its report (see docs/fpga.md).

:func:`synth` is the API (tests and benchmarks call it); ``fpga/cli.py`` only parses options and
calls it, with the throughput measurement the command line hands it (``host.throughput``: this
package does not import ``host``). The output directory is an
:class:`~bayesmachine.outputs.OutputDir`: held by one run at a time, the report committed last (its
presence means a complete run), the tools' work files beside it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

from bayesmachine.checks import as_int
from bayesmachine.hdl.frontend import DEFAULT_FIFO_PIXELS
from bayesmachine.models import DEFAULT_MODEL, ModelParams
from bayesmachine.params import MachineParams

from .targets import Target, get_target

__all__ = ["Measure", "SYNTH_OUTPUTS", "synth", "throughput_model"]

# The files synth commits into OUT (the report last); the tools' work files (top.il, synth.json,
# pnr.json, logs) are written there as they run, synth.json reused while the RTL is unchanged.
SYNTH_OUTPUTS = ("report.md", "report.json")


def throughput_model(params: MachineParams, model: ModelParams | None) -> ModelParams:
    """The model whose words the throughput run feeds ``params`` (default: the hardware model's, as
    ``bayesmachine synth``), checked: a disparity machine that runs it (rows, columns, prior:
    ``models.check_disparity_machine``)."""
    from bayesmachine.models import check_disparity_machine

    model = model if model is not None else _default_model(params)
    if not params.nomatch_row:
        raise ValueError("throughput is measured on a stereo pair: it needs a disparity machine "
                         "(a no-match row); pass --no-throughput")
    check_disparity_machine(model, params)
    return model


# measure(params, model, progress, stereo=None): the cycles of the machine on the bundled pair; with
# ``stereo`` (``width``, ``fifo_pixels``, ``machines``) also the StereoMachine's frame under Verilator
# (``frame_run``; host.throughput.measure_cycles).
Measure = Callable[..., dict]


def synth(params: MachineParams, target_name: str, out: Path, *, machines: int = 1, pin_width: int = 8,
          freq_mhz: float = 150.0, pnr_seed: int = 1, place: bool = True, measure: Measure | None = None,
          progress: bool = True, router: str = "router2", width: int | None = None,
          model: ModelParams | None = None, fifo_pixels: int = DEFAULT_FIFO_PIXELS) -> dict:
    """The whole flow; returns the report (also written to ``out/report.json`` and ``out/report.md``).

    With ``width`` (pixels per image line) the design is the camera-fed ``StereoMachine`` of the
    machine ``params``, the disparity ``model`` (default: the hardware model's, Dmax = rows - 2) and a FIFO
    of ``fifo_pixels``, instead of the machine alone; one StereoMachine with ``machines`` machines
    behind its feature pipeline (map rows dealt to them; docs/frontend.md). Without
    ``width``, ``model`` is the model whose words the throughput run feeds the machine (the census
    model's machine: ``models.disparity_machine``).
    ``measure(params, model, progress)``: the cycles per pixel of the machine on that model's words
    (:func:`bayesmachine.host.throughput.measure_cycles`); None: no throughput in the report.
    Every parameter is checked before any file is written."""
    from bayesmachine.outputs import OutputDir

    from . import report as rep
    from .flow import require_tools

    target = get_target(target_name)
    model = _check(params, target, machines=machines, pin_width=pin_width, freq_mhz=freq_mhz, measure=measure,
                   width=width, model=model, fifo_pixels=fifo_pixels)
    t0 = time.monotonic()

    def say(msg: str) -> None:
        if progress:
            print(f"[{time.monotonic() - t0:6.0f} s] {msg}", file=sys.stderr, flush=True)

    require_tools(target, place)  # a missing tool or an unusable tool cache: said before any work
    if measure is not None and width is not None:
        from bayesmachine.sim.verilator.tools import find_toolchain

        find_toolchain()  # the frame is measured under Verilator: a missing tool said before any work
    # The directory is held by this run alone; the previous run's report goes before any new work.
    with OutputDir(out, SYNTH_OUTPUTS, last="report.json") as od:
        report = _synthesize(params, target, out, say, machines=machines, pin_width=pin_width, width=width,
                             model=model, fifo_pixels=fifo_pixels)
        if place:
            _place(report, target, out, say, freq_mhz=freq_mhz, seed=pnr_seed, router=router)
        else:
            report.update({"fmax_mhz": None, "fmax_provisional": None, "critical_path": {}})
            report["measured"] = f"Yosys {target.yosys_synth} only (no place and route: no fmax)"
        if measure is not None:
            if width is None:
                say("throughput: running the model on the bundled pair")
                cycles = measure(params, model, progress)
            else:
                say(f"throughput: the model on the bundled pair, then this StereoMachine under Verilator on "
                    f"a {width}-pixel-wide frame of 480 lines")
                cycles = measure(params, model, progress,
                                 stereo={"width": width, "fifo_pixels": fifo_pixels, "machines": machines})
            report["throughput"] = _throughput(report, params, model, cycles, width=width)
        report["seconds"] = round(time.monotonic() - t0, 1)
        od.write("report.md", lambda path: path.write_text(rep.markdown(report)))
        od.write("report.json", lambda path: path.write_text(rep.dumps(report)))
        od.commit()  # the report last: its presence means a complete run
    say(f"wrote {out / 'report.json'} and {out / 'report.md'}")
    if progress:
        from bayesmachine.hdl.emit import summary

        print(summary(params).splitlines()[0])
        print(rep.markdown(report))
    return report


def _check(params: MachineParams, target: Target, *, machines: int, pin_width: int, freq_mhz: float,
           measure: Measure | None, width: int | None, model: ModelParams | None,
           fifo_pixels: int) -> ModelParams:
    """Every parameter of :func:`synth`, checked (TypeError, ValueError); returns the model (its
    default: the hardware model's at Dmax = rows - 2)."""
    from bayesmachine.hdl.frontend.stereo import check_stereo_machine

    as_int("machines", machines, 1)
    if not freq_mhz > 0:
        raise ValueError(f"freq must be > 0 MHz, got {freq_mhz}")
    if params.takes_numbers:
        raise ValueError(f"synth needs an on-chip random source, not {params.rng!r} (numbers on a port "
                         "as wide as the matrix): --rng lfsr, lfsr-shared or sobol")
    if measure is not None and (isinstance(measure, bool) or not callable(measure)):
        raise TypeError("measure must be a function (params, model, progress) -> cycles, e.g. "
                        "bayesmachine.host.throughput.measure_cycles, or None")
    if measure is not None:
        model = throughput_model(params, model)  # before any work: the machine must run the model's words
    if width is not None:
        model = model if model is not None else _default_model(params)
        check_stereo_machine(params, model, width, fifo_pixels, machines)
    as_int("pin_width", pin_width, 1, 64)
    return model if model is not None else _default_model(params)


def design_operators(params: MachineParams, model: ModelParams, machines: int, *, stereo: bool) -> int:
    """The operators of a design: ``machines`` machines of ``params``; the stereo top's declared passes'
    machines too (census-lr's right pass)."""
    total = machines * params.operators
    if stereo:
        from bayesmachine.hdl.frontend.words import pass_params

        total += sum(pass_params(model, params, p.name).operators for p in model.passes[:-1])
    return total


def _default_model(params: MachineParams) -> ModelParams:
    """What ``bayesmachine synth`` builds without ``--model``: :data:`~bayesmachine.models.DEFAULT_MODEL`,
    at Dmax = rows - 2."""
    return ModelParams(name=DEFAULT_MODEL, dmax=params.rows - 2)


def _synthesize(params: MachineParams, target: Target, out: Path, say: Callable[[str], None], *,
                machines: int, pin_width: int, width: int | None, model: ModelParams,
                fifo_pixels: int) -> dict:
    """The design behind the pin wrapper through Yosys: the report's design and resource fields."""
    from amaranth.back import rtlil
    from amaranth.lib import wiring

    from bayesmachine.hdl.frontend.stereo import StereoMachine
    from bayesmachine.hdl.machines import ParallelMachines, machine_top

    from . import report as rep
    from .flow import synthesize
    from .wrapper import PinWrapper

    # Every parameter is valid and the directory is ours: build (a component built but never
    # elaborated, e.g. before a refused directory, would warn as unused).
    core: wiring.Component
    if width is not None:
        core = StereoMachine(params=params, model=model, width=width, fifo_pixels=fifo_pixels,
                             machines=machines)
        say(f"elaborating the StereoMachine ({width}-pixel lines, {machines} machine(s) of "
            f"{params.operators} operators) for {target.device}")
    else:
        core = (machine_top(params) if machines == 1
                else ParallelMachines(params=params, machines=machines))
        say(f"elaborating {machines} machine(s) of {params.operators} operators for {target.device}")
    cells = synthesize(rtlil.convert(PinWrapper(core, pin_width=pin_width), name="top"), target, out, say)
    res = rep.resources(target, cells)
    report: dict = {
        "target": target.name,
        "device": target.device,
        "machine": params.to_dict(),
        "machine_summary": ", ".join([
            f"Dmax {params.rows - 2}", f"N {params.columns}", *params.kind.brief(params),
            f"{params.words_per_beat} words per load beat"]),
        "top": "stereo" if width is not None else "machine",
        "stereo": None,
        "machines": machines,
        "pin_width": pin_width,
        "cells": cells,
        "resources": res,
        "utilization": rep.utilization(target, res),
    }
    if width is not None:
        report["stereo"] = {
            "width": width,
            "fifo_pixels": fifo_pixels,
            "fifo_beats": fifo_pixels * params.beats_per_pixel,
            "beats_per_pixel": params.beats_per_pixel,
            "beat_bits": params.words_per_beat * params.memory_word_width,
            "model": model.to_dict(),
            "input_bits": rep.PIXEL_BITS,
            # The line buffer's word: 2 margin lines of 16-bit pairs (64 bits; 96 with a 7x7 census).
            "line_buffer_bits": rep.PIXEL_BITS * 2 * model.margin,
        }
    report["operators"] = design_operators(params, model, machines, stereo=width is not None)
    logic = rep.logic_cells(target, res)
    report["per_machine"] = {"lut4": logic / machines, "ff": res["ff"] / machines,
                             "bram": res["bram"] / machines, "dsp": res["dsp"] / machines}
    report["per_operator"] = {"lut4": round(logic / report["operators"], 2),
                              "ff": round(res["ff"] / report["operators"], 2)}
    report["machines_fit"] = rep.machines_that_fit(target, report["per_machine"], {})
    return report


def _place(report: dict, target: Target, out: Path, say: Callable[[str], None], *, freq_mhz: float, seed: int,
           router: str) -> None:
    """nextpnr on the synthesized design: its figures into ``report``, the machines that fit revised."""
    from .flow import parse_nextpnr, place_and_route
    from .report import placed_sites

    machines = report["machines"]
    pnr = parse_nextpnr(place_and_route(target, out, freq_mhz, seed, say, router))
    report.update(pnr)
    report["fmax_provisional"] = target.fmax_provisional
    # Placed logic cells (a slice half or an iCE40 logic cell holds a LUT and a flip-flop; Gowin's
    # LUT4 sites, ALUs' and flip-flops' pass-through LUTs included) can bind before LUTs or
    # flip-flops alone do: count machines against them too.
    for used, available in placed_sites(target, pnr["pnr_utilization"]).values():
        fit = int(0.9 * available // (used / machines))
        report["machines_fit"] = min(report["machines_fit"], fit)
    report["machines_fit"] = max(report["machines_fit"], machines)  # these just placed and routed
    what = (f"one StereoMachine ({machines} machine(s))" if report["top"] == "stereo"
            else f"{machines} machine(s)")
    report["measured"] = (f"Yosys {target.yosys_synth} and nextpnr ({router}) place and route of "
                          f"{what}; machines that fit from synthesis utilization "
                          f"(at most 90 % of each resource)")


def _throughput(report: dict, params: MachineParams, model: ModelParams, cycles: dict, *,
                width: int | None) -> dict:
    """The report's throughput: the measured cycles per pixel and, with an fmax, the rates."""
    from . import report as rep

    tp: dict = dict(cycles)
    machines, fmax = report["machines"], report["fmax_mhz"]
    frame = tp.pop("frame_run", None)
    if width is not None and frame is not None:
        # The design itself on a frame: its wall cycles, first pixel in to last result out.
        tp.update(rep.frame_throughput(fmax, frame, width))
    elif width is not None and machines > 1:
        tp["assumes"] = ("one machine's cycles per pixel; the K-machine frame rate comes from the "
                         "wall cycles of run --engine verilator --feed pixels --machines K (the bundled "
                         f"pair is narrower than {width} pixels: no frame measured)")
    elif width is not None:
        # No frame as wide as the line in the bundled pair: the machine's own wall cycles per pixel
        # (the front end keeps up: benchmarks/bench_frontend.py); every pixel pair of the frame comes in.
        tp.update(rep.stereo_throughput(fmax, cycles["wall_cycles_per_pixel"], width, params.rows - 2,
                                        margin=model.margin))
    elif fmax:
        beat_bits = params.words_per_beat * params.memory_word_width
        tp.update(rep.throughput(fmax, machines, cycles["wall_cycles_per_pixel"], params.beats_per_pixel,
                                 beat_bits))
        # The machines that fit, each fed a pixel per beat (the load stream widened to keep up).
        fit = rep.throughput(fmax, max(1, report["machines_fit"]), cycles["wall_cycles_per_pixel"], 1,
                             params.words_per_pixel * params.memory_word_width)
        tp["vga_fps_fit"] = fit["vga_fps"]
        tp["load_bits_per_second_fit"] = fit["load_bits_per_second"]
    return tp
