"""bayesmachine.classify.estimator: the scikit-learn estimator (check_estimator, Pipeline, cross_val_score,
its checks in fit) and the engines' decisions bit for bit alike (pysim on a few decisions of a held-out
fold; Verilator on a whole fold, eda tier)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from sklearn.datasets import load_digits, load_iris
from sklearn.model_selection import StratifiedKFold, cross_val_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.estimator_checks import check_estimator

from bayesmachine import BayesianMachineClassifier
from bayesmachine.classify.estimator import expected_failed_checks
from bayesmachine.errors import ParameterError


@pytest.mark.parametrize("options", [{}, {"integrator": "log"}, {"fuse": None, "rng": "lfsr"}])
def test_check_estimator(options: dict) -> None:
    est = BayesianMachineClassifier(**options)
    expected = expected_failed_checks(est)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the skipped checks' warnings (pandas, the array API)
        results = check_estimator(est, expected_failed_checks=expected, on_fail=None)
    failed = [(r["check_name"], str(r["exception"])[:200]) for r in results if r["status"] == "failed"]
    assert not failed
    assert {r["check_name"] for r in results if r["status"] == "xfail"} == set(expected)
    assert sum(r["status"] == "passed" for r in results) >= 50


def test_the_stochastic_machine_names_its_expected_failures() -> None:
    assert set(expected_failed_checks(BayesianMachineClassifier())) == {
        "check_methods_subset_invariance", "check_methods_sample_order_invariance"}
    assert expected_failed_checks(BayesianMachineClassifier(integrator="log")) == {}


def test_pipeline_and_cross_val_score() -> None:
    x, y = load_iris(return_X_y=True)
    folds = StratifiedKFold(5, shuffle=True, random_state=0)
    scores = cross_val_score(make_pipeline(StandardScaler(), BayesianMachineClassifier()), x, y, cv=folds)
    assert scores.shape == (5,) and scores.mean() > 0.9


def test_predict_is_the_map_and_proba_agrees() -> None:
    x, y = load_iris(return_X_y=True)
    labels = np.array(["setosa", "versicolor", "virginica"])[y]
    est = BayesianMachineClassifier().fit(x, labels)
    d = est.decide(x)
    np.testing.assert_array_equal(est.predict(x), est.classes_[d.map])
    np.testing.assert_array_equal(est.classes_[np.argmax(est.predict_proba(x), axis=1)], est.predict(x))
    assert (d.cycles == 17).all()  # one fused column: the best class fires every cycle
    assert est.score(x, labels) > 0.9
    np.testing.assert_allclose(est.exact_proba(x).sum(axis=1), 1.0)


def test_the_fused_log_machine_is_the_argmin_of_the_codes() -> None:
    x, y = load_digits(return_X_y=True)
    est = BayesianMachineClassifier(integrator="log").fit(x[:1200], y[:1200])
    bins = est.bins_.transform(x[1200:])
    np.testing.assert_array_equal(est.decide(x[1200:]).map, est.machine_.energy_decision(bins))


@pytest.mark.parametrize(("options", "features", "error", "match"), [
    ({"engine": "spice"}, 4, ParameterError, "engine"),
    ({"engine": 3}, 4, TypeError, "engine"),
    ({"integrator": "analog"}, 4, ParameterError, "integrator"),
    ({"bins": 0}, 4, ParameterError, "bins"),
    ({"alpha": 0.0}, 4, ParameterError, "alpha"),
    ({"counter_max": 0}, 4, ParameterError, "counter_max"),
    ({"integrator": "log", "counter_max": 8}, 4, ParameterError, "counter_max: the stochastic integrator's"),
    ({"integrator": "log", "rng": "lfsr"}, 4, ParameterError, "rng"),
    ({"fuse": 5}, 4, ParameterError, "fuse"),
    ({"fuse": None}, 20, ParameterError, "16 operator columns"),  # sobol's limit: 20 features + the prior
    ({"fuse": None, "rng": "lfsr"}, 64, ParameterError, "65 operator columns"),
    ({"fuse": None, "integrator": "log"}, 64, ParameterError, "65 operator columns"),
])
def test_fit_checks_its_parameters(options: dict, features: int, error: type, match: str) -> None:
    rng = np.random.default_rng(0)
    x = rng.random((30, features))
    y = rng.integers(0, 2, 30)
    est = BayesianMachineClassifier(**options)
    with pytest.raises(error, match=match):
        est.fit(x, y)


def _held_out(load, options: dict):  # noqa: ANN001, ANN202
    x, y = load(return_X_y=True)
    train, test = next(StratifiedKFold(5, shuffle=True, random_state=0).split(x, y))
    est = BayesianMachineClassifier(**options).fit(x[train], y[train])
    return est, est.bins_.transform(x[test])


def _same(a, b) -> None:  # noqa: ANN001
    for field in ("map", "readout", "cycles", "timeout"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)


@pytest.mark.parametrize("options", [{}, {"integrator": "log"}, {"fuse": None, "rng": "lfsr-shared"}])
def test_pysim_decides_as_the_model(options: dict) -> None:
    est, bins = _held_out(load_iris, options)
    bins = bins[:4]  # pysim is slow: four decisions of the held-out fold
    _same(est.machine_.run(bins, "pysim"), est.machine_.run(bins, "model"))


@pytest.mark.eda
@pytest.mark.parametrize(("load", "options"), [
    (load_digits, {}), (load_digits, {"integrator": "log"}), (load_digits, {"fuse": 4}),
    (load_iris, {"fuse": None}), (load_iris, {"fuse": None, "integrator": "log"})])
def test_verilator_decides_as_the_model(load, options: dict, verilator_toolchain: dict,  # noqa: ANN001
                                        verilator_cache: Path) -> None:
    est, bins = _held_out(load, options)
    got = est.machine_.run(bins, "verilator", build_dir=verilator_cache)
    _same(got, est.machine_.run(bins, "model"))
