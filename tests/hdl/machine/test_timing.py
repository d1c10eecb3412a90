# amaranth: UnusedElaboratable=no
"""The control path's timing: counters' full flags against their twin, and the per-pixel clock
cycles the FPGA report uses (``pixel_wall_cycles``) against the RTL in the simulator."""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Module, Signal
from conftest import run_sim, small_params

from bayesmachine.hdl.machine import hides_bubble, pixel_wall_cycles, search_cycles
from bayesmachine.hdl.machine.counters import (
    overflow_counter_full,
    overflow_counter_full_twin,
    overflow_counter_twin,
)
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.pysim import PysimEngine


@pytest.mark.parametrize("n_max", [1, 2, 5])
def test_counter_with_full_flag_matches_twins(n_max: int) -> None:
    m = Module()
    row, count, full, over = Signal(), Signal(n_max.bit_length()), Signal(), Signal()
    ov, nxt, nfull = overflow_counter_full(row, count, full, n_max)
    m.d.comb += over.eq(ov)
    m.d.sync += [count.eq(nxt), full.eq(nfull)]
    rows = (np.random.default_rng(n_max).random(200) < 0.5).astype(int).tolist()

    async def bench(ctx):
        c, f = 0, 0
        for r in rows:
            ctx.set(row, r)
            want_over, want_next, want_full = overflow_counter_full_twin(r, c, f, n_max)
            # The flag is exactly count == n_max, and the counts are those of the plain counter.
            assert (want_over, want_next) == overflow_counter_twin(r, c, n_max)
            assert want_full == int(want_next == n_max)
            assert (ctx.get(count), ctx.get(full), ctx.get(over)) == (c, f, want_over)
            await ctx.tick()
            c, f = want_next, want_full

    run_sim(m, bench)


@pytest.mark.parametrize(("words_per_beat", "counter_max", "rng", "samples", "answer", "normalize"),
                         [(3, 4, "lfsr", 1, "none", False), (1, 1, "sobol", 1, "none", False),
                          (1, 3, "lfsr-shared", 1, "none", False), (3, 4, "sobol", 1, "none", False),
                          (1, 3, "sobol", 1, "none", False), (3, 4, "sobol", 2, "none", False),
                          (1, 3, "sobol", 2, "none", False), (1, 8, "sobol", 4, "none", False),
                          (3, 4, "lfsr", 1, "leading", False), (3, 4, "sobol", 1, "leading", False),
                          (1, 8, "sobol", 2, "leading", False), (3, 3, "sobol", 4, "leading", False),
                          (1, 1, "sobol", 1, "none", True), (1, 3, "sobol", 1, "none", True),
                          (1, 3, "sobol", 2, "none", True)])
def test_pixel_wall_cycles_match_the_rtl(words_per_beat: int, counter_max: int, rng: str, samples: int,
                                         answer: str, normalize: bool) -> None:
    """The clock cycles of a stream of pixels (loads always offered, results always taken), derived
    from the timing rules of docs/architecture.md ("Timing") alone, against the RTL in the
    simulator; and ``pixel_wall_cycles`` against the same derivation. With ``sobol`` (counter max
    >= 2B, B samples per clock) the machine has no bubble; below, it keeps it. With the leading
    answer a timed-out run's bubble waits ``search_cycles`` more. Normalized columns add no cycle
    (their maxima are final when a pixel's last beat is written), load-bound runs included."""
    leading = answer == "leading"
    params = small_params(words_per_beat=words_per_beat, counter_max=counter_max, rng=rng, word_bits=3,
                          max_cycles=4 * counter_max + 3 if leading else 60, samples_per_clock=samples,
                          timeout_answer=answer, normalize=normalize)
    assert hides_bubble(params) == (rng == "sobol" and counter_max >= 2 * samples)
    rng_ = np.random.default_rng(words_per_beat * 10 + counter_max)
    words = rng_.integers(0, params.word_one + 1, size=(25, params.rows, params.operator_columns))
    if leading:
        words[::2] //= 3  # weak pixels: timeouts
    engine = PysimEngine(params)
    got = engine.run(words)
    assert got.equal(MachineModel(params).run(words))
    beats = params.beats_per_pixel
    search = search_cycles(params) * got.timeout.astype(np.int64)
    assert not leading or (got.timeout[:-1].any() and (~got.timeout[:-1]).any())
    block = (1 << params.word_bits) // samples  # a Sobol block's clocks
    # Cycles are numbered from 0, the first clock after reset. A pixel's beats are handed over one
    # per cycle and each is written the cycle after its handshake, so the shadow memory holds the
    # whole pixel beats + 1 cycles after its first beat. Pixel 0's first beat is in cycle 0.
    if hides_bubble(params):
        # No bubble: ``firsts`` are the runs' first compute cycles, each also its swap. The shadow's
        # first bits are registered a cycle before the swap, so pixel 0's run starts a cycle after
        # its shadow is complete; the next pixel's beats start in the swap itself. A run of k cycles
        # from c ends in c + k - 1; the next run starts in c + k if the shadow was complete in
        # c + k - 1 and that cycle did not begin a Sobol block (k - 1 a nonzero multiple of 2^W / B:
        # then a bubble first) nor timed out with a leading answer (then the search, whose last
        # cycle is the bubble), else as soon as the shadow is complete a cycle before.
        firsts = [beats + 2]
        for k, wait in zip(got.cycles[:-1].tolist(), search[:-1].tolist(), strict=True):
            begins_block = k > 1 and (k - 1) % block == 0
            firsts.append(firsts[-1] + max(k + max(begins_block, wait), beats + 2))
        # The last pixel: its k compute cycles, its bubble (the result register takes the result),
        # then one cycle with the result valid, in which the testbench takes it.
        last_taken = firsts[-1] + int(got.cycles[-1]) + int(search[-1]) + 1
        steps = np.diff(firsts)
        k = got.cycles[:-1].astype(np.int64)
        compute_bound = k >= beats + 2
        late = (k > 1) & ((k - 1) % block == 0) & (search[:-1] == 0)
        quiet = compute_bound & (search[:-1] == 0)
        # Wall cycles equal compute cycles wherever loading is hidden (and no block began last).
        assert (steps == k)[quiet & ~late].all() and (steps == k + 1)[quiet & late].all()
        if counter_max > 3 and not leading and samples == 1:
            assert compute_bound.all() and late.any()
    else:
        # The idle machine swaps a complete shadow in at once:
        firsts = [beats + 1]  # here: the swaps, each the cycle before the run's first compute cycle
        for k, wait in zip(got.cycles[:-1].tolist(), search[:-1].tolist(), strict=True):
            # compute cycles swap + 1 ... swap + k, a leading answer's search, then the run's bubble
            bubble = firsts[-1] + k + wait + 1
            loaded = firsts[-1] + 1 + beats + 1  # the next pixel's beats start the cycle after the swap
            # Swapped in the bubble if the shadow is complete by then; else the machine idles until it is.
            firsts.append(max(bubble, loaded))
        # The last pixel: its k compute cycles, its bubble, then the cycle in which it is taken.
        last_taken = firsts[-1] + int(got.cycles[-1]) + int(search[-1]) + 2
        steps = np.diff(firsts)
        # Both cases of the max: load-bound pixels (runs shorter than a load) and compute-bound ones.
        load_bound = got.cycles[:-1] + search[:-1] + 1 < beats + 2
        if counter_max == 1:
            assert load_bound.any()
        if counter_max > 1 and samples == 1:
            assert (~load_bound).any()
    # The simulator has run every cycle up to and including the one the last result is taken in.
    assert engine.clock_cycles == last_taken + 1
    # pixel_wall_cycles is the steady state's time from one run's start to the next.
    assert pixel_wall_cycles(params, got.cycles, got.timeout)[:-1].tolist() == steps.tolist()
    if not leading:
        assert pixel_wall_cycles(params, got.cycles)[:-1].tolist() == steps.tolist()
    else:
        with pytest.raises(ValueError, match="timeout"):
            pixel_wall_cycles(params, got.cycles)
