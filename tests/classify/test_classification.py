"""bayesmachine.host.classification: data sets, the seeded splits and the study's figures."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.host.classification import BUNDLED_DATASETS, load_dataset, split_folds, study


@pytest.mark.parametrize(("name", "shape"), [("digits", (1797, 64)), ("iris", (150, 4)), ("wine", (178, 13)),
                                             ("breast_cancer", (569, 30))])
def test_bundled(name: str, shape: tuple[int, int]) -> None:
    d = load_dataset(name)
    assert d.x.shape == shape and d.y.shape == (shape[0],) and len(d.feature_names) == shape[1]
    assert name in BUNDLED_DATASETS


def test_splits_are_seeded_and_stratified() -> None:
    y = load_dataset("iris").y
    a, b = split_folds(y, 5, None, 3), split_folds(y, 5, None, 3)
    assert all((ta == tb).all() for (_, ta), (_, tb) in zip(a, b, strict=True))
    assert not (split_folds(y, 5, None, 4)[0][1] == a[0][1]).all()
    tests = np.concatenate([t for _, t in a])
    assert sorted(tests.tolist()) == list(range(150))
    assert all(np.bincount(y[t]).tolist() == [10, 10, 10] for _, t in a)
    (train, test), = split_folds(y, None, 0.2, 0)
    assert (train.size, test.size) == (120, 30)


def test_study_figures() -> None:
    d = load_dataset("wine")
    r = study(d, split_folds(d.y, 3, None, 0), {"integrator": "log", "bins": 4})
    assert [f["test"] for f in r["folds"]] == [60, 59, 59]
    mean = np.mean([f["machine_accuracy"] for f in r["folds"]])
    assert r["accuracy"]["machine"] == pytest.approx(mean)
    assert r["machine_minus_exact_points"] == pytest.approx(100 * (mean - r["accuracy"]["exact_nb"]))
    assert r["bins_per_feature"]["max"] == 4 and r["classifier"]["bins"] == 4
    assert r["cycles_per_decision"]["mean"] == 1.0  # the log machine: one decision per clock
