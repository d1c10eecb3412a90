# amaranth: UnusedElaboratable=no
"""The ``sobol`` source: the RTL generators against their twin, the twin against SciPy's Sobol
points, the net (stratification) property, and rows whose counts beat binomial noise."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from amaranth.hdl import Module, Signal
from conftest import run_sim

from bayesmachine.hdl.sources import SobolGenerators
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel
from bayesmachine.sources.lfsr import column_lfsr_specs, lfsr_numbers
from bayesmachine.sources.sobol import MAX_DIMENSIONS, SobolTwin, direction_numbers, sobol_points


def _params(w: int, columns: int = 3, **kwargs: object) -> MachineParams:
    samples = int(kwargs.get("samples_per_clock", 1))  # type: ignore[call-overload]
    base: dict[str, object] = dict(rows=2, columns=columns, word_bits=w, lfsr_bits=12 if w <= 5 else 31,
                                   counter_max=1, max_cycles=samples + 1, words_per_beat=1, rng="sobol",
                                   seed=5)
    base.update(kwargs)
    return MachineParams(**base)  # type: ignore[arg-type]


def _rtl_numbers(params: MachineParams, drive: list[tuple[int, int]]) -> list[list[int]]:
    """The generators' numbers each cycle for a list of (enable, restart)."""
    dut = SobolGenerators(params=params)
    seen: list[list[int]] = []

    async def bench(ctx):
        for enable, restart in drive:
            ctx.set(dut.enable, enable)
            ctx.set(dut.restart, restart)
            seen.append([ctx.get(n) for n in dut.numbers])
            await ctx.tick()

    run_sim(dut, bench)
    return seen


def _twin_numbers(params: MachineParams, drive: list[tuple[int, int]]) -> list[list[int]]:
    twin = SobolTwin(params)
    out = []
    for enable, restart in drive:
        if restart:  # the restart takes effect first: this cycle is a block's start (computing or not)
            twin.clock(False, True)
            restart = 0
        out.append(twin.numbers)
        twin.clock(bool(enable), bool(restart))
    return out


@pytest.mark.parametrize(("w", "columns"), [(3, 3), (5, 4), (10, 3)])
def test_rtl_matches_twin_over_full_index_periods(w: int, columns: int) -> None:
    """Three whole blocks of 2^W compute cycles without restart, then random enables and restarts."""
    params = _params(w, columns)
    rnd = random.Random(w)
    drive = [(1, 0)] * (3 << w)
    drive += [(int(rnd.random() < 0.8), int(rnd.random() < 0.05)) for _ in range(3 << w)]
    drive += [(1, 1), (0, 1), (1, 0), (0, 0), (1, 0), (1, 1), (1, 0)]
    got = _rtl_numbers(params, drive)
    assert got == _twin_numbers(params, drive)
    # The first block is the Sobol points XOR the column LFSRs' first numbers.
    shifts = [next(iter(lfsr_numbers(spec, 1))) for spec in column_lfsr_specs(params)]
    for j in range(1 << w):
        assert got[j] == [sobol_points(c, w)[j] ^ shifts[c] for c in range(columns)]
    # The second block: the LFSRs' second numbers, a different shift.
    second = [list(lfsr_numbers(spec, 2))[1] for spec in column_lfsr_specs(params)]
    assert got[1 << w] == second


@pytest.mark.parametrize(("w", "samples"), [(3, 2), (4, 4), (5, 8), (5, 16)])
def test_samples_per_clock_give_the_one_sample_points(w: int, samples: int) -> None:
    """With B samples per clock the generators give, clock after clock, B consecutive points of the
    one-sample stream: clock t's sample i is point (tB + i) mod 2^W of its block, XOR the block's
    shift (the column LFSR's next number, one per block); the RTL equals the twin, also under random
    enables and restarts (a restart starts a block: a multiple of B)."""
    params = _params(w, 3, samples_per_clock=samples)
    clocks = (1 << w) // samples
    drive = [(1, 0)] * (3 * clocks)
    rnd = random.Random(w * samples)
    drive += [(int(rnd.random() < 0.8), int(rnd.random() < 0.1)) for _ in range(6 * clocks)]
    got = _rtl_numbers(params, drive)
    assert got == _twin_numbers(params, drive)
    twin = SobolTwin(params)
    shifts = [list(lfsr_numbers(spec, 3)) for spec in column_lfsr_specs(params)]
    for t in range(3 * clocks):
        block, j = divmod(t * samples, 1 << w)
        want = [[sobol_points(c, w)[j + i] ^ shifts[c][block] for c in range(3)] for i in range(samples)]
        assert twin.sample_numbers == want, t
        rtl = [[n ^ pts[i] for n, pts in zip(got[t], twin.points, strict=True)] for i in range(samples)]
        assert rtl == want
        twin.clock(True, False)


def test_twin_blocks_do_not_depend_on_stall_timing() -> None:
    """A pixel of 8 cycles ends on a block's last point (W = 3); the next pixel starts in the next
    clock with a restarting compute cycle (the machine without a bubble), or after idle cycles: it
    sees the same numbers (a block's shift is drawn when used)."""
    params = _params(3)
    back_to_back = [(1, 0)] * 8 + [(1, 1)] + [(1, 0)] * 4
    stalled = [(1, 0)] * 8 + [(0, 0), (0, 0), (0, 1)] + [(1, 0)] * 5
    a = [n for n, (e, _) in zip(_twin_numbers(params, back_to_back), back_to_back, strict=True) if e]
    b = [n for n, (e, _) in zip(_twin_numbers(params, stalled), stalled, strict=True) if e]
    assert a == b
    assert _rtl_numbers(params, stalled) == _twin_numbers(params, stalled)
    assert _rtl_numbers(params, back_to_back) == _twin_numbers(params, back_to_back)


@pytest.mark.parametrize("w", [6, 8, 10, 15])
def test_points_equal_scipy_unscrambled_sobol(w: int) -> None:
    qmc = pytest.importorskip("scipy.stats.qmc")
    n = min(1 << w, 4096)
    ref = (qmc.Sobol(MAX_DIMENSIONS, scramble=False, bits=w).random(n) * (1 << w)).astype(np.int64)
    mine = np.array([sobol_points(d, w, n) for d in range(MAX_DIMENSIONS)]).T
    assert np.array_equal(ref, mine)


def test_direction_numbers_are_odd_multiples() -> None:
    # V_k = m_(k+1) * 2^(W-1-k) with m odd and < 2^(k+1): W bits, lowest set bit at W-1-k.
    for d in range(MAX_DIMENSIONS):
        v = direction_numbers(d, 15)
        assert all(0 < x < (1 << 15) and (x & -x) == 1 << (14 - k) for k, x in enumerate(v))
    with pytest.raises(ParameterError, match="dimension"):
        direction_numbers(MAX_DIMENSIONS, 10)


def _elementary_counts(points: np.ndarray, w: int, bits: tuple[int, ...]) -> np.ndarray:
    """Points per elementary box: the top ``bits[d]`` bits of coordinate d."""
    keys = np.zeros(len(points), np.int64)
    for d, b in enumerate(bits):
        keys = (keys << b) | (points[:, d] >> (w - b))
    return np.bincount(keys, minlength=1 << sum(bits))


@pytest.mark.parametrize("shifted", [False, True])
def test_first_points_are_a_0_m_2_net(shifted: bool) -> None:
    """Columns 0 and 1: every block's first 2^m points put exactly one point in every elementary
    box of volume 2^-m ((0, m, 2)-net), and every column alone is stratified; a digital shift keeps both."""
    w = 10
    pts = np.array([sobol_points(d, w) for d in range(3)]).T
    if shifted:
        pts ^= np.array([0x2A5, 0x13C, 0x3FF])
    for m in range(0, w + 1):
        first = pts[: 1 << m]
        for k in range(m + 1):
            assert (_elementary_counts(first[:, :2], w, (k, m - k)) == 1).all(), (m, k)
        for d in range(3):
            assert (_elementary_counts(first[:, d : d + 1], w, (m,)) == 1).all()
    # Three columns: every 2^m-point block puts exactly two points in each box of volume 2^(1-m)
    # with at most 1 bit of difference in resolution... checked as the t = 1 net the table gives:
    for m in range(1, w + 1):
        first = pts[: 1 << m]
        for a in range(m):
            for b in range(m - 1 - a):
                c = m - 1 - a - b
                assert (_elementary_counts(first, w, (a, b, c)) == 2).all(), (m, a, b, c)


def _count_variance(rng: str, words: tuple[int, ...], cycles: int, pixels: int) -> tuple[float, float]:
    """Mean and variance over pixels of a row's 1s in ``cycles`` compute cycles (the model)."""
    params = MachineParams(rows=2, columns=len(words), counter_max=cycles - 1, max_cycles=cycles,
                           words_per_beat=1,
                           rng=rng, seed=17)
    q = np.array([[words, [0] * len(words)]] * pixels, np.int32)
    res = MachineModel(params).run(q)
    assert res.timeout.all()
    n = res.counts[:, 0].astype(float)
    return float(n.mean()), float(n.var())


@pytest.mark.parametrize("words", [(700, 600, 800), (512, 300, 1000), (900, 1000, 150), (333, 777, 555)])
def test_row_counts_converge_faster_than_binomial(words: tuple[int, int, int]) -> None:
    cycles, pixels = 256, 4000
    p = math.prod(q / 1024 for q in words)
    binomial = cycles * p * (1 - p)
    mean, var = _count_variance("sobol", words, cycles, pixels)
    # Unbiased: the per-pixel random shifts make every number uniform.
    assert abs(mean - cycles * p) < 5 * math.sqrt(binomial / pixels)
    # Low discrepancy: far below the binomial variance (a uniform i.i.d. source gives ~1).
    print(f"\nwords {words}: variance / binomial = sobol {var / binomial:.3f}", end="")
    assert var < binomial / 4
    # The LFSR source, for comparison, is binomial (ratio ~1 within sampling error).
    _, var_lfsr = _count_variance("lfsr", words, cycles, pixels)
    assert abs(var_lfsr / binomial - 1) < 0.15
    print(f", lfsr {var_lfsr / binomial:.3f}", end="")


def test_sobol_needs_a_dimension_per_column() -> None:
    with pytest.raises(ParameterError, match="sobol"):
        MachineParams(rows=2, columns=MAX_DIMENSIONS + 1, rng="sobol", words_per_beat=1)
    with pytest.raises(ParameterError, match="sobol"):
        MachineParams(rows=2, columns=MAX_DIMENSIONS, prior="loaded", rng="sobol", words_per_beat=1)
    MachineParams(rows=2, columns=MAX_DIMENSIONS, rng="sobol", words_per_beat=1)


@pytest.mark.parametrize(("w", "columns", "samples"), [(1, 2, 1), (2, 3, 1), (3, 3, 1), (5, 2, 1), (3, 2, 2),
                                                        (4, 3, 4), (5, 2, 8)])
def test_next_and_restart_numbers_predict_the_next_cycle(w: int, columns: int, samples: int) -> None:
    """The machine's prefetched comparators read ``next_numbers`` in a compute cycle and
    ``restart_numbers`` in a run's start (never both in one cycle): each must be the number of the
    following cycle, across block ends (the shift LFSR's turn) and restarts mid-block; and
    ``following_numbers`` (its per-group copies' input) must be the next cycle's ``next_numbers``
    (with B samples per clock, of the clocks' first numbers)."""
    params = _params(w, columns, samples_per_clock=samples)
    rnd = random.Random(100 + w)
    drive = [(1, 0)] * (2 << w) + [(0, 1), (1, 0), (1, 0), (0, 0), (1, 0)]
    for _ in range(max(200, 6 << w)):
        x = rnd.random()
        drive.append((1, 0) if x < 0.75 else (0, 1) if x < 0.9 else (0, 0))
    dut = SobolGenerators(params=params)
    seen: list[tuple[list[int], ...]] = []

    async def bench(ctx):
        for enable, restart in drive:
            ctx.set(dut.enable, enable)
            ctx.set(dut.restart, restart)
            seen.append(tuple([ctx.get(n) for n in ports] for ports in (
                dut.numbers, dut.next_numbers, dut.restart_numbers, dut.following_numbers)))
            await ctx.tick()

    run_sim(dut, bench)
    assert [s[0] for s in seen] == _twin_numbers(params, drive)
    checked = {(1, 0): 0, (0, 1): 0}
    for t, (enable, restart) in enumerate(drive[:-1]):
        assert seen[t][3] == seen[t + 1][1], t  # following_numbers: next_numbers a cycle early
        if drive[t + 1][1]:
            continue  # the next cycle restarts: its numbers are a block's first, whatever came before
        following = seen[t + 1][0]
        if (enable, restart) == (1, 0):
            assert seen[t][1] == following, t
        elif (enable, restart) == (0, 1):
            assert seen[t][2] == following, t
        else:
            continue
        checked[(enable, restart)] += 1
    assert min(checked.values()) > 10



@pytest.mark.parametrize(("w", "columns", "samples"), [(1, 2, 1), (2, 3, 1), (3, 3, 1), (4, 3, 4)])
def test_following_restart_numbers_is_the_next_cycles_restart_numbers(w: int, columns: int,
                                                                      samples: int) -> None:
    """A register loaded with ``following_restart_numbers`` every clock (reset to the shift LFSR's
    first number) equals ``restart_numbers`` in every cycle, for random enable and restart
    patterns (all four combinations, so blocks end, restart mid-block and the LFSRs step)."""
    params = _params(w, columns, samples_per_clock=samples)
    dut = SobolGenerators(params=params)
    m = Module()
    m.submodules.dut = dut
    mask = (1 << w) - 1
    copies = [Signal(w, init=s.init & mask) for s in column_lfsr_specs(params)]
    m.d.sync += [c.eq(n) for c, n in zip(copies, dut.following_restart_numbers, strict=True)]
    rnd = random.Random(200 + w)
    seen: list[tuple[list[int], list[int]]] = []

    async def bench(ctx):
        for _ in range(max(300, 8 << w)):
            x = rnd.random()
            enable, restart = (1, 0) if x < 0.6 else (0, 1) if x < 0.75 else (1, 1) if x < 0.85 else (0, 0)
            ctx.set(dut.enable, enable)
            ctx.set(dut.restart, restart)
            seen.append(([ctx.get(n) for n in dut.restart_numbers], [ctx.get(c) for c in copies]))
            await ctx.tick()

    run_sim(m, bench)
    for t, (restart, copy) in enumerate(seen):
        assert copy == restart, t
    assert sum(a[0] != b[0] for a, b in zip(seen[:-1], seen[1:], strict=True)) > 20  # the shift LFSRs do step
