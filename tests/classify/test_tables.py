"""bayesmachine.classify.tables: CategoricalNB's smoothing rule, its exact decision and posterior."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.naive_bayes import CategoricalNB

from bayesmachine.classify.tables import NaiveBayesTables
from bayesmachine.errors import ParameterError


def test_counts_by_hand() -> None:
    # class 0: bins 0, 0, 1; class 1: bin 2; one feature of 3 bins, alpha 1
    t = NaiveBayesTables.from_counts(np.array([[0], [0], [1], [2]]), np.array([0, 0, 0, 1]), 2, [3], 1.0)
    np.testing.assert_allclose(t.prior, [0.75, 0.25])
    np.testing.assert_allclose(t.likelihoods[0], [[3 / 6, 2 / 6, 1 / 6], [1 / 4, 1 / 4, 2 / 4]])
    # bin 2: 0.75 / 6 = 0.25 * 2 / 4, a tie: the lowest index
    assert t.predict(np.array([[0], [2]])).tolist() == [0, 0]
    np.testing.assert_allclose(t.posterior(np.array([[2]])), [[0.5, 0.5]])


@pytest.mark.parametrize("alpha", [0.1, 1.0, 3.0])
def test_equals_categorical_nb(alpha: float) -> None:
    rng = np.random.default_rng(5)
    counts = np.array([3, 5, 2, 7])
    y = rng.integers(0, 3, 200)
    b = np.stack([(rng.integers(0, n, 200) + y * (j % 2)) % n for j, n in enumerate(counts)], axis=1)
    t = NaiveBayesTables.from_counts(b, y, 3, counts, alpha)
    nb = CategoricalNB(alpha=alpha, min_categories=counts).fit(b, y)
    test = np.stack([rng.integers(0, n, 50) for n in counts], axis=1)
    np.testing.assert_allclose(t.posterior(test), nb.predict_proba(test), rtol=1e-12)
    assert (t.predict(test) == nb.predict(test)).all()
    np.testing.assert_allclose(np.log(t.likelihoods[1]), nb.feature_log_prob_[1], rtol=1e-12)


def test_factors_prior_first() -> None:
    t = NaiveBayesTables.from_counts(np.array([[0, 1], [1, 0]]), np.array([0, 1]), 2, [2, 2], 1.0)
    f = t.factors(np.array([[1, 1]]))
    np.testing.assert_allclose(f[0], [[0.5, 1 / 3, 2 / 3], [0.5, 2 / 3, 1 / 3]])


@pytest.mark.parametrize("alpha", [0.0, -1.0, float("nan"), float("inf")])
def test_alpha_must_be_positive(alpha: float) -> None:
    with pytest.raises(ParameterError, match="alpha"):
        NaiveBayesTables.from_counts(np.zeros((2, 1), int), np.array([0, 1]), 2, [1], alpha)


def test_bad_counts() -> None:
    with pytest.raises(TypeError, match="alpha"):
        NaiveBayesTables.from_counts(np.zeros((2, 1), int), np.array([0, 1]), 2, [1], "1")
    with pytest.raises(ValueError, match="labels"):
        NaiveBayesTables.from_counts(np.zeros((2, 1), int), np.array([0, 2]), 2, [1], 1.0)
    with pytest.raises(ValueError, match="feature 0"):
        NaiveBayesTables.from_counts(np.ones((2, 1), int), np.array([0, 1]), 2, [1], 1.0)
