"""Study: the fused column against one operator column per piece of evidence, per model.

For each model that has a fused column (``fuse_columns``: census, census-lr), runs the machine (model
engine, the model's machine at ``--counter-max``, ``sobol``, seed 1) on the bundled Motorcycle pair (or
``--crop`` of it) twice, fused and per column, and prints per run: the cycles per output pixel over
every pass (census-lr: the left pass's and the right pass's per their own pixels in brackets), bad-2
on matched pixels and with no match counted as an error, the operator columns per row of each pass's
machine (left / right) and the operator samples per output pixel (``operator_samples_per_pixel``:
every pass's operators x its clocks over its pixels, per output pixel). Prints figures; asserts nothing.

Run: python benchmarks/study_fused.py [--models census,census-lr] [--counter-max 16] [--crop X,Y,W,H]
(docs/models.md, "The fused column").
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import MAX_COUNTER_MAX, argument_type, int_in_range, model_list
from bayesmachine.host.images import bundled_pair, crop_image, parse_crop
from bayesmachine.host.metrics import evaluate
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine


def measure(left: Any, right: Any, gt: Any, model: ModelParams, counter_max: int) -> dict[str, Any]:
    """One run's figures (see the module's text)."""
    prep = prepare(left, right, model, gt)
    machine = disparity_machine(model, counter_max=counter_max)
    run = run_machine(prep, machine, "model", progress=False)
    rep = evaluate(prep, run, sgbm=False).to_report()
    passes = [(p.cycles.size, float(p.cycles.mean()), p.machine.operator_columns)
              for p in run.passes.values()]
    total = (float(run.cycles.sum()) + sum(n * c for n, c, _ in passes)) / run.cycles.size
    return {"cycles": total, "left": float(run.cycles.mean()), "passes": passes,
            "bad2": rep["machine_bad2"], "bad2_nm": rep["machine_bad2_nomatch_bad"],
            "columns": [machine.operator_columns, *(c for _, _, c in passes)],
            "samples": run.operator_samples_per_pixel}


def _row(label: str, r: dict[str, Any]) -> str:
    split = "".join(f" ({r['left']:.2f} + {c:.2f})" for _, c, _ in r["passes"])
    columns = " / ".join(str(c) for c in r["columns"])
    return (f"| {label} | {r['cycles']:.2f}{split} | {r['bad2']:.4f} / {r['bad2_nm']:.4f} | {columns} "
            f"| {r['samples']:,.0f} |")


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", type=model_list, default=["census", "census-lr"],
                    help="models with a fused column (default census,census-lr)")
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16,
                    help="the machines' counter max (default 16)")
    ap.add_argument("--crop", type=argument_type(parse_crop, "crop"), default=None,
                    help="X,Y,W,H of the bundled pair (default the whole pair)")
    args = ap.parse_args(argv)
    for name in args.models:
        if "fuse_columns" not in ModelParams(name=name).to_dict():
            ap.error(f"argument --models: the {name} model has no fused column")
    left, right, gt = (crop_image(a, args.crop) for a in bundled_pair())
    print(f"Motorcycle{'' if args.crop is None else f' crop {args.crop}'}, counter max {args.counter_max}, "
          "sobol, seed 1, the model engine")
    print("| model | cycles per pixel | bad-2 matched / no match = bad | operator columns per row "
          "(left / right) | operator samples per output pixel |")
    print("|---|---|---|---|---|")
    for name in args.models:
        for fused in (False, True):
            t0 = time.perf_counter()
            r = measure(left, right, gt, ModelParams(name=name, fuse_columns=fused), args.counter_max)
            label = f"{name} {'fused' if fused else 'per column'}"
            print(_row(label, r), flush=True)
            print(f"  ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
