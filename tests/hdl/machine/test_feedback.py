# amaranth: UnusedElaboratable=no
"""The neighbour prior's feedback column as a component (``hdl.machine.feedback.FeedbackPrior``), held
cycle by cycle to its twin, the model's per-pixel rule (``sim.model.feedback_result`` then
``sim.model.fill_feedback``); the whole machine with it is held to the model in
``tests/columns/test_prior.py``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import run_sim, small_params

from bayesmachine.hdl.machine import FeedbackPrior
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import feedback_result, fill_feedback

NEIGHBOUR = dict(prior="neighbour", feedback_words=(16, 10, 7, 4), feedback_nomatch_word=6)
VARIANT_IDS = {
    "nomatch": small_params(**NEIGHBOUR),
    "no-nomatch-row": small_params(nomatch_row=False, **{**NEIGHBOUR, "feedback_nomatch_word": None}),
    # 14 rows of 5 operator columns: 7 groups of rows, each with its copy of the previous result.
    "groups": small_params(rows=14, columns=3, **NEIGHBOUR),
    "leading": small_params(timeout_answer="leading", max_cycles=30, **NEIGHBOUR),
}


def _twin_words(params: MachineParams, prev: int, line_start: bool) -> list[int]:
    words = np.zeros(params.rows, np.int64)
    nm_row = params.rows - 1 if params.nomatch_row else -1
    fill_feedback(words, prev, line_start, np.array(params.feedback_words, np.int64),
                  int(params.feedback_nomatch_word or 0), params.rows, 1, nm_row, params.word_one)
    return words.tolist()


@pytest.mark.parametrize("params", list(VARIANT_IDS.values()), ids=list(VARIANT_IDS))
def test_feedback_words_follow_the_previous_result(params: MachineParams) -> None:
    """After each hand-over (``leave``), ``settle`` the next cycle and from the cycle after the
    twin's column for that result (a hypothesis, or flat), or flat on a line start; held until the
    next hand-over. Before any, after reset: flat."""
    dut = FeedbackPrior(params=params)
    rng = np.random.default_rng(params.rows)
    nm_row = params.rows - 1 if params.nomatch_row else -1
    results = [(int(rng.integers(params.rows)), bool(rng.random() < 0.8), bool(rng.random() < 0.2),
                int(rng.integers(0, 3))) for _ in range(120)]
    assert len({r[0] for r in results}) == params.rows  # every row is a previous MAP

    async def bench(ctx):
        def check(prev: int, what: str) -> None:
            for start in (False, True):
                ctx.set(dut.line_start, start)
                got = [ctx.get(w) for w in dut.words]
                assert got == _twin_words(params, prev, start), f"{what}, line start {start}"

        check(-1, "after reset")
        prev = -1
        for i, (row, valid, timed_out, gap) in enumerate(results):
            ctx.set(dut.map, row)
            ctx.set(dut.valid, valid)
            ctx.set(dut.timed_out, timed_out)
            ctx.set(dut.leave, 1)
            await ctx.tick()
            ctx.set(dut.leave, 0)
            ctx.set(dut.map, int(rng.integers(params.rows)))  # the inputs matter at the hand-over only
            ctx.set(dut.valid, 1)
            assert ctx.get(dut.settle) == 1, f"result {i}: settle the cycle after the hand-over"
            await ctx.tick()
            assert ctx.get(dut.settle) == 0
            prev = feedback_result(row if valid else -1, timed_out, nm_row)
            for k in range(gap + 1):
                check(prev, f"result {i} (row {row}, valid {valid}, timed out {timed_out}), cycle {k}")
                await ctx.tick()

    run_sim(dut, bench)


def test_feedback_prior_checks_its_arguments() -> None:
    with pytest.raises(TypeError, match="MachineParams"):
        FeedbackPrior(params={"prior": "neighbour"})  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="neighbour prior") as err:
        FeedbackPrior(params=small_params(prior="loaded"))
    assert err.value.parameter == "prior"
    with pytest.raises(TypeError):
        FeedbackPrior(small_params(**NEIGHBOUR))  # type: ignore[misc]  # keyword-only
    dut = FeedbackPrior(params=small_params(**NEIGHBOUR))
    with pytest.raises(AttributeError):
        dut.params = small_params(**NEIGHBOUR)  # type: ignore[misc]  # read-only
    assert len(dut.previous_rows) == len(dut.previous_valid) == 2  # 5 rows, 3 per group
    assert len(dut.registered_words) == dut.params.rows
    wider = dataclasses.replace(dut.params, rows=14, columns=3)
    assert len(FeedbackPrior(params=wider).previous_rows) == 7
