"""A naive-Bayes classifier on the Bayesian machine: bins, tables from counts, the machine's layout and
readout (pure NumPy), and the scikit-learn estimator, ``BayesianMachineClassifier`` (``.estimator``,
imported when asked for: it needs scikit-learn). docs/classifier.md."""

from __future__ import annotations

from typing import Any

from .bins import DEFAULT_BINS, MAX_BINS, QuantileBins
from .machine import ClassifierMachine, Decisions
from .tables import DEFAULT_ALPHA, NaiveBayesTables

__all__ = ["DEFAULT_ALPHA", "DEFAULT_BINS", "MAX_BINS", "BayesianMachineClassifier", "ClassifierMachine",
           "Decisions", "NaiveBayesTables", "QuantileBins"]


def __getattr__(name: str) -> Any:
    if name == "BayesianMachineClassifier":  # scikit-learn is imported now, not with the package
        from .estimator import BayesianMachineClassifier

        return BayesianMachineClassifier
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
