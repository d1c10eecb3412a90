"""The classifier's study (``bayesmachine classify``): a data set, a seeded split, and per fold the
machine beside the exact naive Bayes on the same bins, scikit-learn's ``CategoricalNB`` (the same bins,
the same ``alpha``) and ``GaussianNB`` (the raw features); the cycles per decision and the calibration
of the machine's confidence (``host.confidence``'s ECE and reliability table). docs/classifier.md.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .confidence import ECE_BINS, expected_calibration_error, reliability_table

__all__ = ["BUNDLED_DATASETS", "Dataset", "HeldOut", "check_top_run", "held_out", "load_dataset",
           "split_folds", "study", "save_reliability_figure", "top_cycles"]

# scikit-learn's bundled data sets (shipped in its wheel: no download).
BUNDLED_DATASETS = ("digits", "iris", "wine", "breast_cancer")
# The methods of a fold, in the report's order.
METHODS = ("machine", "exact_nb", "energy_nb", "categorical_nb", "gaussian_nb")


@dataclass(frozen=True, eq=False)
class Dataset:
    """Samples ``x`` (n, features) float64, labels ``y`` (n,), what they are (``source``)."""

    x: np.ndarray
    y: np.ndarray
    source: str
    feature_names: tuple[str, ...]


def load_dataset(data: str, label: str | None = None) -> Dataset:
    """A bundled data set by name, or a CSV file with a header row whose column ``label`` holds the
    classes (every other column a number)."""
    if data in BUNDLED_DATASETS:
        if label is not None:
            raise ValueError(f"--label: it names a CSV file's label column; {data!r} is a bundled data set")
        import sklearn.datasets

        bunch = getattr(sklearn.datasets, f"load_{data}")()
        names = tuple(str(n) for n in getattr(bunch, "feature_names", range(bunch.data.shape[1])))
        return Dataset(np.asarray(bunch.data, np.float64), np.asarray(bunch.target), f"{data} (scikit-learn)",
                       names)
    path = Path(data)
    if not path.suffix.lower() == ".csv" and not path.exists():
        raise ValueError(f"{data!r}: neither a bundled data set ({', '.join(BUNDLED_DATASETS)}) nor a CSV "
                         "file")
    if label is None:
        raise ValueError(f"{data}: a CSV file needs --label COLUMN, the column of its classes")
    return _read_csv(path, label)


def _read_csv(path: Path, label: str) -> Dataset:
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise ValueError(f"{path}: empty, no header row")
    header = [h.strip() for h in rows[0]]
    if label not in header:
        raise ValueError(f"{path}: no column {label!r} (--label); its columns: {', '.join(header)}")
    if len(header) < 2:
        raise ValueError(f"{path}: no feature column beside the label {label!r}")
    li = header.index(label)
    body = [(n, r) for n, r in enumerate(rows[1:], start=2) if any(c.strip() for c in r)]
    if not body:
        raise ValueError(f"{path}: no data rows after the header")
    x = np.empty((len(body), len(header) - 1))
    y = []
    for i, (n, r) in enumerate(body):
        if len(r) != len(header):
            raise ValueError(f"{path} line {n}: {len(r)} fields, the header has {len(header)}")
        values = [c.strip() for k, c in enumerate(r) if k != li]
        for k, v in enumerate(values):
            try:
                x[i, k] = float(v)
            except ValueError:
                x[i, k] = math.nan
            if not math.isfinite(x[i, k]):
                column = [h for h in header if h != label][k] if header.count(label) == 1 else k
                raise ValueError(f"{path} line {n} column {column!r}: {v!r} is not a finite number")
        y.append(r[li].strip())
    names = tuple(h for k, h in enumerate(header) if k != li)
    return Dataset(x, np.asarray(y), str(path), names)


def split_folds(y: np.ndarray, folds: int | None, test_size: float | None,
                seed: int) -> list[tuple[Any, Any]]:
    """(train, test) index pairs: a stratified shuffled k-fold, or one stratified train/test split."""
    from sklearn.model_selection import StratifiedKFold, StratifiedShuffleSplit

    if test_size is not None:
        splitter: Any = StratifiedShuffleSplit(1, test_size=test_size, random_state=seed)
    else:
        splitter = StratifiedKFold(folds, shuffle=True, random_state=seed)
    _, counts = np.unique(y, return_counts=True)
    need = 2 if test_size is not None else folds
    if counts.min() < need:  # type: ignore[operator]
        raise ValueError(f"the smallest class has {counts.min()} samples: a stratified split into "
                         f"{need} parts needs at least {need} of each class")
    return list(splitter.split(np.zeros((y.size, 1)), y))


def _fold(data: Dataset, train: np.ndarray, test: np.ndarray, options: Mapping[str, Any]) -> dict[str, Any]:
    from sklearn.naive_bayes import CategoricalNB, GaussianNB

    from bayesmachine.classify.estimator import BayesianMachineClassifier

    est = BayesianMachineClassifier(**options).fit(data.x[train], data.y[train])
    labels = np.searchsorted(est.classes_, data.y[test])
    bins_train, bins = est.bins_.transform(data.x[train]), est.bins_.transform(data.x[test])
    d = est.decide(data.x[test])
    cat = CategoricalNB(alpha=est.alpha, min_categories=est.bins_.counts).fit(bins_train, data.y[train])
    exact = est.tables_.predict(bins)
    predicted = {"machine": d.map, "exact_nb": exact, "energy_nb": est.machine_.energy_decision(bins),
                 "categorical_nb": np.searchsorted(est.classes_, cat.predict(bins)),
                 "gaussian_nb": np.searchsorted(est.classes_, GaussianNB().fit(data.x[train], data.y[train])
                                                .predict(data.x[test]))}
    exact_p = est.tables_.posterior(bins)
    return {"est": est, "labels": labels, "decisions": d,
            "exact_confidence": exact_p[np.arange(exact.size), exact], "exact": exact,
            "figures": {"train": int(train.size), "test": int(test.size),
                        **{f"{m}_accuracy": float(np.mean(p == labels)) for m, p in predicted.items()},
                        "machine_exact_agreement": float(np.mean(d.map == exact)),
                        "cycles_per_decision_mean": float(d.cycles.mean()), "timeouts": int(d.timeout.sum())}}


def _calibration(confidence: np.ndarray, good: np.ndarray) -> dict[str, Any]:
    return {"ece": expected_calibration_error(confidence, good), "bins": ECE_BINS,
            "mean_confidence": float(confidence.mean()), "accuracy": float(good.mean()),
            "reliability": reliability_table(confidence, good)}


def study(data: Dataset, splits: list[tuple[Any, Any]], options: Mapping[str, Any]) -> dict[str, Any]:
    """The report of the machine ``options`` (``BayesianMachineClassifier``'s) over ``splits``."""
    start = time.perf_counter()
    runs = [_fold(data, train, test, options) for train, test in splits]
    figures = [r["figures"] for r in runs]
    cycles = np.concatenate([r["decisions"].cycles for r in runs])
    good = np.concatenate([r["decisions"].map == r["labels"] for r in runs])
    exact_good = np.concatenate([r["exact"] == r["labels"] for r in runs])
    first = runs[0]["est"]
    accuracy = {m: float(np.mean([f[f"{m}_accuracy"] for f in figures])) for m in METHODS}
    return {
        "data": data.source, "samples": int(data.x.shape[0]), "features": int(data.x.shape[1]),
        "classes": int(first.classes_.size),
        "labels": [v.item() if hasattr(v, "item") else v for v in first.classes_],
        "classifier": {k: options[k] for k in ("bins", "alpha", "fuse", "engine") if k in options},
        "machine": first.machine_.params.to_dict(complete=True),
        "operator_columns": first.machine_.params.operator_columns,
        "bins_per_feature": {"min": int(first.bins_.counts.min()), "max": int(first.bins_.counts.max()),
                             "mean": float(first.bins_.counts.mean())},
        "folds": figures,
        "accuracy": accuracy,
        "accuracy_std": {m: float(np.std([f[f"{m}_accuracy"] for f in figures])) for m in METHODS},
        "machine_minus_exact_points": 100.0 * (accuracy["machine"] - accuracy["exact_nb"]),
        "cycles_per_decision": {"mean": float(cycles.mean()), "std": float(cycles.std()),
                                "max": int(cycles.max())},
        "load_beats_per_decision": first.machine_.params.beats_per_pixel,
        "confidence": {
            "machine": _calibration(np.concatenate([r["decisions"].confidence for r in runs]), good),
            "exact_nb": _calibration(np.concatenate([r["exact_confidence"] for r in runs]), exact_good)},
        "seconds": time.perf_counter() - start,
    }


def save_reliability_figure(path: str | Path, report: Mapping[str, Any]) -> None:
    """The reliability diagram of the machine's and the exact naive Bayes's confidence (the observed
    accuracy against the mean confidence per bin)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4.5), layout="constrained")
    ax.plot([0, 1], [0, 1], color="gray", linestyle=":", label="perfectly calibrated")
    for key, style, name in (("machine", "o-", "machine"), ("exact_nb", "s--", "exact naive Bayes")):
        figs = report["confidence"][key]
        table = [r for r in figs["reliability"] if r["count"]]
        ax.plot([r["predicted"] for r in table], [r["observed"] for r in table], style,
                label=f"{name} (ECE {figs['ece']:.3f})")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("confidence of the MAP class (mean per bin)")
    ax.set_ylabel("observed accuracy")
    bins = report["confidence"]["machine"]["bins"]
    ax.set_title(f"{report['data']}: reliability, {bins} bins", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.savefig(path, dpi=100)
    plt.close(fig)


@dataclass(frozen=True, eq=False)
class HeldOut:
    """The fused classifier (one energy column) fitted on fold 0 of a data set's stratified 5-fold split
    (split seed 0) and that fold's held-out observations: what the classifier top is measured on
    (``benchmarks/bench_classifier_*.py``, ``synth --top classifier``)."""

    dataset: str
    machine: Any  # the ClassifierMachine
    bins: int  # rows of each likelihood memory: the most bins of a feature
    observed: np.ndarray  # (decisions, features) bins


def held_out(dataset: str, *, bins: int, machine: Mapping[str, Any] | None = None,
             decisions: int | None = None) -> HeldOut:
    """``dataset`` (:func:`load_dataset`'s) binned into at most ``bins`` bins per feature, its tables
    counted on fold 0's training samples (the default ``alpha``), the machine of the options ``machine``
    (``classify.machine.MACHINE_FIELDS``); the first ``decisions`` held-out samples (None: all)."""
    from bayesmachine.classify import DEFAULT_ALPHA, ClassifierMachine, NaiveBayesTables, QuantileBins

    data = load_dataset(dataset)
    train, test = split_folds(data.y, 5, None, 0)[0]
    classes, labels = np.unique(data.y, return_inverse=True)
    quantile = QuantileBins.fit(data.x[train], bins)
    tables = NaiveBayesTables.from_counts(quantile.transform(data.x[train]), labels[train], classes.size,
                                          quantile.counts, DEFAULT_ALPHA)
    return HeldOut(dataset, ClassifierMachine(tables=tables, fuse=1, machine=machine),
                   int(quantile.counts.max()), quantile.transform(data.x[test][:decisions]))


def check_top_run(held: HeldOut, result: Any, engine: str) -> None:
    """``result`` (a ``MachineResult`` of the classifier top under ``engine``) against the model's
    decisions of the same observations: MAP, counters or weights, cycles; ValueError if any differs."""
    want = held.machine.run(held.observed, "model")
    for what, got, exp in (("MAP", result.map, want.map), ("readout", result.counts, want.readout),
                           ("cycles", result.cycles, want.cycles)):
        if not np.array_equal(got, exp):
            raise ValueError(f"{held.dataset}: the classifier top under {engine} differs from the model "
                             f"({what})")


def top_cycles(held: HeldOut) -> dict[str, Any]:
    """The classifier top's wall cycles per decision under pysim (``sim.classifier_top``): its tables
    loaded, then ``held``'s observations back to back, from the first observation taken to the last
    result; every decision checked against the model's (:func:`check_top_run`)."""
    from bayesmachine.sim.classifier_top import run_classifier_top

    run = run_classifier_top(held.machine, held.observed, held.bins)
    check_top_run(held, run.result, "pysim")
    n = len(held.observed)
    return {"dataset": held.dataset, "decisions": n, "cycles_per_decision": float(run.result.cycles.mean()),
            "wall_cycles_per_decision": run.wall_cycles / n}
