"""Study: what a camera rate costs a stochastic machine, in operator samples and LUT4 sites.

A machine's work is its operator samples: each clock each operator draws B samples, and a pixel is
done when a row's counter overflows (or its watchdog stops it). From the runs' own figures
(``bayesmachine run ... -o OUT``'s ``OUT/report.json``, any engine: the mean cycles per pixel of each
pass, B, the operators of each pass's machine) this prints the operator samples per output pixel and,
at the camera rate on the run's frame (its output pixels, ``--fps`` frames per second), the operator
samples the machines must draw per clock at each ``--clocks`` frequency. With ``--synth`` reports
(``bayesmachine synth ... -o OUT``'s ``OUT/report.json``) it prints the LUT4 sites that work takes at
each design's measured cost of an operator sample per clock (its LUT4 sites per operator, CCU2C
counted twice, divided by its B), and that against the design's device. The cycles are clocks: at
B > 1 a pixel's samples are its clocks x B, at most B - 1 more than it drew (use B = 1 runs).
Prints figures; asserts nothing.

Run: python benchmarks/study_camera_budget.py RUN.json [RUN.json ...] [--synth SYNTH.json ...]
     [--fps 60] [--clocks 25,50,150]
(docs/fpga.md, "What 60 VGA frames per second takes").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import float_in_range, input_path, value_list
from bayesmachine.fpga.targets import get_target
from bayesmachine.params import MachineParams
from bayesmachine.region import CAMERA_FPS


def _operators(machine: dict) -> int:
    """The operators of the machine a report's ``machine`` dict describes."""
    fields = {k: tuple(v) if isinstance(v, list) else v for k, v in machine.items()}
    return MachineParams(**fields).operators


def run_work(report: dict) -> dict[str, float]:
    """Operator samples per output pixel of one run: the left pass's, plus census-lr's right pass's
    scaled by its pixels per output pixel."""
    b = report.get("samples_per_clock") or 1
    left = report.get("left_pass_cycles_per_pixel_mean", report["cycles_per_pixel_mean"])
    right = report.get("right_pass_cycles_per_pixel_mean") if report.get("right_pass_machine") else 0.0
    if left is None or right is None:  # a board run asked for MAPs only (--board-fields map)
        raise ValueError("its cycles per pixel are null (a run without cycles, --board-fields map?): "
                         "give the report of a run that has them")
    if not report["pixels"]:
        raise ValueError("it has no output pixel")
    work = {"label": f"{report['model_name']}, B = {b}", "pixels": report["pixels"],
            "left": left * b * _operators(report["machine"]), "right": 0.0}
    if report.get("right_pass_machine"):
        share = report["right_pass_pixels"] / report["pixels"]
        work["right"] = right * b * share * _operators(report["right_pass_machine"])
    work["total"] = work["left"] + work["right"]
    return work


def synth_cost(report: dict) -> dict[str, float]:
    """A synthesized design's LUT4 sites per operator sample per clock, and its device's LUT4 sites."""
    b = report["machine"].get("samples_per_clock") or 1
    return {"label": f"{report['device']}: {report.get('top', 'machine')}, B = {b}",
            "per_sample": report["per_operator"]["lut4"] / b,
            "device_sites": get_target(report["target"]).luts}


def _load(path: str, read, kind: str) -> dict:  # noqa: ANN001
    """``read`` of the JSON at ``path``; a ValueError naming it if it is not such a report."""
    try:
        data = json.loads(Path(path).read_text())
    except ValueError as e:
        raise ValueError(f"{path}: not JSON ({e})") from None
    try:
        return read(data)
    except ValueError as e:  # a report of this kind that cannot give the figures: why
        raise ValueError(f"{path}: {e}") from None
    except (KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{path} is not a report.json of bayesmachine {kind} (no {e})") from None


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=input_path, help="report.json files of bayesmachine run")
    ap.add_argument("--synth", action="append", type=input_path, default=[],
                    help="a report.json of bayesmachine synth")
    ap.add_argument("--fps", type=float_in_range(0.001, 1e6), default=CAMERA_FPS,
                    help=f"frames per second (default {CAMERA_FPS})")
    ap.add_argument("--clocks", type=value_list(float_in_range(0.001, 1e5), "clock"), default="25,50,150",
                    help="clock frequencies in MHz, comma-separated (default 25,50,150)")
    args = ap.parse_args(argv)
    clocks = args.clocks
    works = [_load(p, run_work, "run") for p in args.runs]
    costs = [_load(p, synth_cost, "synth") for p in args.synth]
    mhz = " | ".join(f"{c:g} MHz" for c in clocks)
    print(f"| run | output px | operator samples / px (left + right) "
          f"| per clock at {args.fps:g} fps: {mhz} |")
    for w in works:  # operator samples per clock at each clock, computed once
        w["per_clock"] = [w["total"] * w["pixels"] * args.fps / (c * 1e6) for c in clocks]
        per_clock = " | ".join(f"{n:,.0f}" for n in w["per_clock"])
        print(f"| {w['label']} | {w['pixels']:,} | {w['total']:,.0f} ({w['left']:,.0f} + {w['right']:,.0f}) "
              f"| {per_clock} |")
    for c in costs:
        print(f"\nLUT4 sites at {c['per_sample']:.2f} per operator sample per clock ({c['label']}; "
              f"device {c['device_sites']:,.0f}):")
        for w in works:
            sites = [n * c["per_sample"] for n in w["per_clock"]]
            cells = " | ".join(f"{n:,.0f} ({n / c['device_sites']:.0%})" for n in sites)
            print(f"| {w['label']} | {cells} |")


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
