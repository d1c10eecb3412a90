"""``bayesmachine synth --top classifier``: the classifier top (``hdl.classifier.ClassifierTop``) behind
the pin-saving wrapper through Yosys and nextpnr, and its report: LUT4, FF, block RAM, LUT RAM, fmax and
decisions per second (fmax / the wall cycles per decision measured on a data set's held-out fold; see
docs/classifier.md and docs/fpga.md).

:func:`synth_classifier` is the API (the command and ``benchmarks/bench_classifier_synth.py`` call it);
the measurement is handed to it (``host.classification.top_cycles``: this package does not import
``host``). The output directory is an :class:`~bayesmachine.outputs.OutputDir`, as ``synth``'s.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bayesmachine.checks import as_int
from bayesmachine.params import MachineParams

from .synth import SYNTH_OUTPUTS
from .targets import Target, get_target

if TYPE_CHECKING:
    from bayesmachine.hdl.classifier import ClassifierTop

__all__ = ["ClassifierTask", "synth_classifier"]

THROUGHPUT_DECISIONS = 20  # held-out decisions whose wall cycles give the decisions per second


@dataclass(frozen=True)
class ClassifierTask:
    """What ``synth --top classifier`` is handed from ``host`` (``bayesmachine.cli``): the data sets it
    takes, ``held_out(dataset, bins=, machine=, decisions=)`` (the fitted classifier and its held-out
    observations: ``host.classification.held_out``) and ``top_cycles(held)`` (the measured throughput:
    ``host.classification.top_cycles``)."""

    datasets: tuple[str, ...]
    held_out: Callable[..., Any]
    top_cycles: Callable[[Any], dict]


def synth_classifier(params: MachineParams, features: int, bins: int, target_name: str, out: Path, *,
                     pin_width: int = 8, freq_mhz: float = 150.0, pnr_seed: int = 1, place: bool = True,
                     router: str = "router2", measure: Callable[[], dict] | None = None,
                     progress: bool = True) -> dict:
    """The classifier top of ``params`` (``classify.machine.classifier_params(fuse=1)``), ``features``
    memories of ``bins`` rows, through the flow; returns the report (also ``out/report.json`` and
    ``out/report.md``). ``measure()``: the throughput run's figures (``wall_cycles_per_decision`` and
    what it ran on); None: no decisions per second in the report. Every parameter is checked (the top's
    constructor's checks) before any file is written."""
    from bayesmachine.hdl.classifier import ClassifierTop
    from bayesmachine.outputs import OutputDir

    from . import report as rep
    from .flow import require_tools

    target = get_target(target_name)
    top = ClassifierTop(params=params, features=features, bins=bins)  # checks its parameters
    as_int("pin_width", pin_width, 1, 64)
    if not freq_mhz > 0:
        raise ValueError(f"freq must be > 0 MHz, got {freq_mhz}")
    if params.takes_numbers:
        raise ValueError(f"synth needs an on-chip random source, not {params.rng!r}")
    if measure is not None and not callable(measure):
        raise TypeError("measure must be a function () -> dict of the throughput run, or None")
    t0 = time.monotonic()

    def say(msg: str) -> None:
        if progress:
            print(f"[{time.monotonic() - t0:6.0f} s] {msg}", file=sys.stderr, flush=True)

    require_tools(target, place)
    with OutputDir(out, SYNTH_OUTPUTS, last="report.json") as od:
        report = _synthesize(top, target, out, say, pin_width)
        if place:
            _place(report, target, out, say, freq_mhz=freq_mhz, seed=pnr_seed, router=router)
        else:
            report.update({"fmax_mhz": None, "critical_path": {},
                           "measured": f"Yosys {target.yosys_synth} only (no place and route: no fmax)"})
        if measure is not None:
            say("throughput: the top's held-out decisions under pysim, checked against the model")
            tp = dict(measure())
            fmax = report["fmax_mhz"]
            tp["decisions_per_second"] = fmax * 1e6 / tp["wall_cycles_per_decision"] if fmax else None
            report["throughput"] = tp
        report["seconds"] = round(time.monotonic() - t0, 1)
        od.write("report.md", lambda path: path.write_text(markdown(report)))
        od.write("report.json", lambda path: path.write_text(rep.dumps(report)))
        od.commit()  # the report last: its presence means a complete run
    say(f"wrote {out / 'report.json'} and {out / 'report.md'}")
    if progress:
        print(markdown(report))
    return report


def _synthesize(top: ClassifierTop, target: Target, out: Path, say: Callable[[str], None],
                pin_width: int) -> dict:
    """The top behind the pin wrapper through Yosys: the report's design and resource fields."""
    from amaranth.back import rtlil

    from . import report as rep
    from .flow import synthesize
    from .wrapper import PinWrapper

    p = top.params
    size = {"classes": p.rows, "features": top.features, "bins": top.bins}
    say(f"elaborating the classifier top ({size['classes']} classes, {size['features']} features, "
        f"{size['bins']} bins) for {target.device}")
    cells = synthesize(rtlil.convert(PinWrapper(top, pin_width=pin_width), name="top"), target, out, say)
    res = rep.resources(target, cells)
    return {"target": target.name, "device": target.device, "top": "classifier", "machine": p.to_dict(),
            "integrator": p.integrator, "machine_summary": ", ".join(p.kind.brief(p)), "classifier": size,
            "pin_width": pin_width, "cells": cells, "resources": res,
            "lut4": rep.logic_cells(target, res), "utilization": rep.utilization(target, res)}


def _place(report: dict, target: Target, out: Path, say: Callable[[str], None], *, freq_mhz: float,
           seed: int, router: str) -> None:
    """nextpnr on the synthesized top: fmax, critical path and placed sites into ``report``."""
    from .flow import parse_nextpnr, place_and_route

    report.update(parse_nextpnr(place_and_route(target, out, freq_mhz, seed, say, router)))
    report["fmax_provisional"] = target.fmax_provisional
    report["measured"] = (f"Yosys {target.yosys_synth} and nextpnr ({router}) place and route of the "
                          "classifier top")


def markdown(report: dict) -> str:
    """The report as a table."""
    r, c, tp = report["resources"], report["classifier"], report.get("throughput") or {}
    fmax, dps = report.get("fmax_mhz"), tp.get("decisions_per_second")
    wall = tp.get("wall_cycles_per_decision")
    lines = [f"# bayesmachine synth --top classifier: {report['target']} ({report['device']})", "",
             f"Classifier top: {c['classes']} classes, {c['features']} features, {c['bins']} bins; "
             f"machine: {report['integrator']} integrator, {report['machine_summary']}; "
             f"wrapper {report['pin_width']}-bit pins.", "",
             "| LUT4 | FF | block RAM | LUT RAM | fmax (MHz) | wall cycles per decision | decisions/s |",
             "|---|---|---|---|---|---|---|",
             f"| {report['lut4']:,} | {r['ff']:,} | {r['bram']:,} | {r['lutram']:,} | "
             f"{'—' if fmax is None else f'{fmax:.2f}'} | "
             f"{'—' if wall is None else f'{wall:.2f}'} | "
             f"{'—' if dps is None else f'{dps:,.0f}'} |"]
    if tp:
        lines += ["", f"Throughput: {tp['decisions']} held-out decisions of {tp['dataset']} under pysim, "
                  "every one the model's; decisions/s = fmax / wall cycles per decision."]
    cp = report.get("critical_path") or {}
    if cp:
        lines += ["", f"Critical path: {cp['start']} -> {cp['end']}: {cp['delay_ns']:.2f} ns ({cp['levels']} "
                  "logic steps)."]
    lines += ["", f"Figures from: {report['measured']}.", ""]
    return "\n".join(lines)
