# amaranth: UnusedElaboratable=no
"""The log integrator's blocks under pysim against the rule (``bayesmachine.sim.log_model``): random
pixels and edge cases (ties everywhere, every row excluded, one row, census-lr's 82 rows), the
latency at one pixel per clock, and random back-pressure on both streams."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest
from amaranth.lib import wiring
from conftest import run_sim

from bayesmachine.columns.energy import exp_table
from bayesmachine.errors import ParameterError
from bayesmachine.hdl.log import (
    ArgminTree,
    LogIntegrator,
    LogParams,
    RowAdders,
    WeightStage,
)
from bayesmachine.sim.log_model import argmin_rows, log_integrate, row_sums, row_weights

TABLE = tuple(int(x) for x in exp_table(4, 0.5))  # (16, 10, 6, 4, 2, 1, 1, 0)


@dataclass
class Run:
    """A stream run: the outputs taken in order, the clocks each input and output was taken at, and
    what ``watch`` read each clock."""

    outputs: list
    taken_in: list[int]
    taken_out: list[int]
    watched: list = field(default_factory=list)


def drive(dut: wiring.Component, sink: str, source: str, payloads: list, *, p_valid: float = 1.0,
          p_ready: float = 1.0, seed: int = 0, watch: Callable[[object], object] | None = None) -> Run:
    """Offer ``payloads`` in order (valid with probability ``p_valid`` each clock, held until taken)
    and take the outputs (ready with probability ``p_ready``); checks the output stream's rule: a
    result offered and not taken is offered again unchanged. ``watch(ctx)`` each clock, before it ends."""
    rng = np.random.default_rng(seed)
    run = Run([], [], [])
    port_in, port_out = getattr(dut, sink), getattr(dut, source)

    async def bench(ctx: object) -> None:
        clock, held = 0, None
        while len(run.outputs) < len(payloads):
            assert clock < 20 * len(payloads) + 50, "the pipeline stopped"
            i = len(run.taken_in)
            offer = i < len(payloads) and (held is not None and held[0] == "in" or rng.random() < p_valid)
            ctx.set(port_in.valid, offer)
            if i < len(payloads):
                ctx.set(port_in.payload, payloads[i])
            ready = bool(rng.random() < p_ready)
            ctx.set(port_out.ready, ready)
            valid, payload = ctx.get(port_out.valid), ctx.get(port_out.payload)
            if held is not None and held[0] == "out":
                assert valid and payload == held[1], f"clock {clock}: a held result changed"
            held = None
            if offer and ctx.get(port_in.ready):
                run.taken_in.append(clock)
            elif offer:
                held = ("in", None)
            if valid and ready:
                run.outputs.append(payload)
                run.taken_out.append(clock)
            elif valid:
                held = ("out", payload)
            if watch is not None:
                run.watched.append(watch(ctx))
            await ctx.tick()
            clock += 1

    run_sim(dut, bench)
    return run


def codes_of(p: LogParams, pixels: int, seed: int, high: int = 4) -> np.ndarray:
    """Random codes below ``high`` (ties are frequent), some infinite, and the edge cases first: a
    pixel with every row excluded, one with every code equal, one with only the last row finite."""
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, min(high, p.infinite), size=(pixels, p.rows, p.codes))
    codes[rng.random(codes.shape) < 0.1] = p.infinite
    codes[0] = p.infinite
    codes[1] = 1
    codes[2, :-1, 0] = p.infinite
    return codes


def integrator_results(run: Run, p: LogParams) -> list[tuple]:
    return [(o.map, o.nomatch, o.all_excluded, o.s_min, [o.weights[r] for r in range(p.rows)])
            for o in run.outputs]


def expected(codes: np.ndarray, p: LogParams) -> list[tuple]:
    res = log_integrate(codes, p)
    return [(int(res.map[i]), int(res.nomatch[i]), int(res.all_excluded[i]), int(res.s_min[i]),
             res.weights[i].tolist()) for i in range(len(codes))]


INTEGRATORS = [
    # (rows, codes, code_bits, nomatch_row, tie_break, levels_per_stage, adder_levels_per_stage)
    (7, 3, 3, True, "nomatch-first", 1, 1),
    (7, 3, 3, True, "lowest-index", 2, 2),
    (5, 2, 2, False, "nomatch-first", 3, 1),
    (1, 1, 2, False, "lowest-index", 1, 1),
    (2, 5, 3, True, "nomatch-first", 1, 2),
    (82, 4, 6, True, "nomatch-first", 2, 1),  # census-lr: Dmax 80
]


@pytest.mark.parametrize("case", INTEGRATORS, ids=lambda c: "-".join(map(str, c)))
def test_integrator_equals_the_rule(case: tuple) -> None:
    rows, codes, code_bits, nomatch_row, tie_break, levels, adder_levels = case
    p = LogParams(rows=rows, codes=codes, code_bits=code_bits, weights=TABLE, nomatch_row=nomatch_row,
                  tie_break=tie_break)
    dut = LogIntegrator(params=p, levels_per_stage=levels, adder_levels_per_stage=adder_levels)
    pix = codes_of(p, 40 if rows > 10 else 120, seed=rows + codes)
    run = drive(dut, "codes", "result", [c.tolist() for c in pix], p_valid=0.8, p_ready=0.6, seed=rows)
    assert integrator_results(run, p) == expected(pix, p)


@pytest.mark.parametrize("codes", [5, 8])
def test_integrator_census_lr_rows(codes: int) -> None:
    """82 rows (Dmax 80 and the no-match row), N = 5 and 8 codes of 7 and 8 bits, the default table
    of 1/16-nat steps: large sums and every weight of the table in use."""
    p = LogParams(rows=82, codes=codes, code_bits=codes, weights=exp_table(8, 1 / 16))
    dut = LogIntegrator(params=p, levels_per_stage=3, adder_levels_per_stage=2)
    pix = codes_of(p, 24, seed=codes, high=p.infinite)
    run = drive(dut, "codes", "result", [c.tolist() for c in pix], p_valid=0.9, p_ready=0.7, seed=codes)
    assert integrator_results(run, p) == expected(pix, p)


@pytest.mark.parametrize(("rows", "codes", "levels", "adder_levels", "latency"),
                         [(82, 4, 1, 1, 13), (82, 4, 2, 2, 9), (82, 7, 3, 1, 10), (82, 8, 7, 3, 6),
                          (1, 1, 1, 1, 6)])
def test_latency_at_one_pixel_per_clock(rows: int, codes: int, levels: int, adder_levels: int,
                                        latency: int) -> None:
    """The adders', the issue register's 1, the tree's and the weights' 3; one pixel per clock."""
    p = LogParams(rows=rows, codes=codes, code_bits=3, weights=TABLE, nomatch_row=rows > 1)
    dut = LogIntegrator(params=p, levels_per_stage=levels, adder_levels_per_stage=adder_levels)
    assert dut.latency == latency and dut.loop == 1 and not dut.feedback
    pix = codes_of(p, 12, seed=1)
    run = drive(dut, "codes", "result", [c.tolist() for c in pix])
    assert run.taken_in == list(range(12))
    assert run.taken_out == [t + latency for t in range(12)]
    assert integrator_results(run, p) == expected(pix, p)


def feedback_expected(codes: np.ndarray, starts: np.ndarray, p: LogParams, words: tuple,
                      nomatch_word: int | None) -> list[tuple]:
    """The rule pixel by pixel in order, each pixel's feedback column (column 0) formed from the
    previous result: the code at |r - MAP| clamped, ``nomatch_word`` in the no-match row; 0 at a line
    start, after a no-match or all-excluded result and from reset."""
    out, prev = [], -1
    for pixel, start in zip(codes, starts, strict=True):
        full = np.zeros((1, p.rows, p.codes), np.int64)
        full[0, :, 1:] = pixel
        if not start and prev >= 0:
            full[0, :, 0] = [words[min(abs(r - prev), len(words) - 1)] for r in range(p.rows)]
            if p.nomatch_row:
                full[0, -1, 0] = nomatch_word
        want = expected(full, p)[0]
        out.append(want)
        prev = -1 if want[1] or want[2] else want[0]
    return out


FEEDBACK = [
    # (rows, loaded codes, code_bits, nomatch_row, tie_break, levels_per_stage, adder_levels_per_stage)
    (7, 2, 3, True, "nomatch-first", 1, 1),
    (7, 2, 3, True, "lowest-index", 4, 1),
    (5, 1, 3, False, "nomatch-first", 2, 1),
    (12, 3, 4, True, "nomatch-first", 4, 1),  # census at Dmax 10: the machine's setting, a 2-clock loop
    (18, 2, 4, True, "lowest-index", 2, 2),  # rows past two feedback groups
]


@pytest.mark.parametrize("case", FEEDBACK, ids=lambda c: "-".join(map(str, c)))
def test_integrator_feedback_equals_the_rule(case: tuple) -> None:
    """With a feedback column: each pixel's result is the rule's with the codes formed from the previous
    result (flat at a line start), in order under back-pressure; its line_start comes out with it."""
    rows, loaded, code_bits, nomatch_row, tie_break, levels, adder_levels = case
    p = LogParams(rows=rows, codes=loaded + 1, code_bits=code_bits, weights=TABLE, nomatch_row=nomatch_row,
                  tie_break=tie_break)
    words = (0, 1, 3, 5)  # low codes: the feedback column often moves the MAP
    nomatch_word = 2 if nomatch_row else None
    dut = LogIntegrator(params=p, feedback_words=words, feedback_nomatch_word=nomatch_word,
                        levels_per_stage=levels, adder_levels_per_stage=adder_levels)
    assert dut.feedback and dut.loop == max(1, -(-((rows - 1).bit_length() + 1) // levels))
    pix = codes_of(dataclasses.replace(p, codes=loaded), 90, seed=rows, high=6)
    starts = np.random.default_rng(rows).random(90) < 0.15
    payloads = [{"codes": c.tolist(), "line_start": int(s)} for c, s in zip(pix, starts, strict=True)]
    run = drive(dut, "codes", "result", payloads, p_valid=0.8, p_ready=0.6, seed=rows,
                watch=lambda ctx: ctx.get(dut.line_start))
    want = feedback_expected(pix, starts, p, words, nomatch_word)
    assert integrator_results(run, p) == want
    assert [run.watched[t] for t in run.taken_out] == starts.astype(int).tolist()
    fed = [w for w, s in zip(want, starts, strict=True) if not s]
    assert len({w[0] for w in fed}) > 2  # the MAP moves


def test_integrator_feedback_issue_interval() -> None:
    """Without back-pressure pixels with a left neighbour issue every ``loop`` clocks, a line's first
    pixel as soon as its sums are ready."""
    p = LogParams(rows=12, codes=3, code_bits=4, weights=TABLE)
    dut = LogIntegrator(params=p, feedback_words=(0, 2, 4), feedback_nomatch_word=3)
    assert dut.loop == 2 and dut.latency == 1 + 1 + 2 + 3
    pix = codes_of(dataclasses.replace(p, codes=2), 20, seed=4)
    starts = np.zeros(20, bool)
    starts[[0, 11]] = True
    payloads = [{"codes": c.tolist(), "line_start": int(s)} for c, s in zip(pix, starts, strict=True)]
    run = drive(dut, "codes", "result", payloads)
    gaps = np.diff(run.taken_out)
    assert (gaps[np.flatnonzero(~starts[1:])] == dut.loop).all() and gaps[10] == 1
    assert integrator_results(run, p) == feedback_expected(pix, starts, p, (0, 2, 4), 3)


@pytest.mark.parametrize(("codes", "levels"), [(1, 1), (2, 1), (5, 1), (5, 2), (8, 3), (7, 64)])
def test_row_adders(codes: int, levels: int) -> None:
    p = LogParams(rows=6, codes=codes, code_bits=3, weights=TABLE)
    dut = RowAdders(params=p, levels_per_stage=levels)
    assert dut.latency == max(1, -(-((codes - 1).bit_length()) // levels))
    pix = codes_of(p, 80, seed=codes, high=p.infinite)
    run = drive(dut, "codes", "sums", [c.tolist() for c in pix], p_valid=0.7, p_ready=0.5, seed=codes)
    sums, excluded = row_sums(pix, p)
    for i, o in enumerate(run.outputs):
        assert [o.sums[r] for r in range(p.rows)] == sums[i].tolist(), f"pixel {i}"
        assert [(o.excluded >> r) & 1 for r in range(p.rows)] == excluded[i].astype(int).tolist()


def test_row_adders_carry_bits() -> None:
    """``carried`` bits come out with their pixel's sums, unchanged, under back-pressure."""
    p = LogParams(rows=3, codes=5, code_bits=3, weights=TABLE)
    dut = RowAdders(params=p, levels_per_stage=1, carried=2)
    assert dut.latency == 3 and dut.carried == 2
    pix = codes_of(p, 60, seed=9, high=p.infinite)
    tags = np.random.default_rng(9).integers(0, 4, 60)
    payloads = [{"codes": c.tolist(), "carried": int(t)} for c, t in zip(pix, tags, strict=True)]
    run = drive(dut, "codes", "sums", payloads, p_valid=0.7, p_ready=0.5, seed=9)
    sums, _ = row_sums(pix, p)
    assert [o.carried for o in run.outputs] == tags.tolist()
    assert [[o.sums[r] for r in range(p.rows)] for o in run.outputs] == sums.tolist()


def sums_inputs(p: LogParams, pixels: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random sums from a narrow range (many ties, with the no-match row too), random exclusions."""
    rng = np.random.default_rng(seed)
    top = (1 << p.sum_bits) - 1
    base = rng.integers(0, top - 3, size=(pixels, 1))
    sums = np.clip(base + rng.integers(0, 4, size=(pixels, p.rows)), 0, top)
    excluded = rng.random((pixels, p.rows)) < 0.3
    excluded[0] = True
    sums[1] = sums[1, 0]
    excluded[1] = False
    return sums, excluded


def flags(bits: np.ndarray) -> int:
    return int(sum(int(b) << r for r, b in enumerate(bits)))


@pytest.mark.parametrize(("rows", "nomatch_row", "tie_break", "levels", "pass_sums"), [
    (1, False, "lowest-index", 1, False), (2, True, "nomatch-first", 1, True),
    (5, True, "nomatch-first", 2, False), (7, True, "lowest-index", 1, True),
    (7, False, "nomatch-first", 3, False), (82, True, "nomatch-first", 1, True),
    (82, True, "lowest-index", 7, False), (33, False, "lowest-index", 2, True),
])
def test_argmin_tree(rows: int, nomatch_row: bool, tie_break: str, levels: int, pass_sums: bool) -> None:
    p = LogParams(rows=rows, codes=2, code_bits=3, weights=TABLE, nomatch_row=nomatch_row,
                  tie_break=tie_break)
    dut = ArgminTree(params=p, levels_per_stage=levels, pass_sums=pass_sums)
    assert dut.latency == max(1, -(-((rows - 1).bit_length()) // levels))
    sums, excluded = sums_inputs(p, 100, seed=rows)
    payloads = [{"sums": s.tolist(), "excluded": flags(x)} for s, x in zip(sums, excluded, strict=True)]
    run = drive(dut, "sums", "best", payloads, p_valid=0.8, p_ready=0.5, seed=rows)
    want = argmin_rows(sums, excluded, p)
    for i, o in enumerate(run.outputs):
        assert (o.map, o.nomatch, o.all_excluded, o.s_min) == tuple(int(a[i]) for a in want), f"pixel {i}"
        if pass_sums:
            assert [o.sums[r] for r in range(rows)] == sums[i].tolist() and o.excluded == flags(excluded[i])


@pytest.mark.parametrize(("rows", "tie_break", "levels"), [(1, "lowest-index", 1), (7, "nomatch-first", 1),
                                                        (7, "lowest-index", 2), (82, "nomatch-first", 4)])
def test_argmin_tree_feedback(rows: int, tie_break: str, levels: int) -> None:
    """``feedback``: each row's feedback code added to its sum of the other codes (an infinite one
    excludes the row) in a level before the tree's: the rule's argmin of the totals, which it carries."""
    p = LogParams(rows=rows, codes=3, code_bits=3, weights=TABLE, nomatch_row=rows > 1, tie_break=tie_break)
    dut = ArgminTree(params=p, levels_per_stage=levels, pass_sums=True, feedback=True)
    assert dut.feedback and dut.latency == max(1, -(-((rows - 1).bit_length() + 1) // levels))
    rng = np.random.default_rng(rows)
    others = rng.integers(0, 2 * p.infinite + 1, (100, rows))  # the sum of two codes
    feedback = rng.integers(0, 4, (100, rows))
    feedback[rng.random(feedback.shape) < 0.1] = p.infinite
    excluded = rng.random((100, rows)) < 0.2
    payloads = [{"sums": s.tolist(), "excluded": flags(x), "feedback": f.tolist()}
                for s, x, f in zip(others, excluded, feedback, strict=True)]
    run = drive(dut, "sums", "best", payloads, p_valid=0.8, p_ready=0.5, seed=rows)
    totals, out = others + feedback, excluded | (feedback == p.infinite)
    want = argmin_rows(totals, out, p)
    assert np.any(feedback == p.infinite) and np.unique(want[0]).size > min(rows, 3) - 1
    for i, o in enumerate(run.outputs):
        assert (o.map, o.nomatch, o.all_excluded, o.s_min) == tuple(int(a[i]) for a in want), f"pixel {i}"
        assert [o.sums[r] for r in range(rows)] == totals[i].tolist() and o.excluded == flags(out[i])


def test_argmin_tree_latest() -> None:
    """``latest_copies``: every copy holds the map, nomatch and all_excluded of the last pixel to reach
    the output buffer (``arriving`` in that clock) from the clock after, taken or not (it runs ahead
    of a held output); every row excluded from reset."""
    p = LogParams(rows=7, codes=3, code_bits=3, weights=TABLE, nomatch_row=True)
    dut = ArgminTree(params=p, levels_per_stage=1, feedback=True, latest_copies=3)
    rng = np.random.default_rng(9)
    sums = rng.integers(0, 2 * p.infinite + 1, (80, p.rows))  # the sum of two codes
    excluded = rng.random(sums.shape) < 0.3
    feedback = rng.integers(0, 3, sums.shape)
    payloads = [{"sums": s.tolist(), "excluded": flags(x), "feedback": f.tolist()}
                for s, x, f in zip(sums, excluded, feedback, strict=True)]

    def watch(ctx: object) -> tuple:
        copies = [ctx.get(dut.latest[k]) for k in range(3)]
        head = ctx.get(dut.best.payload)
        return (ctx.get(dut.arriving), [(c.map, c.nomatch, c.all_excluded) for c in copies],
                ctx.get(dut.best.valid) and (head.map, head.nomatch, head.all_excluded))

    run = drive(dut, "sums", "best", payloads, p_valid=0.8, p_ready=0.4, seed=9, watch=watch)
    want = list(zip(*(a.astype(int).tolist() for a in argmin_rows(sums + feedback, excluded, p)[:3]),
                    strict=True))
    latest, arrived, ahead = (0, 0, 1), 0, 0
    for arriving, copies, head in run.watched:
        assert copies == [latest] * 3
        ahead += bool(head) and arrived > 0 and head != latest
        if arriving:
            latest, arrived = want[arrived], arrived + 1
    assert arrived == len(run.outputs) == 80 and ahead > 0
    assert dut.latest_copies == 3 and ArgminTree(params=p).latest_copies == 0


def test_weight_stage() -> None:
    p = LogParams(rows=9, codes=4, code_bits=3, weights=TABLE)
    dut = WeightStage(params=p)
    assert dut.latency == 3
    sums, excluded = sums_inputs(p, 100, seed=3)
    rng = np.random.default_rng(4)
    # s_min from the rows, or any value (above some sums: the clamp at 0) for a block on its own.
    s_min = np.where(rng.random(100) < 0.7, sums.min(axis=1), rng.integers(0, 1 << p.sum_bits, 100))
    payloads = [{"map": 3, "nomatch": 1, "all_excluded": 0, "s_min": int(m), "sums": s.tolist(),
                 "excluded": flags(x)} for s, x, m in zip(sums, excluded, s_min, strict=True)]
    run = drive(dut, "best", "result", payloads, p_valid=0.6, p_ready=0.6, seed=5)
    want = row_weights(sums, excluded, s_min, p)
    for i, o in enumerate(run.outputs):
        assert (o.map, o.nomatch, o.all_excluded, o.s_min) == (3, 1, 0, s_min[i])
        assert [o.weights[r] for r in range(p.rows)] == want[i].tolist(), f"pixel {i}"


def test_bad_block_parameters() -> None:
    p = LogParams(rows=5, codes=2, code_bits=3, weights=TABLE)
    with pytest.raises(ParameterError, match="levels_per_stage"):
        ArgminTree(params=p, levels_per_stage=0)
    with pytest.raises(TypeError, match="levels_per_stage"):
        LogIntegrator(params=p, levels_per_stage=1.5)
    with pytest.raises(ParameterError, match="adder_levels_per_stage"):
        LogIntegrator(params=p, adder_levels_per_stage=0)
    with pytest.raises(TypeError, match="feedback_words"):
        LogIntegrator(params=p, feedback_words=3)
    with pytest.raises(ParameterError, match=r"feedback_words\[1\]"):
        LogIntegrator(params=p, feedback_words=(0, 8), feedback_nomatch_word=1)
    with pytest.raises(ParameterError, match="feedback_nomatch_word"):
        LogIntegrator(params=p, feedback_words=(0, 1))
    with pytest.raises(ParameterError, match="feedback_nomatch_word"):
        LogIntegrator(params=p, feedback_nomatch_word=1)
    for other, match in ((dataclasses.replace(p, nomatch_row=False), "no-match row"),
                         (dataclasses.replace(p, codes=1), "codes >= 2")):
        with pytest.raises(ParameterError, match=match):
            LogIntegrator(params=other, feedback_words=(0,), feedback_nomatch_word=1)
    with pytest.raises(TypeError, match="pass_sums"):
        ArgminTree(params=p, pass_sums=1)
    with pytest.raises(TypeError, match="feedback"):
        ArgminTree(params=p, feedback=1)
    with pytest.raises(ParameterError, match="latest_copies"):
        ArgminTree(params=p, latest_copies=65)
    with pytest.raises(ParameterError, match="carried"):
        RowAdders(params=p, carried=-1)
    for block in (RowAdders, ArgminTree, WeightStage, LogIntegrator):
        with pytest.raises(TypeError, match="LogParams"):
            block(params=(5, 2, 3))
    assert not hasattr(RowAdders(params=p), "nets")  # its builder returns them (StallPipeline.build)
