"""Benchmark: per-pixel column normalization (``--normalize-columns``): how far each column is scaled,
and what the scaling costs in generic Yosys LUT4s and flip-flops.

1. On the bundled pair (model engine, counter max 16, ``--max-cycles 256``), for census and
   census-lr's left pass: per operator column, the fraction of pixels whose scale m (the column's
   largest word) is below 2^W, and the mean m / 2^W, read from the model's own scales during the run.
2. The census model's machine (``BayesianMachine``, Dmax ``--dmax``) with normalize off and on:
   generic Yosys ``synth -flatten; abc -lut 4`` LUT4s and flip-flops.

Prints figures; asserts nothing. Run: python benchmarks/bench_normalize.py [--dmax 80] [--no-synth]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from bench_leap_forward import yosys_stat

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import int_in_range
from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import MAX_DMAX
from bayesmachine.sim import model as machine_model


def scale_statistics(name: str) -> None:
    """Run the model with normalize on and record the scales of the model's own pass."""
    left, right, _ = bundled_pair()
    model = ModelParams(name=name)
    machine = disparity_machine(model, normalize=True, max_cycles=256)
    seen: list[np.ndarray] = []
    original = machine_model.column_scales

    def recording(params, q):  # noqa: ANN001, ANN202
        scales = original(params, q)
        if params == machine:  # the model's own pass (census-lr's right pass has its own machine)
            seen.append(scales)
        return scales

    machine_model.column_scales = recording
    try:
        run = run_machine(prepare(left, right, model, reference=False), machine, "model", progress=False)
    finally:
        machine_model.column_scales = original
    scales = np.concatenate(seen) / machine.word_one
    print(f"{name}: {scales.shape[0]} pixels, cycles/px {run.cycles.mean():.2f}; per operator column "
          f"(feedback column first): m < 2^W {np.round((scales < 1).mean(axis=0), 4).tolist()}, "
          f"mean m / 2^W {np.round(scales.mean(axis=0), 4).tolist()}")


def synth_cost(dmax: int) -> None:
    for normalize in (False, True):
        params = disparity_machine(ModelParams(name="census", dmax=dmax), normalize=normalize)
        luts, ffs = yosys_stat(BayesianMachine(params=params))
        print(f"census machine Dmax {dmax} ({params.rows} x {params.operator_columns}), normalize "
              f"{'on' if normalize else 'off'}: {luts} LUT4, {ffs} FF")


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--dmax", type=int_in_range(0, MAX_DMAX), default=80)
    ap.add_argument("--no-synth", action="store_true")
    ap.add_argument("--no-runs", action="store_true")
    args = ap.parse_args(argv)
    if not args.no_runs:
        for name in ("census", "census-lr"):
            scale_statistics(name)
    if not args.no_synth:
        synth_cost(args.dmax)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
