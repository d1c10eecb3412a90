# amaranth: UnusedElaboratable=no
"""The control path's timing: counters' full flags against their twin, and the per-pixel clock
cycles the FPGA report uses (``pixel_wall_cycles``) against the RTL in the simulator."""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Module, Signal
from conftest import run_sim, small_params

from bayesmachine.hdl.counters import overflow_counter_full, overflow_counter_full_twin, overflow_counter_twin
from bayesmachine.hdl.machine import LOAD_LATENCY, pixel_wall_cycles
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
    # Loads always offered and results always taken: from one swap to the next, a pixel takes its
    # per-pixel figure; before the first swap come the first pixel's load beats (written a cycle
    # after their handshakes), and the last
    # pixel (no load after it) takes its compute cycles, its bubble and the hand-over.
    params = small_params(lanes=lanes, counter_max=counter_max, max_cycles=60)
    rng = np.random.default_rng(lanes * 10 + counter_max)
    words = rng.integers(0, params.word_one + 1, size=(25, params.rows, params.operator_columns))
    engine = PysimEngine(params)
    got = engine.run(words)
    assert got.equal(MachineModel(params).run(words))
    per_pixel = pixel_wall_cycles(params, got.cycles)
    if counter_max == 1:
        assert (got.cycles < params.beats_per_pixel).any()  # the load-bound case is covered
    last = int(got.cycles[-1]) + 1
    first = params.beats_per_pixel + LOAD_LATENCY
    assert engine.clock_cycles == first + int(per_pixel[:-1].sum()) + last + 2
