"""The stochastic operator: RTL against its twin, exact p = 0 and p = 1, rate = p."""

from __future__ import annotations

import math
import random

import pytest
from conftest import run_sim

from bayesmachine.hdl.operator import StochasticOperator, operator_stream, stochastic_operator_twin
from bayesmachine.hdl.rng import LFSRSpec, lfsr_specs, lfsr_step
from bayesmachine.params import MachineParams


def _spec(length: int, w: int, index: int = 0) -> LFSRSpec:
    params = MachineParams(rows=8, columns=1, word_bits=w, lfsr_bits=length, counter_max=1, max_cycles=2,
                           lanes=1)
    return lfsr_specs(params)[index]


def _rtl_outputs(spec: LFSRSpec, drive: list[tuple[int, int, int]]) -> list[tuple[int, int]]:
    """(number, bus_out) per cycle for a list of (word, bus_in, enable)."""
    dut = StochasticOperator(spec)
    seen: list[tuple[int, int]] = []

    async def bench(ctx):
        for word, bus_in, enable in drive:
            ctx.set(dut.word, word)
            ctx.set(dut.bus_in, bus_in)
            ctx.set(dut.enable, enable)
            seen.append((ctx.get(dut.number), ctx.get(dut.bus_out)))
            await ctx.tick()

    run_sim(dut, bench)
    return seen


@pytest.mark.parametrize(("length", "w"), [(12, 4), (31, 10)])
def test_rtl_operator_matches_twin(length: int, w: int) -> None:
    spec = _spec(length, w)
    rnd = random.Random(length)
    one = 1 << w
    words = [0, one, 1, one - 1, one // 2] + [rnd.randint(0, one) for _ in range(5)]
    drive = [(rnd.choice(words), int(rnd.random() < 0.8), int(rnd.random() < 0.7)) for _ in range(600)]
    got = _rtl_outputs(spec, drive)
    state = spec.init
    for (word, bus_in, enable), (number, bit) in zip(drive, got, strict=True):
        n, nxt = lfsr_step(state, spec)
        assert number == n
        assert bit == stochastic_operator_twin(bus_in, n, word)
        if enable:
            state = nxt


def test_rtl_operator_p0_and_p1_exact() -> None:
    spec = _spec(31, 10, 2)
    for word, expected in ((0, 0), (1 << 10, 1)):
        got = _rtl_outputs(spec, [(word, 1, 1)] * 300)
        assert {bit for _, bit in got} == {expected}
    # bus_in = 0 blocks even p = 1
    assert {bit for _, bit in _rtl_outputs(spec, [(1 << 10, 0, 1)] * 50)} == {0}


def test_twin_p0_and_p1_exact_long() -> None:
    spec = _spec(31, 10, 3)
    assert sum(operator_stream(spec, 0, 100_000)) == 0
    assert sum(operator_stream(spec, 1 << 10, 100_000)) == 100_000


@pytest.mark.parametrize("q", [1, 3, 8, 13, 15])
def test_rate_is_exact_over_a_whole_period(q: int) -> None:
    # Over a whole period every non-zero L-bit state occurs once (gcd(W, 2^L - 1) = 1), so the
    # W low bits take each value 2^(L-W) times, except 0 which misses the all-zero state once:
    # exactly q * 2^(L-W) - 1 numbers fall below q >= 1.
    length, w = 12, 4
    spec = _spec(length, w, 1)
    ones = sum(operator_stream(spec, q, spec.period))
    assert ones == q * (1 << (length - w)) - 1


@pytest.mark.parametrize("q", [10, 20, 100, 512, 900, 1014])  # p from ~0.01 (p_nm0) to ~0.99
def test_rate_equals_p_full_size(q: int) -> None:
    # The full-size LFSR (L = 31, W = 10) over 200k cycles: binomial bound of 5 sigma.
    n = 200_000
    p = q / 1024
    for index in (0, 5):
        ones = sum(operator_stream(_spec(31, 10, index), q, n))
        assert abs(ones - n * p) < 5 * math.sqrt(n * p * (1 - p))


def test_rtl_rate_equals_p_short() -> None:
    spec = _spec(31, 10, 1)
    n, q = 2000, 300
    ones = sum(bit for _, bit in _rtl_outputs(spec, [(q, 1, 1)] * n))
    p = q / 1024
    assert abs(ones - n * p) < 5 * math.sqrt(n * p * (1 - p))
