# amaranth: UnusedElaboratable=no
"""The whole machine RTL (in Amaranth's simulator) against the NumPy machine model, bit for bit.

Counters, MAP, flags and cycle counts must be identical, whatever the load/result stream
timing (random valid/ready stalls), the split of pixels into calls, and the machine variant.
"""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Module, Shape, Signal
from conftest import assert_same_results, run_sim, small_params

from bayesmachine.hdl.machine import (
    BayesianMachine,
    hides_bubble,
    load_layout,
    pixel_wall_cycles,
    result_layout,
)
from bayesmachine.hdl.machine.counters import overflow_counter, overflow_counter_twin
from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.pysim import PysimEngine
from bayesmachine.sim.synthetic import synthetic_disparity_words


def _mixed_words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    """Random words with many exact 0 and 2^W words, plus all-zero (timeout) and all-one (tie) pixels."""
    rng = np.random.default_rng(seed)
    one = params.word_one
    shape = (pixels, params.rows, params.operator_columns)
    words = rng.integers(0, one + 1, size=shape)
    pick = rng.random(shape)
    words[pick < 0.15] = 0
    words[pick > 0.75] = one
    words[1] = 0  # nothing ever fires: watchdog timeout
    words[2] = one  # every row fires every cycle: all overflow together (a tie of all rows)
    words[3] = 0
    words[3, -1] = one  # only the last row (no-match row if any) fires
    return words.astype(np.int32)


def test_overflow_counter_matches_twin() -> None:
    n_max = 5
    m = Module()
    row, count, over = Signal(), Signal(3), Signal()
    ov, nxt = overflow_counter(row, count, n_max)
    m.d.comb += over.eq(ov)
    m.d.sync += count.eq(nxt)
    rnd = np.random.default_rng(0)
    rows = (rnd.random(300) < 0.4).astype(int).tolist()

    async def bench(ctx):
        c = 0
        for r in rows:
            ctx.set(row, r)
            want_over, want_next = overflow_counter_twin(r, c, n_max)
            assert (ctx.get(count), ctx.get(over)) == (c, want_over)
            await ctx.tick()
            c = want_next
            assert c <= n_max

    run_sim(m, bench)


def _check(params: MachineParams, words: np.ndarray, *, chunks: int = 1, **engine_opts: float) -> PysimEngine:
    engine = PysimEngine(params, **engine_opts)
    model = MachineModel(params)
    for part in np.array_split(words, chunks):
        assert_same_results(engine.run(part), model.run(part))
    return engine


@pytest.mark.parametrize("tie_break", ["nomatch-first", "lowest-index"])
def test_small_machine_matches_model_with_stalls(tie_break: str) -> None:
    params = small_params(tie_break=tie_break)
    words = _mixed_words(params, 40, seed=1)
    _check(params, words, load_stall=0.3, result_stall=0.3, stall_seed=2)


def test_tie_of_all_rows_follows_the_tie_rule() -> None:
    for tie_break, winner in (("nomatch-first", 4), ("lowest-index", 0)):
        params = small_params(tie_break=tie_break)
        words = np.full((2, params.rows, params.operator_columns), params.word_one, np.int32)
        res = PysimEngine(params).run(words)
        assert res.map.tolist() == [winner] * 2
        assert res.cycles.tolist() == [params.counter_max + 1] * 2
        assert res.nomatch.tolist() == [winner == params.rows - 1] * 2
        assert (res.counts == params.counter_max).all()


def test_timeout_pixels() -> None:
    params = small_params(max_cycles=25)
    words = np.zeros((3, params.rows, params.operator_columns), np.int32)
    words[1, 0, :] = 1  # p = 1/16 on row 0 only: rarely 4 ones in 25 cycles
    res = PysimEngine(params).run(words)
    assert_same_results(res, MachineModel(params).run(words))
    assert res.timeout[0] and res.timeout[2] and res.cycles[0] == 25 and res.map[0] == 0
    assert not (res.nomatch & res.timeout).any()


@pytest.mark.parametrize(
    "variant",
    [
        dict(prior="loaded"),
        dict(words_per_beat=1),
        dict(words_per_beat=10),  # exactly one beat per pixel
        dict(words_per_beat=4),  # the last beat has unused lanes
        dict(nomatch_row=False),
        dict(rows=2, columns=1, words_per_beat=1),
        dict(rows=1, columns=3, nomatch_row=False, words_per_beat=2),
        dict(counter_max=1, max_cycles=8),
        dict(word_bits=1, lfsr_bits=5, counter_max=2),
        dict(columns=4, words_per_beat=7, seed=12345),
        dict(rng="lfsr-shared"),
        dict(rng="lfsr-shared", prior="loaded", tie_break="lowest-index"),
        dict(rng="sobol"),
        dict(rng="sobol", prior="loaded", words_per_beat=4),
        # 2-bit words: Sobol blocks of 4 cycles, so runs span several blocks and shifts.
        dict(rng="sobol", word_bits=2, lfsr_bits=7, counter_max=5, max_cycles=50),
    ],
    ids=lambda v: ",".join(f"{k}={x}" for k, x in v.items()),
)
def test_machine_variants_match_model(variant: dict[str, object]) -> None:
    params = small_params(**variant)
    words = _mixed_words(params, 25, seed=len(str(variant)))
    _check(params, words, load_stall=0.2, result_stall=0.2, stall_seed=7)


def test_external_rng_matches_model() -> None:
    params = small_params(rng="external", max_cycles=40)
    words = _mixed_words(params, 20, seed=4)
    rng = np.random.default_rng(9)
    engine, model = PysimEngine(params, load_stall=0.3, result_stall=0.4, stall_seed=3), MachineModel(params)
    for part in np.array_split(words, 2):
        numbers = rng.integers(0, 1 << params.word_bits, size=(40 * len(part), params.operators))
        assert_same_results(engine.run(part, numbers), model.run(part, numbers))


def test_external_rng_runs_out() -> None:
    params = small_params(rng="external")
    words = np.zeros((1, params.rows, params.operator_columns), np.int32)
    engine = PysimEngine(params)
    with pytest.raises(ValueError, match="ran out"):
        engine.run(words, np.zeros((10, params.operators), np.int32))
    # The cut-short pixel is still in the machine: the engine refuses to go on until a reset...
    good = _mixed_words(params, 5, seed=9)
    nums = np.random.default_rng(3).integers(0, 1 << params.word_bits, (5000, params.operators))
    with pytest.raises(RuntimeError, match="reset"):
        engine.run(good, nums)
    # ...after which it matches the model again.
    engine.reset()
    assert engine.run(good, nums).equal(MachineModel(params).run(good, numbers=nums))


def test_state_carries_over_between_calls() -> None:
    params = small_params()
    words = _mixed_words(params, 30, seed=5)
    engine = PysimEngine(params)
    parts = [engine.run(words[:7]), engine.run(words[7:8]), engine.run(words[8:])]
    whole = MachineModel(params).run(words)
    for field in ("counts", "map", "cycles", "timeout", "nomatch"):
        assert np.array_equal(np.concatenate([getattr(p, field) for p in parts]), getattr(whole, field))


@pytest.mark.parametrize("rng", ["lfsr", "sobol"])
def test_runs_are_back_to_back(rng: str) -> None:
    # Without stalls: the first pixel's beats_per_pixel load cycles, its swap, then each run's
    # compute cycles with no idle cycle between runs (each run lasts >= counter_max + 1 >= beats + 2
    # cycles, so the next pixel is always in the shadow memory in time; a beat is written the cycle
    # after its handshake), then the last run's bubble and the hand-over of its result. With an
    # LFSR source each run ends with its bubble (the registered stop, in which the next run is
    # swapped in); with ``sobol`` the next run's first compute cycle is its swap, so there is no
    # bubble between runs except after a run whose last cycle began a Sobol block (k - 1 a
    # nonzero multiple of 2^W = 8 here, which the run lengths below include).
    params = small_params(words_per_beat=3, counter_max=6, word_bits=3,
                          rng=rng)  # 10 words: 4 beats per pixel
    assert hides_bubble(params) == (rng == "sobol")
    words = _mixed_words(params, 40, seed=6)
    engine = _check(params, words)
    k = MachineModel(params).run(words).cycles.astype(np.int64)
    between = len(words) - 1 if rng == "lfsr" else int(((k[:-1] > 1) & ((k[:-1] - 1) % 8 == 0)).sum())
    if rng == "sobol":
        assert 0 < between < len(words) // 4  # some late runs, and most runs without a bubble
    assert engine.clock_cycles == params.beats_per_pixel + 1 + engine.compute_cycles + between + 3
    wall = int(pixel_wall_cycles(params, k)[:-1].sum())
    assert engine.clock_cycles == params.beats_per_pixel + 4 + wall + k[-1]


def test_heavy_result_backpressure() -> None:
    params = small_params()
    words = _mixed_words(params, 15, seed=8)
    engine = _check(params, words, result_stall=0.9, stall_seed=11)
    # Each result waits ~10 cycles for ready; the next run computes meanwhile, but its bubble
    # (the cycle that hands its result over) waits for the register to empty.
    assert engine.clock_cycles > engine.compute_cycles + 2 * len(words)


def test_ports_and_layouts() -> None:
    params = MachineParams.for_disparity(80)
    dut = BayesianMachine(params=params)
    assert Shape.cast(load_layout(params)).width == 16 * 11
    layout = result_layout(params)
    names = ["map", "nomatch", "timeout", "cycles", "counts"]
    assert [name for name, _ in layout] == names
    assert [layout[name].offset for name in names] == [0, 7, 8, 9, 29]
    assert Shape.cast(layout).width == 7 + 1 + 1 + 20 + 82 * 5
    assert not hasattr(dut, "entropy")
    ext = BayesianMachine(params=MachineParams.for_disparity(80, rng="external"))
    assert Shape.cast(ext.entropy.shape()).width == 246 * 10
    with pytest.raises(TypeError):
        BayesianMachine(params={"rows": 3})  # type: ignore[arg-type]


# --- The full-size machine of the paper: Dmax = 80 (82 rows), N = 3, n_max = 16 ---

@pytest.mark.pysim
def test_full_size_machine_matches_model() -> None:
    params = MachineParams.for_disparity(80)
    rng = np.random.default_rng(2017)
    words = synthetic_disparity_words(params, 6, rng, occluded=0.2)
    words[2, :, :] = params.word_one  # a tie of all 82 rows: the no-match row wins
    engine = _check(params, words, chunks=2, load_stall=0.3, result_stall=0.3, stall_seed=1)
    assert engine.compute_cycles > 6 * 17


@pytest.mark.pysim
@pytest.mark.parametrize("rng", ["lfsr-shared", "sobol"])
def test_full_size_shared_sources_match_model(rng: str) -> None:
    params = MachineParams.for_disparity(80, rng=rng)
    words = synthetic_disparity_words(params, 6, np.random.default_rng(2026), occluded=0.2)
    words[3, :, :] = params.word_one  # a tie of all 82 rows
    engine = _check(params, words, chunks=2, load_stall=0.3, result_stall=0.3, stall_seed=5)
    assert engine.compute_cycles > 6 * 17


@pytest.mark.pysim
def test_full_size_machine_timeout_and_lowest_index() -> None:
    params = MachineParams.for_disparity(80, max_cycles=120, tie_break="lowest-index", seed=99)
    rng = np.random.default_rng(80)
    words = synthetic_disparity_words(params, 4, rng)
    words[1] = 0  # timeout after 120 cycles
    words[3] = params.word_one  # all rows tie: lowest index wins
    engine = PysimEngine(params, load_stall=0.2, result_stall=0.2, stall_seed=4)
    res = engine.run(words)
    assert_same_results(res, MachineModel(params).run(words))
    # Expected from the rules alone: words of 0 never give a 1, so the watchdog stops the run at
    # max_cycles with every counter at 0 and map 0...
    assert (res.timeout[1], res.cycles[1], res.map[1], res.nomatch[1]) == (True, 120, 0, False)
    assert not res.counts[1].any()
    # ...and words of 1.0 give every row a 1 each cycle: all 82 overflow together in cycle n_max + 1,
    # and lowest-index picks row 0 over the no-match row.
    sure = params.counter_max + 1
    assert (res.timeout[3], res.cycles[3], res.map[3], res.nomatch[3]) == (False, sure, 0, False)
    assert (res.counts[3] == params.counter_max).all()
    assert len(engine.run(words[:0])) == 0  # an empty batch: nothing in, nothing out


@pytest.mark.slow
@pytest.mark.parametrize("tie_break", ["nomatch-first", "lowest-index"])
def test_full_size_machine_many_pixels(tie_break: str) -> None:
    params = MachineParams.for_disparity(80, tie_break=tie_break, seed=7)
    words = synthetic_disparity_words(params, 400, np.random.default_rng(60))
    _check(params, words, chunks=4, load_stall=0.1, result_stall=0.1, stall_seed=9)


def test_pysim_gives_up_with_a_clear_error_instead_of_hanging() -> None:
    """All-zero words never overflow; with a huge watchdog the engine stops on its patience."""
    params = MachineParams(rows=2, columns=1, counter_max=1, max_cycles=10_000_000, words_per_beat=2)
    engine = PysimEngine(params, patience=300)
    with pytest.raises(RuntimeError, match="no result for 300 clock cycles"):
        engine.run(np.zeros((1, 2, 1), np.uint16))
