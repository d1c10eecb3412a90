"""Leap-forward LFSRs: RTL against the twin, primitivity against published tables, maximal period,
serial and cross correlation."""

from __future__ import annotations

import math
import random

import numba
import numpy as np
import pytest
from amaranth.hdl import Module, Signal
from conftest import run_sim

from bayesmachine.hdl.sources import LFSRBank
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources.lfsr import (
    LFSRSpec,
    column_lfsr_specs,
    is_primitive,
    lfsr_bit_sequence,
    lfsr_numbers,
    lfsr_specs,
    lfsr_step,
)


def _specs(length: int, w: int, n: int = 2, seed: int = 1) -> list[LFSRSpec]:
    params = MachineParams(rows=n, columns=1, word_bits=w, lfsr_bits=length, counter_max=1, max_cycles=2,
                           words_per_beat=1, seed=seed)
    return lfsr_specs(params)


def _rtl_numbers(spec: LFSRSpec, enables: list[int]) -> list[int]:
    """The number of a one-LFSR bank (the machine's component) each cycle, ``enable`` from ``enables``."""
    return [n[0] for n in _rtl_bank_numbers([spec], enables)]


def _rtl_bank_numbers(specs: list[LFSRSpec], enables: list[int]) -> list[list[int]]:
    dut = LFSRBank(specs=specs)
    seen: list[list[int]] = []

    async def bench(ctx):
        for en in enables:
            ctx.set(dut.enable, en)
            seen.append([ctx.get(n) for n in dut.numbers])
            await ctx.tick()

    run_sim(dut, bench)
    return seen


def _twin_numbers(spec: LFSRSpec, enables: list[int]) -> list[int]:
    state, out = spec.init, []
    for en in enables:
        number, nxt = lfsr_step(state, spec)
        out.append(number)
        if en:
            state = nxt
    return out


@pytest.mark.parametrize(("length", "w"), [(9, 3), (10, 4), (12, 4)])
def test_rtl_lfsr_matches_twin_over_whole_period(length: int, w: int) -> None:
    spec = _specs(length, w)[0]
    assert math.gcd(w, spec.period) == 1  # so the leap-forward state also has the full period
    enables = [1] * (spec.period + 3)  # one whole period and a wrap
    got = _rtl_numbers(spec, enables)
    assert got == _twin_numbers(spec, enables)
    assert got[spec.period : spec.period + 3] == got[:3]


@pytest.mark.parametrize(("length", "w"), [(12, 4), (31, 10)])
def test_rtl_lfsr_advances_only_when_enabled(length: int, w: int) -> None:
    spec = _specs(length, w)[1]
    rnd = random.Random(5)
    enables = [int(rnd.random() < 0.6) for _ in range(400)]
    assert _rtl_numbers(spec, enables) == _twin_numbers(spec, enables)


@pytest.mark.parametrize(("length", "w"), [(9, 3), (10, 4), (12, 4), (13, 5)])
def test_twin_is_the_bit_serial_m_sequence_and_maximal(length: int, w: int) -> None:
    for spec in _specs(length, w, n=3):
        period = (1 << length) - 1
        bits = lfsr_bit_sequence(spec, period + length)
        # Leap-forward numbers are consecutive W-bit chunks of the sequence, bit j = s[kW + j].
        count = (period + length) // w
        chunks = [sum(bits[k * w + j] << j for j in range(w)) for k in range(count)]
        assert list(lfsr_numbers(spec, count)) == chunks
        # Maximal length: the L-bit windows run through all 2^L - 1 non-zero states once.
        windows = {sum(bits[t + i] << i for i in range(length)) for t in range(period)}
        assert len(windows) == period and 0 not in windows
        assert bits[period : period + length] == bits[:length]


# --- Correlation: why the leap-forward (W bits per clock) matters ---

N_CORR = 100_000
SIGMA = 1 / math.sqrt(N_CORR)  # standard error of a correlation estimate for independent streams


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.astype(float), b.astype(float))[0, 1])


@pytest.fixture(scope="module")
def streams() -> dict[str, np.ndarray]:
    """Random numbers of the full-size machine's first two operators (L = 31, W = 10)."""
    specs = _specs(31, 10)
    w = 10
    leap0 = np.fromiter(lfsr_numbers(specs[0], N_CORR), dtype=np.int64)
    leap1 = np.fromiter(lfsr_numbers(specs[1], N_CORR), dtype=np.int64)
    # The naive alternative: the same m-sequence in a register that shifts ONE bit per clock, the
    # comparator reading its W low bits (number_t = s[t] ... s[t + W - 1]).
    bits = np.array(lfsr_bit_sequence(specs[0], N_CORR + w), dtype=np.int64)
    shift1 = sum(bits[j : j + N_CORR] << j for j in range(w))
    return {"leap0": leap0, "leap1": leap1, "shift1": shift1}


@pytest.mark.parametrize("q", [256, 307, 512, 768])  # p = 0.25, 0.3, 0.5, 0.75 at W = 10
def test_leap_forward_stream_has_no_lag1_correlation(streams: dict[str, np.ndarray], q: int) -> None:
    b = streams["leap0"] < q
    assert abs(b.mean() - q / 1024) < 5 * math.sqrt(q / 1024 * (1 - q / 1024) / N_CORR)
    for lag in (1, 2, 3):
        assert abs(_corr(b[:-lag], b[lag:])) < 5 * SIGMA


@pytest.mark.parametrize(("q", "expected"), [(256, 1 / 3), (768, 1 / 3), (307, None)])
def test_one_bit_shift_stream_is_serially_correlated(
    streams: dict[str, np.ndarray], q: int, expected: float | None
) -> None:
    # number_t < q with q = 2^(W-2) is "the two top bits are 0"; number_{t+1} shares one of
    # them, so P(b_t & b_{t+1}) = 1/8 instead of 1/16: correlation (1/16) / (3/16) = 1/3.
    b = streams["shift1"] < q
    c = _corr(b[:-1], b[1:])
    assert c > 40 * SIGMA  # > 0.12: clearly correlated
    if expected is not None:
        assert abs(c - expected) < 5 * SIGMA


def test_one_bit_shift_at_p_half_depends_on_one_bit(streams: dict[str, np.ndarray]) -> None:
    # The exception: at p = 1/2 the comparator reads only the newest bit, and consecutive
    # m-sequence bits are uncorrelated, so the lag-1 correlation of the comparator stream is ~0
    # even for the one-bit shift; the numbers themselves are still strongly correlated.
    b = streams["shift1"] < 512
    assert abs(_corr(b[:-1], b[1:])) < 5 * SIGMA
    n = streams["shift1"]
    assert _corr(n[:-1], n[1:]) > 0.45  # number_{t+1} ~ number_t / 2 + new bit * 2^(W-1)
    leap = streams["leap0"]
    assert abs(_corr(leap[:-1], leap[1:])) < 5 * SIGMA


@pytest.mark.parametrize("q", [256, 512])
def test_two_operators_streams_are_uncorrelated(streams: dict[str, np.ndarray], q: int) -> None:
    a, b = streams["leap0"] < q, streams["leap1"] < q
    for lag in (0, 1, 2):
        assert abs(_corr(a[: N_CORR - lag], b[lag:])) < 5 * SIGMA
        assert abs(_corr(b[: N_CORR - lag], a[lag:])) < 5 * SIGMA


@pytest.mark.slow
def test_polynomial_search_ends_when_heptanomials_run_out() -> None:
    """L = 34, taps <= 24: only ~3,200 primitive heptanomials exist; asking for more must fall
    back to pentanomials and trinomials, not draw forever."""
    from bayesmachine.sources.lfsr import _primitive_tap_sets

    sets = _primitive_tap_sets(34, 24, 3300, 1)
    assert len(sets) == 3300 and len(set(sets)) == 3300
    assert any(len(t) < 6 for t in sets)
    assert all(is_primitive(34, t) for t in sets[-5:])
    # All there are (3,365 of weight <= 7): a machine with more operators reuses them.
    assert len(_primitive_tap_sets(34, 24, 4000, 1)) == 3365


def test_rtl_bank_of_column_lfsrs_matches_twins() -> None:
    """lfsr-shared's bank: one LFSR per operator column, distinct polynomials and start states."""
    params = MachineParams(rows=4, columns=3, prior="loaded", word_bits=4, lfsr_bits=12, counter_max=1,
                           max_cycles=2, words_per_beat=1, rng="lfsr-shared", seed=9)
    specs = column_lfsr_specs(params)
    assert len(specs) == 4 and len({s.taps for s in specs}) == 4 and len({s.init for s in specs}) == 4
    assert {s.init for s in specs}.isdisjoint(s.init for s in lfsr_specs(params))
    rnd = random.Random(3)
    enables = [int(rnd.random() < 0.7) for _ in range(300)]
    got = _rtl_bank_numbers(specs, enables)
    for i, spec in enumerate(specs):
        assert [n[i] for n in got] == _twin_numbers(spec, enables)


# --- Primitivity against published tables ---

def _taps_of(poly: int) -> tuple[int, ...]:
    return tuple(i for i in range(poly.bit_length() - 1) if (poly >> i) & 1)


def test_degree_31_trinomials_match_the_published_table() -> None:
    # Zierler & Brillhart, "On primitive trinomials (mod 2)", Inform. Control 13 (1968): the
    # irreducible trinomials x^31 + x^k + 1 are k = 3, 6, 7, 13 and their reciprocals 18, 24, 25,
    # 28; 2^31 - 1 is prime, so they are all primitive (XAPP052 lists taps 31, 28 for n = 31).
    primitive = {k for k in range(1, 31) if is_primitive(31, (0, k))}
    assert primitive == {3, 6, 7, 13, 18, 24, 25, 28}


# OEIS A132449: the first primitive polynomial over GF(2) of degree n with at most 5 terms, as
# an integer (bit i = coefficient of x^i), n = 2 ... 31 (2147483657 = x^31 + x^3 + 1).
A132449 = [7, 11, 19, 37, 67, 131, 285, 529, 1033, 2053, 4179, 8219, 16427, 32771, 65581, 131081, 262183,
           524327, 1048585, 2097157, 4194307, 8388641, 16777243, 33554441, 67108935, 134217767, 268435465,
           536870917, 1073741907, 2147483657]


@pytest.mark.parametrize("degree", range(2, 32))
def test_first_primitive_polynomial_with_at_most_5_terms(degree: int) -> None:
    first = next(poly for poly in range((1 << degree) + 1, 1 << (degree + 1), 2)
                 if poly.bit_count() <= 5 and is_primitive(degree, _taps_of(poly)))
    assert first == A132449[degree - 2]


@pytest.mark.parametrize("degree", [2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12])
def test_number_of_primitive_polynomials_is_phi_over_n(degree: int) -> None:
    # There are phi(2^n - 1) / n primitive polynomials of degree n over GF(2) (Lidl & Niederreiter,
    # Finite Fields, Thm 3.5): 1, 2, 2, 6, 6, 18, 16, 48, 60, 176, 144 for n = 2 ... 12.
    order = (1 << degree) - 1
    phi = sum(1 for k in range(1, order + 1) if math.gcd(k, order) == 1)
    count = sum(is_primitive(degree, _taps_of(poly)) for poly in range(1 << degree, 1 << (degree + 1)))
    assert count == phi // degree


@pytest.mark.parametrize(
    ("poly", "order"),
    [
        # Irreducible but not primitive (x has order < 2^n - 1), as listed in tables of irreducible
        # polynomials (e.g. Peterson & Weldon, Error-Correcting Codes, 1972, appendix C); the
        # orders are recomputed by brute force below.
        (0b11111, 5),  # x^4 + x^3 + x^2 + x + 1
        (0b1001001, 9),  # x^6 + x^3 + 1
        (0b1110101, 21),  # x^6 + x^5 + x^4 + x^2 + 1
        (0b1010111, 21),  # x^6 + x^4 + x^2 + x + 1
        (0b100011011, 51),  # x^8 + x^4 + x^3 + x + 1 (the AES polynomial, FIPS 197)
    ],
)
def test_irreducible_but_not_primitive_polynomials_are_rejected(poly: int, order: int) -> None:
    degree = poly.bit_length() - 1
    assert not is_primitive(degree, _taps_of(poly))
    # The order of x, by brute force (independent of is_primitive's arithmetic).
    x, k = 1, 0
    while True:
        x <<= 1
        if x >> degree:
            x ^= poly
        k += 1
        if x == 1:
            break
    assert k == order


def test_lfsr_spec_enforces_what_the_model_kernel_assumes() -> None:
    LFSRSpec(31, (0, 3), 10, 1)
    LFSRSpec(31, (0, 1, 2, 3, 4, 5), 10, 1)
    for taps, message in [
        ((3, 0), "increasing"),
        ((0, 3, 3, 5), "increasing"),
        ((1, 3), "starting at 0"),
        ((0, 22), "L - W"),
        ((0, 3, 5), "even number"),
        ((0, 1, 2, 3, 4, 5, 6, 7), "even number"),
    ]:
        with pytest.raises(ParameterError, match=message):
            LFSRSpec(31, taps, 10, 1)
    with pytest.raises(ParameterError, match="non-zero"):
        LFSRSpec(31, (0, 3), 10, 0)


@numba.njit(cache=True)
def _period(init: int, taps: np.ndarray, length: int, w: int, limit: int) -> int:
    """Leap-forward steps until the state returns to ``init`` (0 if not within ``limit``)."""
    mask = np.uint64((1 << w) - 1)
    top = np.uint64(length - w)
    s = np.uint64(init)
    start = np.uint64(init)
    for k in range(1, limit + 1):
        new = np.uint64(0)
        for t in taps:
            new ^= s >> np.uint64(t)
        s = (s >> np.uint64(w)) | ((new & mask) << top)
        if s == start:
            return k
    return 0


def test_numba_period_helper_on_a_small_lfsr() -> None:
    spec = _specs(12, 4)[0]
    taps = np.array(spec.taps, np.int64)
    assert _period(spec.init, taps, 12, 4, 1 << 13) == spec.period


@pytest.mark.slow
def test_full_period_of_the_machines_first_lfsr() -> None:
    """One whole period, 2^31 - 1 leap-forward steps, of the default machine's operator 0 (L = 31,
    W = 10: gcd(10, 2^31 - 1) = 1, so the leap-forward state has the full period too)."""
    spec = lfsr_specs(MachineParams.for_disparity(80))[0]
    assert (spec.length, spec.step) == (31, 10)
    taps = np.array(spec.taps, np.int64)
    assert _period(spec.init, taps, 31, 10, 1 << 31) == (1 << 31) - 1


def test_rtl_lfsr_next_numbers_and_enable_groups() -> None:
    """``next_numbers`` (the machine's prefetched comparators) is the number after an enabled
    clock, ``following_numbers`` the next cycle's ``next_numbers``; with ``enable_groups`` each
    LFSR advances on its own group's enable bit."""
    specs = _specs(12, 4, n=3)
    dut = LFSRBank(specs=specs, enable_groups=[0, 1, 0])
    rnd = random.Random(8)
    enables = [(int(rnd.random() < 0.6), int(rnd.random() < 0.6)) for _ in range(200)]
    seen: list[tuple[list[int], list[int]]] = []

    async def bench(ctx):
        for e0, e1 in enables:
            ctx.set(dut.enable, e0 | (e1 << 1))
            seen.append(([ctx.get(n) for n in dut.numbers], [ctx.get(n) for n in dut.next_numbers],
                         [ctx.get(n) for n in dut.following_numbers]))
            await ctx.tick()

    run_sim(dut, bench)
    for i, spec in enumerate(specs):
        mine = [e1 if i == 1 else e0 for e0, e1 in enables]
        assert [s[0][i] for s in seen] == _twin_numbers(spec, mine)
        for t in range(len(seen) - 1):
            assert seen[t][2][i] == seen[t + 1][1][i]  # following_numbers: next_numbers a cycle early
            if mine[t]:
                assert seen[t][1][i] == seen[t + 1][0][i]



def test_rtl_lfsr_following_restart_numbers() -> None:
    """``following_restart_numbers`` means what the machine's per-group copies need: a register
    loaded with it every clock (reset to the start state's number) equals ``restart_numbers`` in
    every cycle, each LFSR on its own group's random enable."""
    specs = _specs(12, 4, n=3)
    dut = LFSRBank(specs=specs, enable_groups=[0, 1, 0])
    m = Module()
    m.submodules.dut = dut
    copies = [Signal(s.step, init=s.init & ((1 << s.step) - 1)) for s in specs]
    m.d.sync += [c.eq(n) for c, n in zip(copies, dut.following_restart_numbers, strict=True)]
    rnd = random.Random(9)
    seen: list[tuple[list[int], list[int]]] = []

    async def bench(ctx):
        for _ in range(300):
            ctx.set(dut.enable, rnd.getrandbits(2))
            seen.append(([ctx.get(n) for n in dut.restart_numbers], [ctx.get(c) for c in copies]))
            await ctx.tick()

    run_sim(m, bench)
    for t, (restart, copy) in enumerate(seen):
        assert copy == restart, t
    assert sum(a[0] != b[0] for a, b in zip(seen[:-1], seen[1:], strict=True)) > 100  # they move, not always
