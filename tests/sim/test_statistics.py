"""Statistics of the machine (on the model, which the RTL matches bit for bit; fixed seeds).

- the AND of operators in a row fires at the product of their probabilities (every source);
- with independent LFSRs per operator (``rng = "lfsr"``), which row overflows first follows the
  exact race probability of independent Bernoulli rows, and cycles per pixel on realistic
  likelihoods match an ideal machine of independent streams (column-shared sources correlate
  the rows on purpose: ``tests/sources/test_sobol.py`` and docs/sources.md);
- how often ties happen, and what the tie rule changes.
"""

from __future__ import annotations

import itertools
import math
from functools import cache

import numba
import numpy as np
import pytest
from scipy import stats

from bayesmachine.hdl.machine.encoder import map_encoder_twin
from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.synthetic import synthetic_disparity_words
from bayesmachine.sim.ties import measure_ties

W = 10
ONE = 1 << W


@pytest.mark.parametrize("rng", ["lfsr", "lfsr-shared", "sobol"])
@pytest.mark.parametrize(
    "qs",
    [(512, 512), (100, 900), (ONE, 300), (700, 600, 800), (20, ONE), (1000, 1000, 1000)],
)
def test_and_of_operators_fires_at_the_product(qs: tuple[int, ...], rng: str) -> None:
    # Overflow needs n ones in n cycles (impossible for p < 1): the run times out after n cycles
    # and the counter holds the number of 1s of the row's stochastic bus.
    n = 200_000
    params = MachineParams(rows=2, columns=len(qs), counter_max=n - 1, max_cycles=n, words_per_beat=1,
                           seed=3, rng=rng)
    words = np.array([[qs, [0] * len(qs)]], np.int32)
    res = MachineModel(params).run(words)
    assert res.timeout[0] and res.counts[0, 1] == 0
    p = math.prod(q / ONE for q in qs)
    ones = int(res.counts[0, 0])
    assert abs(ones - n * p) <= 5 * math.sqrt(n * p * (1 - p)) + 1e-9, (ones, n * p)


def exact_winner_probabilities(
    rates: list[float], n_max: int, nomatch_row: bool, tie_break: str
) -> np.ndarray:
    """P(row i wins) for independent Bernoulli rows, by dynamic programming over counter states.

    From counters c, a cycle fires pattern f with probability prod(r_i^f_i (1 - r_i)^(1 - f_i));
    rows firing at c_i = n_max overflow (the MAP encoder picks among them), otherwise c += f.
    The all-zero pattern leaves the state unchanged, so it is divided out. No watchdog.
    """
    m = len(rates)

    @cache
    def win(counts: tuple[int, ...]) -> np.ndarray:
        total = np.zeros(m)
        stay = 0.0
        for fire in itertools.product((0, 1), repeat=m):
            pf = math.prod(r if f else 1 - r for r, f in zip(rates, fire, strict=True))
            if pf == 0:
                continue
            over = [f and c == n_max for f, c in zip(fire, counts, strict=True)]
            if any(over):
                total[map_encoder_twin(over, nomatch_row, tie_break)] += pf
            elif not any(fire):
                stay = pf
            else:
                total += pf * win(tuple(c + f for c, f in zip(counts, fire, strict=True)))
        return total / (1 - stay)

    return win((0,) * m)


RACES = [
    # (words per row, n_max, nomatch_row, tie_break)
    ([[512], [400]], 1, True, "nomatch-first"),
    ([[512], [400]], 1, True, "lowest-index"),
    ([[700, 600], [800, 500], [300, ONE]], 2, True, "nomatch-first"),
    ([[700, 600], [800, 500], [300, ONE]], 2, True, "lowest-index"),
    ([[900], [900], [600]], 1, False, "lowest-index"),
    ([[300, 900], [ONE, 250], [200, 700]], 2, False, "lowest-index"),
]


@pytest.mark.parametrize(("rows", "n_max", "nomatch_row", "tie_break"), RACES)
def test_first_overflow_follows_exact_race_probability(
    rows: list[list[int]], n_max: int, nomatch_row: bool, tie_break: str
) -> None:
    pixels = 20_000
    params = MachineParams(rows=len(rows), columns=len(rows[0]), counter_max=n_max, nomatch_row=nomatch_row,
                           tie_break=tie_break, words_per_beat=1, seed=11, rng="lfsr")
    words = np.repeat(np.array([rows], np.int32), pixels, axis=0)
    res = MachineModel(params).run(words)
    assert not res.timeout.any()
    rates = [math.prod(q / ONE for q in row) for row in rows]
    expected = exact_winner_probabilities(rates, n_max, nomatch_row, tie_break)
    observed = np.bincount(res.map, minlength=len(rows))
    keep = expected > 0
    assert observed[~keep].sum() == 0
    chi2 = stats.chisquare(observed[keep], expected[keep] * pixels)
    assert chi2.pvalue > 1e-4, (observed, expected * pixels)
    sigma = np.sqrt(pixels * expected * (1 - expected))
    assert (np.abs(observed - pixels * expected) <= 5 * sigma + 1e-9).all()


@numba.njit(cache=True)
def _ideal_machine(rates: np.ndarray, n_max: int, max_cycles: int, nomatch_first: bool, seed: int):
    """Independent Bernoulli rows (numpy's generator): (cycles, map) per pixel."""
    np.random.seed(seed)
    pixels, rows = rates.shape
    cycles = np.zeros(pixels, np.int64)
    winner = np.zeros(pixels, np.int64)
    counts = np.zeros(rows, np.int64)
    for p in range(pixels):
        counts[:] = 0
        k = 0
        w = -1
        while w < 0 and k < max_cycles:
            k += 1
            for r in range(rows):
                if np.random.random() < rates[p, r]:
                    if counts[r] == n_max:
                        if w < 0 or (nomatch_first and r == rows - 1):
                            w = r
                    else:
                        counts[r] += 1
        cycles[p] = k
        winner[p] = max(w, 0)
    return cycles, winner


def test_cycles_per_pixel_match_an_ideal_machine() -> None:
    params = MachineParams.for_disparity(80, rng="lfsr")
    pixels = 3000
    words = synthetic_disparity_words(params, pixels, np.random.default_rng(31))
    res = MachineModel(params).run(words)
    rates = np.prod(words / params.word_one, axis=2)
    cycles, winner = _ideal_machine(rates, params.counter_max, params.max_cycles, True, 5)
    a, b = res.cycles.astype(float), cycles.astype(float)
    bound = 5 * math.sqrt(a.var() / pixels + b.var() / pixels)
    print(f"\nmean cycles/pixel: machine {a.mean():.2f}, ideal {b.mean():.2f} (bound {bound:.2f}); "
          f"medians {np.median(a)}, {np.median(b)}")
    assert abs(a.mean() - b.mean()) < bound
    ks = stats.ks_2samp(a, b)
    assert ks.pvalue > 1e-3, ks
    # The decisions too: same fraction of no-match pixels and of MAP agreement with the argmax rate.
    nm_a, nm_b = (res.map == params.rows - 1).mean(), (winner == params.rows - 1).mean()
    assert abs(nm_a - nm_b) < 5 * math.sqrt(nm_a * (1 - nm_a) * 2 / pixels)
    best = rates.argmax(axis=1)
    agree_a, agree_b = (res.map == best).mean(), (winner == best).mean()
    assert abs(agree_a - agree_b) < 5 * math.sqrt(agree_a * (1 - agree_a) * 2 / pixels)


def test_tie_rule_measurement() -> None:
    params = MachineParams.for_disparity(80)
    words = synthetic_disparity_words(params, 1000, np.random.default_rng(41))
    m = measure_ties(params, words, np.random.default_rng(42))
    print(f"\nties: {m['ties']}/{m['pixels']} pixels ({100 * m['tie_fraction']:.1f} %), with the no-match "
          f"row: {m['nomatch_ties']} ({100 * m['nomatch_tie_fraction']:.1f} %); no-match decisions "
          f"lowest-index {m['nomatch_lowest_index']}, nomatch-first {m['nomatch_nomatch_first']}")
    assert 0 < m["nomatch_ties"] <= m["ties"] < m["pixels"]  # ties do happen on paper-like pixels
    # Only no-match ties change a decision, always towards no match.
    assert m["nomatch_nomatch_first"] - m["nomatch_lowest_index"] == m["nomatch_ties"]


def test_tie_rule_changes_nothing_but_the_map_of_nomatch_ties() -> None:
    # Same seed, same LFSR streams: the rule cannot change when a run ends or the counters, only
    # which of the rows overflowing together is reported.
    base = MachineParams.for_disparity(80)
    words = synthetic_disparity_words(base, 1500, np.random.default_rng(43))
    a = MachineModel(base).run(words)
    b = MachineModel(MachineParams.for_disparity(80, tie_break="lowest-index")).run(words)
    assert np.array_equal(a.cycles, b.cycles) and np.array_equal(a.counts, b.counts)
    differ = a.map != b.map
    assert (a.map[differ] == base.rows - 1).all()
    # ... and in those pixels the lower row also holds n_max (it overflowed in the last cycle).
    assert (b.counts[differ, b.map[differ]] == base.counter_max).all()
