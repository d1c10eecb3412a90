"""The classifier top under Verilator (sim/classifier_verilator.py): its decisions are the model's, and
its switching activity per decision is counted by the StereoMachine's mechanism (sim/activity.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bayesmachine.sim.activity import block_of

# The machine's own datapath blocks whose toggles depend only on the words loaded, not on when: the
# top's machine counts what the machine fed the same words by the word engine counts.
SAME_AS_FED_WORDS = {"stochastic": ("likelihood memory", "operators", "counters"),
                     "log": ("likelihood memory",)}


def test_the_top_s_own_registers_have_blocks() -> None:
    assert block_of("bayesmachine", "sums") == "sums" and block_of("bayesmachine", "entries") == "sums"
    assert block_of("bayesmachine", "prior") == "tables" and block_of("bayesmachine", "_12_") == "tables"
    # Only the top module's: a machine's submodule's read registers stay control.
    assert block_of("bayesmachine.machine", "_0_") == "control"


@pytest.mark.eda
def test_activity_per_decision_of_both_integrators(tmp_path: Path) -> None:
    """12 held-out iris decisions through the top built for activity, each integrator: the model's
    decisions, every register block of the top toggling, a plausible total per decision that differs
    between the integrators, and the machine's datapath counted as the machine fed the same words."""
    from conftest import require_tool

    from bayesmachine.host.classification import check_top_run, held_out
    from bayesmachine.sim.activity import directory_activity
    from bayesmachine.sim.classifier_verilator import run_classifier_verilator
    from bayesmachine.sim.verilator.engine import VerilatorEngine

    require_tool("verilator")
    totals = {}
    for integrator, same in SAME_AS_FED_WORDS.items():
        held = held_out("iris", bins=4, machine={"integrator": integrator}, decisions=12)
        top_dir, words_dir = tmp_path / f"{integrator}-top", tmp_path / f"{integrator}-words"
        run = run_classifier_verilator(held.machine, held.observed, held.bins, activity=top_dir)
        check_top_run(held, run.result, "Verilator")
        act = directory_activity(top_dir, 12)
        for block in ("tables", "sums", "control", *same):
            assert act.toggles.get(block, 0) > 0, (integrator, block, act.toggles)
        # Plausible: tens to thousands of bit toggles a decision (a few dozen registers, 1 to 17 clocks).
        totals[integrator] = act.per_pixel()["total"]
        assert 10 < totals[integrator] < 10_000, totals
        engine = VerilatorEngine(held.machine.params, activity=words_dir, verbose=False)
        try:
            engine.run(held.machine.entries(held.observed).reshape(12, -1))
        finally:
            engine.close()
        fed = directory_activity(words_dir, 12)
        assert {b: act.toggles[b] for b in same} == {b: fed.toggles[b] for b in same}
    assert totals["stochastic"] != totals["log"]
