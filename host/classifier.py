"""``BayesianMachineClassifier``: the machine as a scikit-learn classifier (docs/classifier.md).

``fit`` bins the features (``bayesmachine.classify.QuantileBins``), counts the tables
(``NaiveBayesTables``, ``CategoricalNB``'s smoothing) and builds the machine (``ClassifierMachine``);
``predict`` and ``predict_proba`` run the samples through a fresh engine (as after reset), so that the
same samples in the same order give the same decisions. Every parameter is checked in ``fit``
(scikit-learn's convention): a TypeError for a type, a ``ParameterError`` (a ValueError) naming the
parameter for a value.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

from bayesmachine.checks import type_name
from bayesmachine.classify import (
    DEFAULT_ALPHA,
    DEFAULT_BINS,
    ClassifierMachine,
    Decisions,
    NaiveBayesTables,
    QuantileBins,
)
from bayesmachine.errors import ParameterError
from bayesmachine.params import DEFAULT_COUNTER_MAX, DEFAULT_RNG, DEFAULT_SEED, DEFAULT_WORD_BITS
from bayesmachine.sim.engines import ENGINES, get_engine

__all__ = ["BayesianMachineClassifier", "decide", "expected_failed_checks"]


def decide(machine: ClassifierMachine, bins: np.ndarray, engine: str = "model", **options: Any) -> Decisions:
    """The decisions of ``bins`` (n, features) by ``machine`` on a fresh ``engine`` (as after reset; one of
    ``bayesmachine.sim.engines.ENGINES``, ``options`` its constructor's)."""
    with get_engine(engine, machine.params, **options) as e:
        r = e.run(machine.entries(bins))
    return machine.readout(r.map, r.counts, r.cycles, r.timeout)


def expected_failed_checks(estimator: BayesianMachineClassifier) -> dict[str, str]:
    """The checks of ``sklearn.utils.estimator_checks`` this estimator is expected to fail, with why
    (``check_estimator(est, expected_failed_checks=...)``)."""
    if estimator.integrator != "stochastic":
        return {}
    why = ("the stochastic machine's random source runs on from one decision to the next (as on chip), "
           "so a decision's readout depends on the decisions before it in the batch")
    return {"check_methods_subset_invariance": why, "check_methods_sample_order_invariance": why}


class BayesianMachineClassifier(ClassifierMixin, BaseEstimator):
    """A naive-Bayes classifier run on the Bayesian machine (docs/classifier.md).

    Parameters
    ----------
    integrator : str
        ``"stochastic"`` (overflow counters) or ``"log"`` (energy sums, argmin).
    counter_max, word_bits, rng, seed, max_cycles : machine options
        As ``MachineParams``'s (the stochastic integrator's only: counter max, random source, seed,
        watchdog; None: its default).
    bins : int
        The most quantile bins per feature (1 .. 256).
    alpha : float
        Additive smoothing of the tables, > 0 (``CategoricalNB``'s rule).
    fuse : int or None
        The features fused into this many energy-domain operator columns (default 1), or None: one
        operator column per feature plus a loaded prior column (at most 63 features).
    engine : str
        ``"model"``, ``"pysim"`` or ``"verilator"``: bit for bit the same decisions.

    Attributes
    ----------
    classes_ : ndarray
        The class labels, in the order of the machine's rows.
    n_features_in_ : int
    bins_ : QuantileBins
    tables_ : NaiveBayesTables
    machine_ : ClassifierMachine
    """

    def __init__(self, *, integrator: str = "stochastic", counter_max: int = DEFAULT_COUNTER_MAX,
                 word_bits: int = DEFAULT_WORD_BITS, rng: str = DEFAULT_RNG, seed: int = DEFAULT_SEED,
                 max_cycles: int | None = None, bins: int = DEFAULT_BINS, alpha: float = DEFAULT_ALPHA,
                 fuse: int | None = 1, engine: str = "model") -> None:
        self.integrator = integrator
        self.counter_max = counter_max
        self.word_bits = word_bits
        self.rng = rng
        self.seed = seed
        self.max_cycles = max_cycles
        self.bins = bins
        self.alpha = alpha
        self.fuse = fuse
        self.engine = engine


    def _machine_options(self) -> dict[str, Any]:
        options = {"integrator": self.integrator, "counter_max": self.counter_max,
                   "word_bits": self.word_bits, "rng": self.rng, "seed": self.seed}
        if self.max_cycles is not None:
            options["max_cycles"] = self.max_cycles
        return options

    def fit(self, X: Any, y: Any) -> BayesianMachineClassifier:
        """Bin ``X`` (n, features), count the tables of labels ``y`` and build the machine."""
        if not isinstance(self.engine, str):
            raise TypeError(f"engine must be one of {ENGINES}, not {type_name(self.engine)}")
        if self.engine not in ENGINES:
            raise ParameterError(f"engine must be one of {ENGINES}, got {self.engine!r}", "engine")
        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        self.classes_, labels = np.unique(y, return_inverse=True)
        self.bins_ = QuantileBins.fit(X, self.bins)
        self.tables_ = NaiveBayesTables.from_counts(self.bins_.transform(X), labels, self.classes_.size,
                                                    self.bins_.counts, self.alpha)
        self.machine_ = ClassifierMachine(tables=self.tables_, fuse=self.fuse,
                                          machine=self._machine_options())
        return self

    def decide(self, X: Any) -> Decisions:
        """The machine's ``Decisions`` of ``X``: MAP, readout, distribution, confidence,
        cycles."""
        check_is_fitted(self)
        X = validate_data(self, X, dtype=np.float64, reset=False)
        return decide(self.machine_, self.bins_.transform(X), self.engine)

    def predict(self, X: Any) -> np.ndarray:
        """The MAP class of each sample."""
        decisions = self.decide(X)  # checks the fit first
        return self.classes_[decisions.map]

    def predict_proba(self, X: Any) -> np.ndarray:
        """(n, classes): the distribution the machine's counters (or weights) read out."""
        return self.decide(X).proba

    def exact_proba(self, X: Any) -> np.ndarray:
        """(n, classes): the exact float64 naive-Bayes posterior on the same bins."""
        check_is_fitted(self)
        X = validate_data(self, X, dtype=np.float64, reset=False)
        return self.tables_.posterior(self.bins_.transform(X))
