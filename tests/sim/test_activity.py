"""Switching activity (bayesmachine.sim.activity): the registers of a design's Verilog, Verilator's
toggle counts read back, their sum by block; and the StereoMachine's activity build under Verilator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import own_options

from bayesmachine.sim.activity import Activity, activity, block_of, read_toggles, register_names

# As Yosys writes Amaranth's designs: escaped module and signal names, a memory and its read register.
VERILOG = r"""
module bayesmachine(clk, rst, a);
  reg [3:0] count_0 = 4'h0;
  reg \over$3  = 1'h0;
  wire [3:0] \$5 ;
  always @(posedge clk)
    count_0 <= \$5 ;
  always @(posedge clk)
    \over$3  <= 1'h1;
endmodule

module \bayesmachine.machine (clk, x);
  reg [7:0] mem [3:0];
  reg [7:0] _0_;
  reg [5:0] word_1_2 = 6'h00;
  reg bit_1_2 = 1'h0;
  reg \beats__payload  = 1'h0;
  always @(posedge clk)
    if (x) mem[a] <= 8'h01;
  always @(posedge clk)
    _0_ <= mem[a];
  always @(posedge clk) begin
    word_1_2 <= 6'h3f;
    bit_1_2 <= x;
  end
  always @(posedge clk)
    \beats__payload  <= x;
  assign y = word_1_2 <= 6'h01;
endmodule
"""


def _point(module: str, signal: str, count: int) -> str:
    fields = {"f": "bayesmachine.v", "l": "10", "t": "toggle", "page": f"v_toggle/{module}", "o": signal,
              "h": "TOP.bayesmachine_harness_top.dut"}
    return "C '" + "".join(f"\x01{k}\x02{v}" for k, v in fields.items()) + f"' {count}\n"


def _coverage(tmp_path: Path) -> Path:
    top, machine = "bayesmachine", "bayesmachine.machine"
    points = [
        (top, "count_0[0]:0->1", 5), (top, "count_0[0]:1->0", 4), (top, "count_0[3]:0->1", 1),
        (top, "over__0243:0->1", 2),  # \over$3 as Verilator mangles it
        (top, "__0245[1]:0->1", 100),  # a wire: left out
        (machine, "word_1_2[5]:0->1", 7), (machine, "bit_1_2:0->1", 3), (machine, "bit_1_2:1->0", 3),
        (machine, "_0_[2]:1->0", 6), (machine, "beats___05Fpayload:0->1", 1),
    ]
    path = tmp_path / "coverage.dat"
    path.write_text("# SystemC::Coverage-3\n" + "".join(_point(*p) for p in points))
    return path


def test_registers_are_the_clocked_left_hand_sides_without_memories() -> None:
    regs = register_names(VERILOG)
    assert regs == {"bayesmachine": {"count_0", "over$3"},
                    "bayesmachine.machine": {"_0_", "word_1_2", "bit_1_2", "beats__payload"}}


def test_toggles_read_back_by_signal_unmangled(tmp_path: Path) -> None:
    read = read_toggles(_coverage(tmp_path))
    counts = {(m.removeprefix("bayesmachine"), s): n for (m, s), n in read.items()}
    assert counts[("", "count_0")] == 10 and counts[("", "over$3")] == 2 and counts[("", "$5")] == 100
    assert counts[(".machine", "bit_1_2")] == 6 and counts[(".machine", "beats__payload")] == 1


def test_activity_sums_registers_by_block(tmp_path: Path) -> None:
    act = activity(_coverage(tmp_path), VERILOG, pixels=2, blocks=("counters", "front end"))
    # Named as the machine's registers in any module: count_0 a counter, over$3 the encoder's.
    assert act.toggles == {"counters": 10, "front end": 0, "encoder": 2, "control": 6 + 1,
                           "likelihood memory": 7, "operators": 6}
    assert act.wire_toggles == 100  # the wire $5
    assert act.total == 32 and act.per_pixel()["total"] == 16.0 and act.per_pixel()["operators"] == 3.0
    with pytest.raises(ValueError, match="pixels must be > 0"):
        activity(_coverage(tmp_path), VERILOG, pixels=0)


def test_blocks_of_the_machines_names() -> None:
    m = "bayesmachine.machine"
    assert block_of(m, "count_12") == "counters" and block_of(m, "bit_3_4") == "operators"
    assert block_of(m, "word_0_1") == "likelihood memory" and block_of(m, "shadow_2_0") == "likelihood memory"
    assert block_of(m, "next_number_rep0_5_0") == "sources" and block_of(m, "over_group_1") == "encoder"
    assert block_of("bayesmachine.machine.source", "state") == "sources"
    # A shared source's copies (hdl/machine/top.py), and the log machine's row sums at its issue point.
    assert block_of("bayesmachine.source_rep1", "direction_0") == "sources"
    assert block_of("bayesmachine.right.source_rep12", "index") == "sources"
    assert block_of("bayesmachine", "issue_sums") == "adders"
    assert block_of("bayesmachine.right", "issue_sums") == "adders"
    assert block_of("bayesmachine.frontend.pipeline.linebuffer", "column") == "front end"
    assert block_of("bayesmachine.fifo", "r_port__addr") == "front end"
    assert block_of("bayesmachine.right.machine", "count_0") == "counters"
    assert block_of(m, "running") == "control" and block_of("bayesmachine", "count_3") == "counters"
    assert block_of("bayesmachine", "code7") == "likelihood memory"
    assert block_of("bayesmachine.argmin", "stage0") == "argmin"
    assert isinstance(Activity(1).per_pixel(), dict)


@pytest.mark.eda
@pytest.mark.parametrize(("integrator", "feed", "blocks"), [
    ("stochastic", "pixels",
     ("operators", "counters", "sources", "likelihood memory", "front end", "encoder")),
    ("log", "words", ("adders", "argmin", "weights")),
    ("log", "pixels", ("front end", "adders", "argmin", "weights", "likelihood memory")),
])
def test_activity_builds_count_every_register(integrator, feed, blocks, tmp_path: Path) -> None:
    """A small census design built for activity (the StereoMachine fed pixels with either integrator,
    the log machine fed words): its results equal the model's, the coverage files name every register
    of its Verilog, and its blocks' registers toggle."""
    from conftest import require_tool

    from bayesmachine.hdl.frontend.stereo import stereo_machine_params
    from bayesmachine.host.images import bundled_pair
    from bayesmachine.host.likelihoods import ModelParams
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.sim.activity import directory_activity

    require_tool("verilator")
    left, right, _ = bundled_pair()
    model = ModelParams(name="census", dmax=3)
    machine = stereo_machine_params(3, model=model, integrator=integrator,
                                    **own_options(integrator, counter_max=4))
    crop = (slice(200, 211), slice(300, 324))
    prep = prepare(left[crop], right[crop], model, None, reference=False)
    run = run_machine(prep, machine, engine="verilator", feed=feed,
                      engine_options={"activity": tmp_path / "act", "verbose": False})
    want = run_machine(prep, machine, engine="model")
    np.testing.assert_array_equal(run.counts, want.counts)
    np.testing.assert_array_equal(run.cycles, want.cycles)
    (dat,) = sorted((tmp_path / "act").glob("*.dat"))
    counts = read_toggles(dat)
    regs = register_names(dat.with_suffix(".v").read_text())
    missing = [(m, r) for m, names in regs.items() for r in names if (m, r) not in counts]
    assert not missing, missing[:10]
    act = directory_activity(tmp_path / "act", run.map.size)
    for block in blocks:
        assert act.toggles.get(block, 0) > 0, (block, act.toggles)
