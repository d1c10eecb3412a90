"""A naive-Bayes classifier's tables from counts, and its exact float64 decision on the same bins.

Rows are the classes. Per feature j its table ``P(bin | class)`` from the training counts with additive
(Laplace / Lidstone) smoothing, scikit-learn's ``CategoricalNB`` rule:

    P(x_j = t | c) = (N_jtc + alpha) / (N_c + alpha * n_j)

``N_jtc`` the training samples of class c whose feature j is in bin t, ``N_c`` those of class c,
``n_j`` feature j's number of bins; the prior ``P(c) = N_c / N`` (the class frequencies, unsmoothed, as
``CategoricalNB``'s with ``fit_prior``). ``alpha > 0`` keeps every entry above 0: no class is excluded by
one feature (a 0 would be a word that never fires, an infinite code). The exact decision is the MAP of
``log P(c) + sum_j log P(x_j | c)``, its posterior the normalized exponential.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bayesmachine.checks import as_int, as_real, shown
from bayesmachine.errors import ParameterError

__all__ = ["DEFAULT_ALPHA", "NaiveBayesTables", "check_alpha"]

DEFAULT_ALPHA = 1.0


def check_alpha(alpha: object) -> float:
    """``alpha`` as a float: TypeError for a non-number, ParameterError unless finite and > 0."""
    a = as_real("alpha", alpha)
    if not (math.isfinite(a) and a > 0):
        raise ParameterError(f"alpha must be a finite number > 0 (additive smoothing), got {shown(alpha)}",
                             "alpha")
    return a


@dataclass(frozen=True, eq=False)
class NaiveBayesTables:
    """The float64 tables of a classifier (module text).

    Attributes
    ----------
    prior : ndarray
        (classes,) P(c).
    likelihoods : tuple of ndarray
        Per feature (classes, bins_j) P(bin | c); every entry in (0, 1).
    alpha : float
    """

    prior: np.ndarray
    likelihoods: tuple[np.ndarray, ...]
    alpha: float

    @classmethod
    def from_counts(cls, bins: np.ndarray, labels: np.ndarray, classes: int, bin_counts: np.ndarray,
                    alpha: float) -> NaiveBayesTables:
        """The tables of training ``bins`` (n, features) int, ``labels`` (n,) in 0 .. classes - 1, feature
        j with ``bin_counts[j]`` bins."""
        alpha = check_alpha(alpha)
        classes = as_int("classes", classes, 1)
        b = np.asarray(bins, np.int64)
        y = np.asarray(labels, np.int64)
        if b.ndim != 2 or y.shape != (b.shape[0],) or b.shape[0] == 0:
            raise ValueError(f"bins (n, features) and labels (n,) of n >= 1 samples, got {b.shape} and "
                             f"{y.shape}")
        if y.min() < 0 or y.max() >= classes:
            raise ValueError(f"labels must be in 0 .. {classes - 1}")
        n_c = np.bincount(y, minlength=classes).astype(np.float64)
        tables = []
        for j, n_j in enumerate(np.asarray(bin_counts, np.int64)):
            if b[:, j].min() < 0 or b[:, j].max() >= n_j:
                raise ValueError(f"feature {j}'s bins must be in 0 .. {n_j - 1}")
            counts = np.zeros((classes, int(n_j)))
            np.add.at(counts, (y, b[:, j]), 1.0)
            tables.append((counts + alpha) / (n_c[:, None] + alpha * n_j))
        return cls(n_c / n_c.sum(), tuple(tables), alpha)

    @property
    def classes(self) -> int:
        return self.prior.size

    @property
    def features(self) -> int:
        return len(self.likelihoods)

    def factors(self, bins: np.ndarray) -> np.ndarray:
        """(n, classes, 1 + features) float64: each decision's prior and likelihood factors, the prior
        first (what the machine's operator columns multiply, before quantization)."""
        b = np.asarray(bins, np.int64)
        out = np.empty((b.shape[0], self.classes, 1 + self.features))
        out[:, :, 0] = self.prior
        for j, t in enumerate(self.likelihoods):
            out[:, :, 1 + j] = t[:, b[:, j]].T
        return out

    def log_joint(self, bins: np.ndarray) -> np.ndarray:
        """(n, classes) float64: log P(c) + sum_j log P(x_j | c)."""
        b = np.asarray(bins, np.int64)
        with np.errstate(divide="ignore"):
            out = np.broadcast_to(np.log(self.prior), (b.shape[0], self.classes)).copy()
        for j, t in enumerate(self.likelihoods):
            out += np.log(t)[:, b[:, j]].T
        return out

    def posterior(self, bins: np.ndarray) -> np.ndarray:
        """(n, classes) float64: the exact posterior on the bins."""
        lj = self.log_joint(bins)
        e = np.exp(lj - lj.max(axis=1, keepdims=True))
        return e / e.sum(axis=1, keepdims=True)

    def predict(self, bins: np.ndarray) -> np.ndarray:
        """(n,) int64: the exact MAP class (ties to the lowest index)."""
        return np.argmax(self.log_joint(bins), axis=1)
