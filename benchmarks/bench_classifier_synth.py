"""The classifier top (``emit --top classifier``) through Yosys and nextpnr on the ECP5-85F: LUT4, FF,
block RAM, fmax, and decisions per second from its wall cycles per decision under pysim.

The top sits behind the pin-saving wrapper (``fpga.wrapper.PinWrapper``) as ``synth`` puts the machine.
The wall cycles per decision: ``sim/classifier_top.py`` on a held-out fold of the data set (its tables
loaded, then ``--decisions`` observations back to back), from the first observation taken to the last
result. Decisions per second = fmax / wall cycles per decision.

    python benchmarks/bench_classifier_synth.py --dataset digits --integrator stochastic -o build/clf
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bayesmachine.argtypes import choice_of, int_in_range, output_path
from bayesmachine.classify import DEFAULT_BINS, MAX_BINS
from bayesmachine.cli import Parser, run_script
from bayesmachine.host.classification import BUNDLED_DATASETS, load_dataset, split_folds
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

    from amaranth.back import rtlil

    from bayesmachine.classify.estimator import BayesianMachineClassifier
    from bayesmachine.fpga import report as rep
    from bayesmachine.fpga.flow import parse_nextpnr, place_and_route, synthesize
    from bayesmachine.fpga.targets import get_target
    from bayesmachine.fpga.wrapper import PinWrapper
    from bayesmachine.hdl.classifier import ClassifierTop
    from bayesmachine.sim.classifier_top import run_classifier_top

    data = load_dataset(args.dataset)
    train, test = split_folds(data.y, 5, None, 0)[0]
    est = BayesianMachineClassifier(integrator=args.integrator, bins=args.bins)
    est.fit(data.x[train], data.y[train])
    machine, bins = est.machine_, int(est.bins_.counts.max())
    observed = est.bins_.transform(data.x[test][: args.decisions])
    run = run_classifier_top(machine, observed, bins)
    want = machine.run(observed, "model")
    if not (run.result.map == want.map).all() or not (run.result.counts == want.readout).all():
        raise RuntimeError("the top under pysim differs from the model")
    per_decision = run.wall_cycles / len(observed)
    target = get_target("ecp5-85k")
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    top = ClassifierTop(params=machine.params, features=machine.tables.features, bins=bins)
    cells = synthesize(rtlil.convert(PinWrapper(top), name="top"), target, out, print)
    res = rep.resources(target, cells)
    figures = {"dataset": args.dataset, "integrator": args.integrator, "classes": machine.tables.classes,
               "features": machine.tables.features, "bins": bins, "lut4": rep.logic_cells(target, res),
               "ff": res["ff"], "bram": res["bram"], "lutram": res["lutram"],
               "wall_cycles_per_decision": per_decision}
    if not args.no_pnr:
        pnr = parse_nextpnr(place_and_route(target, out, args.freq, args.seed, print))
        figures["fmax_mhz"] = pnr["fmax_mhz"]
        figures["decisions_per_second"] = pnr["fmax_mhz"] * 1e6 / per_decision
    (out / "figures.json").write_text(json.dumps(figures, indent=2) + "\n")
    print(json.dumps(figures, indent=2))


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
