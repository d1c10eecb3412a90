"""bayesmachine.classify.machine: the two layouts' entries, the machine's parameters, the readout."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.classify.machine import ClassifierMachine
from bayesmachine.classify.tables import NaiveBayesTables
from bayesmachine.columns.energy import energy_codes, exp_table
from bayesmachine.errors import ParameterError


def _tables(features: int = 3, classes: int = 3, seed: int = 0) -> NaiveBayesTables:
    rng = np.random.default_rng(seed)
    counts = np.full(features, 4)
    y = rng.integers(0, classes, 60)
    b = np.stack([(rng.integers(0, 2, 60) + y) % 4 for _ in range(features)], axis=1)
    return NaiveBayesTables.from_counts(b, y, classes, counts, 1.0)


def test_fused_words_are_the_exp_table_at_the_summed_codes() -> None:
    t = _tables()
    m = ClassifierMachine(tables=t, fuse=1)
    bins = np.array([[0, 1, 2], [3, 3, 0]])
    s = energy_codes(t.prior).astype(int) + sum(energy_codes(t.likelihoods[j][:, bins[:, j]].T).astype(int)
                                                for j in range(3))
    d = s - s.min(axis=1, keepdims=True)
    x = exp_table(10)
    np.testing.assert_array_equal(m.entries(bins)[:, :, 0], x[np.minimum(d, x.size - 1)])
    assert (m.entries(bins).max(axis=1) == 1024).all()  # the best class's word is 2^W
    p = m.params
    assert (p.rows, p.columns, p.prior, p.normalize, p.nomatch_row) == (3, 1, "uniform", False, False)
    log = ClassifierMachine(tables=t, fuse=1, machine={"integrator": "log"})
    np.testing.assert_array_equal(log.entries(bins)[:, :, 0], d)
    np.testing.assert_array_equal(log.energy_decision(bins), np.argmin(s, axis=1))


def test_two_fused_columns_split_the_features_in_order() -> None:
    t = _tables(features=5)
    m = ClassifierMachine(tables=t, fuse=2, machine={"integrator": "log"})
    assert [g.tolist() for g in m.groups] == [[0, 1, 2], [3, 4]]
    bins = np.array([[0, 1, 2, 3, 1]])
    s1 = sum(energy_codes(t.likelihoods[j][:, bins[0, j]]).astype(int) for j in (3, 4))
    np.testing.assert_array_equal(m.entries(bins)[0, :, 1], s1 - s1.min())


def test_one_column_per_feature_quantizes_each_table() -> None:
    t = _tables()
    m = ClassifierMachine(tables=t, fuse=None, machine={"rng": "lfsr"})
    bins = np.array([[0, 1, 2]])
    w = m.entries(bins)
    assert w.shape == (1, 3, 4)
    np.testing.assert_array_equal(w[0, :, 0], np.floor(t.prior * 1024 + 0.5))
    np.testing.assert_array_equal(w[0, :, 2], np.floor(t.likelihoods[1][:, 1] * 1024 + 0.5))
    p = m.params
    assert (p.columns, p.prior, p.normalize, p.timeout_answer) == (3, "loaded", True, "leading")
    log = ClassifierMachine(tables=t, fuse=None, machine={"integrator": "log"})
    np.testing.assert_array_equal(log.entries(bins)[0, :, 1], energy_codes(t.likelihoods[0][:, 0]))
    # the log machine draws no random number: more than sobol's 16 operator columns
    wide = ClassifierMachine(tables=_tables(features=40), fuse=None, machine={"integrator": "log"})
    assert wide.params.operator_columns == 41


def test_layout_limits() -> None:
    with pytest.raises(ParameterError, match="65 operator columns"):
        ClassifierMachine(tables=_tables(features=64), fuse=None, machine={"rng": "lfsr"})
    with pytest.raises(ParameterError, match="fuse"):
        ClassifierMachine(tables=_tables(features=2), fuse=3)
    with pytest.raises(ParameterError, match="fuse"):
        ClassifierMachine(tables=_tables(features=2), fuse=0)
    with pytest.raises(TypeError, match="fuse"):
        ClassifierMachine(tables=_tables(features=2), fuse=1.5)
    with pytest.raises(ParameterError, match="normalize"):
        ClassifierMachine(tables=_tables(), machine={"normalize": True})
    with pytest.raises(ParameterError, match="seed: the stochastic integrator's"):
        ClassifierMachine(tables=_tables(), machine={"integrator": "log", "seed": 3})
    with pytest.raises(TypeError, match="tables"):
        ClassifierMachine(tables=None)


def test_readout_counts_the_overflowing_one() -> None:
    m = ClassifierMachine(tables=_tables(), fuse=1)
    d = m.readout(np.array([1, 0]), np.array([[16, 16, 3], [2, 5, 5]]), np.array([17, 900]),
                  np.array([False, True]))
    # a run that overflowed: its MAP row held counter max + 1 ones; a timeout: the counters as they are
    np.testing.assert_allclose(d.proba, [[16 / 36, 17 / 36, 3 / 36], [2 / 12, 5 / 12, 5 / 12]])
    np.testing.assert_allclose(d.confidence, [17 / 36, 2 / 12])
    log = ClassifierMachine(tables=_tables(), fuse=1, machine={"integrator": "log"})
    d = log.readout(np.array([2]), np.array([[0, 512, 1024]]), np.array([1]), np.array([False]))
    np.testing.assert_allclose(d.proba, [[0, 1 / 3, 2 / 3]])
