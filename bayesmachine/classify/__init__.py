"""A naive-Bayes classifier on the Bayesian machine: bins, tables from counts, the machine's layout and
readout (pure NumPy, docs/classifier.md). The scikit-learn estimator that runs it on an engine is
``bayesmachine.BayesianMachineClassifier`` (``bayesmachine.host.classifier``)."""

from .bins import DEFAULT_BINS, MAX_BINS, QuantileBins
from .machine import ClassifierMachine, Decisions
from .tables import DEFAULT_ALPHA, NaiveBayesTables

__all__ = ["DEFAULT_ALPHA", "DEFAULT_BINS", "MAX_BINS", "ClassifierMachine", "Decisions", "NaiveBayesTables",
           "QuantileBins"]
