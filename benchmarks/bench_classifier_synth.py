"""The classifier top (``emit --top classifier``) through Yosys and nextpnr on the ECP5-85F: LUT4, FF,
block RAM, fmax, and decisions per second from its wall cycles per decision under pysim.

The library function of ``bayesmachine synth --top classifier`` (``fpga.classifier_synth``), with the
number of held-out decisions measured as an option: the top behind the pin-saving wrapper, its wall
cycles per decision from ``host.classification.top_cycles`` (fold 0 of a stratified 5-fold split,
split seed 0: its tables loaded, then ``--decisions`` observations back to back, from the first
observation taken to the last result, every decision the model's). Decisions per second = fmax /
wall cycles per decision.

    python benchmarks/bench_classifier_synth.py --dataset digits --integrator stochastic -o build/clf
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bayesmachine.argtypes import choice_of, int_in_range, output_path
from bayesmachine.classify import DEFAULT_BINS, MAX_BINS
from bayesmachine.cli import Parser, run_script
from bayesmachine.host.classification import BUNDLED_DATASETS, held_out, top_cycles
from bayesmachine.params import INTEGRATORS


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", type=choice_of(BUNDLED_DATASETS), default="digits")
    ap.add_argument("--integrator", type=choice_of(INTEGRATORS), default="stochastic")
    ap.add_argument("--bins", type=int_in_range(1, MAX_BINS), default=DEFAULT_BINS)
    ap.add_argument("--decisions", type=int_in_range(2, 10_000), default=20)
    ap.add_argument("--freq", type=int_in_range(1, 500), default=50,
                    help="nextpnr's target, MHz (default 50)")
    ap.add_argument("--seed", type=int_in_range(0, 2**31 - 1), default=1, help="nextpnr's seed (default 1)")
    ap.add_argument("--no-pnr", action="store_true", help="synthesis only")
    ap.add_argument("-o", "--output", type=output_path, default="build/classifier-synth",
                    help="the tools' directory (default build/classifier-synth)")
    args = ap.parse_args(argv)

    from bayesmachine.fpga.classifier_synth import synth_classifier

    held = held_out(args.dataset, bins=args.bins, machine={"integrator": args.integrator},
                    decisions=args.decisions)
    report = synth_classifier(held.machine.params, held.machine.tables.features, held.bins, "ecp5-85k",
                              Path(args.output), freq_mhz=args.freq, pnr_seed=args.seed,
                              place=not args.no_pnr, measure=lambda: top_cycles(held), progress=False)
    res, tp = report["resources"], report["throughput"]
    figures = {"dataset": args.dataset, "integrator": args.integrator, **report["classifier"],
               "lut4": report["lut4"], "ff": res["ff"], "bram": res["bram"], "lutram": res["lutram"],
               "fmax_mhz": report["fmax_mhz"], "wall_cycles_per_decision": tp["wall_cycles_per_decision"],
               "decisions_per_second": tp["decisions_per_second"]}
    print(json.dumps(figures, indent=2))


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
