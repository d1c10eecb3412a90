# amaranth: UnusedElaboratable=no
"""The control path's timing: counters' full flags against their twin, and the per-pixel clock
cycles the FPGA report uses (``pixel_wall_cycles``) against the RTL in the simulator."""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Module, Signal
from conftest import run_sim, small_params

from bayesmachine.hdl.counters import overflow_counter_full, overflow_counter_full_twin, overflow_counter_twin
from bayesmachine.hdl.machine import pixel_wall_cycles
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


@pytest.mark.parametrize(("lanes", "counter_max"), [(3, 4), (1, 1), (1, 3)])
def test_pixel_wall_cycles_match_the_rtl(lanes: int, counter_max: int) -> None:
    """The clock cycles of a stream of pixels (loads always offered, results always taken), derived
    from the timing rules of docs/architecture.md ("Timing") alone, against the RTL in the
    simulator; and ``pixel_wall_cycles`` against the same derivation."""
    params = small_params(lanes=lanes, counter_max=counter_max, max_cycles=60)
    rng = np.random.default_rng(lanes * 10 + counter_max)
    words = rng.integers(0, params.word_one + 1, size=(25, params.rows, params.operator_columns))
    engine = PysimEngine(params)
    got = engine.run(words)
    assert got.equal(MachineModel(params).run(words))
    beats = params.beats_per_pixel
    # Cycles are numbered from 0, the first clock after reset. A pixel's beats are handed over one
    # per cycle and each is written the cycle after its handshake, so the shadow memory holds the
    # whole pixel beats + 1 cycles after its first beat. Pixel 0's first beat is in cycle 0, and the
    # idle machine swaps a complete shadow in at once:
    swaps = [beats + 1]
    for k in got.cycles[:-1].tolist():
        bubble = swaps[-1] + k + 1  # compute cycles swap + 1 ... swap + k, then the run's bubble
        loaded = swaps[-1] + 1 + beats + 1  # the next pixel's beats start the cycle after the swap
        # Swapped in the bubble if the shadow is complete by then; else the machine idles until it is.
        swaps.append(max(bubble, loaded))
    # The last pixel: its k compute cycles, its bubble (the result register takes the result), then
    # one cycle with the result valid, in which the testbench takes it; the simulator has run every
    # cycle up to and including that one.
    last_taken = swaps[-1] + int(got.cycles[-1]) + 2
    assert engine.clock_cycles == last_taken + 1
    # pixel_wall_cycles is the steady state's swap-to-swap time.
    assert pixel_wall_cycles(params, got.cycles)[:-1].tolist() == np.diff(swaps).tolist()
    # Both cases of the max: load-bound pixels (runs shorter than a load) and compute-bound ones.
    load_bound = got.cycles[:-1] + 1 < beats + 2
    if counter_max == 1:
        assert load_bound.any()
    if counter_max > 1:
        assert (~load_bound).any()
