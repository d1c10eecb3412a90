# amaranth: UnusedElaboratable=no
"""The stochastic operators: the matrix RTL against its twin, exact p = 0 and p = 1, rate = p."""

from __future__ import annotations

import math
import random

import pytest
from conftest import run_sim

from bayesmachine.hdl.machine.operator import OperatorMatrix, operator_matrix_twin, stochastic_operator_twin
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources.lfsr import LFSRSpec, lfsr_numbers, lfsr_specs


def _spec(length: int, w: int, index: int = 0) -> LFSRSpec:
    params = MachineParams(rows=8, columns=1, word_bits=w, lfsr_bits=length, counter_max=1, max_cycles=2,
                           words_per_beat=1)
    return lfsr_specs(params)[index]


def _rtl_rows(dut: OperatorMatrix, drive: list[tuple[list[int], list[int]]]) -> list[int]:
    """The ``row`` output for each (words, numbers) of ``drive`` (combinational)."""
    seen: list[int] = []

    async def bench(ctx):
        for words, numbers in drive:
            for port, v in zip(dut.words, words, strict=True):
                ctx.set(port, v)
            for port, v in zip(dut.numbers, numbers, strict=True):
                ctx.set(port, v)
            seen.append(ctx.get(dut.row))

    run_sim(dut, bench, clock=False)
    return seen


@pytest.mark.parametrize(("rows", "columns", "w", "shared"),
                         [(3, 2, 4, False), (4, 3, 4, True), (82, 3, 10, False), (82, 4, 10, True)])
def test_rtl_matrix_matches_twin(rows: int, columns: int, w: int, shared: bool) -> None:
    """The component wraps the machine's own matrix function; per-operator and per-column numbers."""
    ops = rows * columns
    sources = [o % columns for o in range(ops)] if shared else list(range(ops))
    dut = OperatorMatrix(rows=rows, columns=columns, word_bits=w, sources=sources)
    rnd = random.Random(rows * columns)
    one = 1 << w
    edge = [0, one, 1, one - 1, one // 2]
    drive = []
    for _ in range(300 if ops < 100 else 80):
        words = [rnd.choice(edge) if rnd.random() < 0.4 else rnd.randint(0, one) for _ in range(ops)]
        if rnd.random() < 0.5:  # rows of likely words, so that row bits of 1 are common
            words = [rnd.randint(one - 2, one) for _ in range(ops)]
        numbers = [rnd.randrange(one) for _ in range(max(sources) + 1)]
        drive.append((words, numbers))
    got = _rtl_rows(dut, drive)
    ones = 0
    for (words, numbers), row in zip(drive, got, strict=True):
        want = operator_matrix_twin(words, numbers, rows, columns, sources)
        assert [(row >> r) & 1 for r in range(rows)] == want
        ones += sum(want)
    assert ones > 20


def test_rtl_matrix_p0_and_p1_exact() -> None:
    w = 10
    dut = OperatorMatrix(rows=2, columns=1, word_bits=w, sources=[0, 1])
    drive = [([1 << w, 0], [n, n]) for n in (0, 1, 511, 1022, 1023)]
    assert _rtl_rows(dut, drive) == [0b01] * 5  # 1.0 always fires, 0 never does


def test_matrix_rejects_bad_parameters() -> None:
    with pytest.raises(ParameterError, match="one random number per operator"):
        OperatorMatrix(rows=2, columns=2, word_bits=4, sources=[0, 1, 2])
    with pytest.raises(ParameterError, match="word_bits"):
        OperatorMatrix(rows=2, columns=2, word_bits=0, sources=[0, 1, 2, 3])


def _stream(spec: LFSRSpec, word: int, cycles: int) -> list[int]:
    return [stochastic_operator_twin(1, n, word) for n in lfsr_numbers(spec, cycles)]


def test_twin_p0_and_p1_exact_long() -> None:
    spec = _spec(31, 10, 3)
    assert sum(_stream(spec, 0, 100_000)) == 0
    assert sum(_stream(spec, 1 << 10, 100_000)) == 100_000


@pytest.mark.parametrize("q", [1, 3, 8, 13, 15])
def test_rate_is_exact_over_a_whole_period(q: int) -> None:
    # Over a whole period every non-zero L-bit state occurs once (gcd(W, 2^L - 1) = 1), so the
    # W low bits take each value 2^(L-W) times, except 0 which misses the all-zero state once:
    # exactly q * 2^(L-W) - 1 numbers fall below q >= 1.
    length, w = 12, 4
    spec = _spec(length, w, 1)
    ones = sum(_stream(spec, q, spec.period))
    assert ones == q * (1 << (length - w)) - 1


@pytest.mark.parametrize("q", [10, 20, 100, 512, 900, 1014])  # p from ~0.01 (p_nm0) to ~0.99
def test_rate_equals_p_full_size(q: int) -> None:
    # The full-size LFSR (L = 31, W = 10) over 200k cycles: binomial bound of 5 sigma.
    n = 200_000
    p = q / 1024
    for index in (0, 5):
        ones = sum(_stream(_spec(31, 10, index), q, n))
        assert abs(ones - n * p) < 5 * math.sqrt(n * p * (1 - p))


@pytest.mark.parametrize(("w", "samples"), [(1, 1), (3, 1), (4, 1), (3, 2), (4, 4), (5, 4), (5, 8)])
def test_sample_bits_compare_every_point(w: int, samples: int) -> None:
    """``sample_bits`` gives ``(n ^ point) < word`` for every number, word and point of a Sobol clock
    (a clock's B points, and a block's first two clocks' 2B as the machine without a bubble compares
    them in a swap), equal to its twin."""
    from amaranth.hdl import Module, Signal

    from bayesmachine.hdl.machine.operator import sample_bits, sample_bits_twin
    from bayesmachine.sources.sobol import sample_points

    point_sets = [sample_points(c, w, samples) for c in range(3)]
    if 2 * samples <= 1 << w:
        point_sets += [sample_points(c, w, 2 * samples) for c in range(3)]
    m = Module()
    number, word = Signal(w), Signal(w + 1)
    outs = []
    for points in point_sets:
        out = Signal(len(points))
        m.d.comb += out.eq(sample_bits(number, word, points))
        outs.append(out)
    cases = [(n, q) for n in range(1 << w) for q in range((1 << w) + 1)]

    async def bench(ctx):
        for n, q in cases:
            ctx.set(number, n)
            ctx.set(word, q)
            for out, points in zip(outs, point_sets, strict=True):
                want = sample_bits_twin(n, q, points)
                assert want == [int((n ^ p) < q) for p in points]
                assert [(ctx.get(out) >> i) & 1 for i in range(len(points))] == want, (n, q, points)

    run_sim(m, bench, clock=False)


@pytest.mark.parametrize(("w", "samples"), [(3, 1), (3, 2), (4, 4), (4, 8)])
def test_scaled_numbers_for_every_point(w: int, samples: int) -> None:
    """``scaled_numbers`` gives ``((n ^ point) * m) >> W`` for every number, scale m (0 .. 2^W) and
    point of a clock's B points and a block's first 2B, exhaustively at small W, equal to its twin."""
    from amaranth.hdl import Module, Signal

    from bayesmachine.hdl.machine.operator import scaled_numbers, scaled_numbers_twin
    from bayesmachine.sources.sobol import sample_points

    point_sets = [sample_points(c, w, b) for c in range(3) for b in (samples, 2 * samples) if b <= 1 << w]
    m = Module()
    number, scale = Signal(w), Signal(w + 1)
    outs = []
    for points in point_sets:
        values = [Signal(w) for _ in points]
        m.d.comb += [v.eq(x) for v, x in zip(values, scaled_numbers(number, scale, points), strict=True)]
        outs.append(values)

    async def bench(ctx):
        for n in range(1 << w):
            for s in range((1 << w) + 1):
                ctx.set(number, n)
                ctx.set(scale, s)
                for values, points in zip(outs, point_sets, strict=True):
                    want = scaled_numbers_twin(n, s, points, w)
                    assert want == [((n ^ p) * s) >> w for p in points]
                    assert [ctx.get(v) for v in values] == want, (n, s, points)

    run_sim(m, bench, clock=False)
