"""``BayesianMachineClassifier``: the machine as a scikit-learn classifier (docs/classifier.md).

``fit`` bins the features (:class:`~.bins.QuantileBins`), counts the tables
(:class:`~.tables.NaiveBayesTables`, ``CategoricalNB``'s smoothing) and builds the machine
(:class:`~.machine.ClassifierMachine`);
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
from bayesmachine.errors import ParameterError
from bayesmachine.integrators import INTEGRATOR_KINDS
from bayesmachine.params import DEFAULT_WORD_BITS

from .bins import DEFAULT_BINS, QuantileBins
from .machine import ClassifierMachine, Decisions
from .tables import DEFAULT_ALPHA, NaiveBayesTables

__all__ = ["BayesianMachineClassifier", "expected_failed_checks"]


def expected_failed_checks(estimator: BayesianMachineClassifier) -> dict[str, str]:
    """The checks of ``sklearn.utils.estimator_checks`` this estimator is expected to fail, with why
    (``check_estimator(est, expected_failed_checks=...)``)."""
    kind = INTEGRATOR_KINDS.get(estimator.integrator) if isinstance(estimator.integrator, str) else None
    if kind is None or not kind.draws_numbers:
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
    counter_max, rng, seed, max_cycles : int, str, int, int or None
        The stochastic integrator's (``MachineParams``'s fields: counter max, random source, seed,
        watchdog); None: its default. Given to another integrator, refused in ``fit``.
    word_bits : int
        W, the comparator resolution (the words' and the exp table's).
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

    def __init__(self, *, integrator: str = "stochastic", counter_max: int | None = None,
                 word_bits: int = DEFAULT_WORD_BITS, rng: str | None = None, seed: int | None = None,
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
        given = {"counter_max": self.counter_max, "rng": self.rng, "seed": self.seed,
                 "max_cycles": self.max_cycles}
        return {"integrator": self.integrator, "word_bits": self.word_bits,
                **{k: v for k, v in given.items() if v is not None}}

    def fit(self, X: Any, y: Any) -> BayesianMachineClassifier:
        """Bin ``X`` (n, features), count the tables of labels ``y`` and build the machine."""
        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        self.classes_, labels = np.unique(y, return_inverse=True)
        self.bins_ = QuantileBins.fit(X, self.bins)
        self.tables_ = NaiveBayesTables.from_counts(self.bins_.transform(X), labels, self.classes_.size,
                                                    self.bins_.counts, self.alpha)
        self.machine_ = ClassifierMachine(tables=self.tables_, fuse=self.fuse,
                                          machine=self._machine_options())
        engines = tuple(self.machine_.params.kind.engines)
        if not isinstance(self.engine, str):
            raise TypeError(f"engine must be one of {engines}, not {type_name(self.engine)}")
        if self.engine not in engines:
            raise ParameterError(f"engine must be one of {engines}, got {self.engine!r}", "engine")
        return self

    def decide(self, X: Any) -> Decisions:
        """The machine's :class:`~.machine.Decisions` of ``X``: MAP, readout, distribution, confidence,
        cycles."""
        check_is_fitted(self)
        X = validate_data(self, X, dtype=np.float64, reset=False)
        return self.machine_.run(self.bins_.transform(X), self.engine)

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
