# amaranth: UnusedElaboratable=no
"""bayesmachine.hdl.classifier (and sim/classifier_top.py, its simulation): the classifier top under pysim
decides as the model (its twin, ClassifierMachine.run), its tables and then the bins in its load stream;
emit --top classifier."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.datasets import load_digits, load_iris
from sklearn.model_selection import StratifiedKFold

from bayesmachine import BayesianMachineClassifier
from bayesmachine.classify.machine import ClassifierMachine
from bayesmachine.classify.tables import NaiveBayesTables
from bayesmachine.errors import ParameterError
from bayesmachine.hdl.classifier import ClassifierTop
from bayesmachine.sim.classifier_top import load_beats, run_beats, run_classifier_top


def run_top(machine: ClassifierMachine, observed: np.ndarray, bins: int):  # noqa: ANN201
    return run_classifier_top(machine, observed, bins).result


def _held_out(load, options: dict, n: int):  # noqa: ANN001, ANN202
    x, y = load(return_X_y=True)
    train, test = next(StratifiedKFold(5, shuffle=True, random_state=0).split(x, y))
    est = BayesianMachineClassifier(**options).fit(x[train], y[train])
    return est.machine_, est.bins_.transform(x[test][:n]), int(est.bins_.counts.max())


@pytest.mark.parametrize(("load", "options", "n"), [
    (load_iris, {}, 8), (load_iris, {"integrator": "log"}, 8), (load_digits, {"bins": 8}, 3)])
def test_the_top_decides_as_the_model(load, options: dict, n: int) -> None:  # noqa: ANN001
    machine, observed, bins = _held_out(load, options, n)
    got = run_top(machine, observed, bins)
    want = machine.run(observed, "model")
    np.testing.assert_array_equal(got.map, want.map)
    np.testing.assert_array_equal(got.counts, want.readout)
    np.testing.assert_array_equal(got.cycles, want.cycles)


def test_tables_loaded_again_hold_for_the_observations_after_them() -> None:
    x, y = load_iris(return_X_y=True)
    (a_train, test), (b_train, _) = list(StratifiedKFold(5, shuffle=True, random_state=0).split(x, y))[:2]
    a = BayesianMachineClassifier().fit(x[a_train], y[a_train])
    b = BayesianMachineClassifier(alpha=5.0).fit(x[b_train], y[b_train])
    assert a.machine_.params == b.machine_.params and (a.bins_.counts == b.bins_.counts).all()
    observed = a.bins_.transform(x[test][:4])
    beats = load_beats(a.machine_, 4, observed)[0] + load_beats(b.machine_, 4, observed)[0]
    top = ClassifierTop(params=a.machine_.params, features=4, bins=4)
    got = run_beats(top, beats, 8).result
    # the machine's random source runs on across the second table set, as in one model run
    engine = a.machine_.params.kind.engine_class("model")(a.machine_.params)
    want = engine.run(np.concatenate([a.machine_.entries(observed), b.machine_.entries(observed)]))
    np.testing.assert_array_equal(got.map, want.map)
    np.testing.assert_array_equal(got.counts, want.counts)
    assert not (a.machine_.entries(observed) == b.machine_.entries(observed)).all()


def test_more_classes_than_a_beat_holds() -> None:
    rng = np.random.default_rng(2)
    y = np.arange(200) % 20
    b = np.stack([(y + rng.integers(0, 2, 200)) % 3, rng.integers(0, 3, 200)], axis=1)
    machine = ClassifierMachine(tables=NaiveBayesTables.from_counts(b, y, 20, [3, 3], 1.0))
    assert machine.params.beats_per_pixel == 2  # 20 words, 16 per beat
    observed = np.array([[0, 1], [2, 2], [1, 0]])
    got = run_top(machine, observed, 3)
    want = machine.run(observed, "model")
    np.testing.assert_array_equal(got.map, want.map)
    np.testing.assert_array_equal(got.counts, want.readout)


def test_the_top_holds_one_fused_column() -> None:
    t = NaiveBayesTables.from_counts(np.array([[0], [1]]), np.array([0, 1]), 2, [2], 1.0)
    per_feature = ClassifierMachine(tables=t, fuse=None, machine={"rng": "lfsr"})
    with pytest.raises(ParameterError, match="one fused energy column"):
        ClassifierTop(params=per_feature.params, features=1, bins=2)
    with pytest.raises(TypeError, match="MachineParams"):
        ClassifierTop(params=None, features=1, bins=2)
    with pytest.raises(ParameterError, match="bins"):
        ClassifierTop(params=ClassifierMachine(tables=t).params, features=1, bins=0)


def test_emit_the_classifier_top(tmp_path, capsys) -> None:  # noqa: ANN001
    from bayesmachine.cli import main

    out = tmp_path / "classifier.il"
    assert main(["emit", "--top", "classifier", "--classes", "10", "--features", "64", "--bins", "8",
                 "-o", str(out)]) == 0
    text = out.read_text()
    assert "likelihood63" in text and "exp_table" in text
    assert "64 likelihood memories of 8 rows x 10 classes" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "words"), [
    (["--top", "classifier", "--classes", "3", "--features", "4"], "needs --bins"),
    (["--top", "classifier", "--classes", "3", "--features", "4", "--bins", "4", "--prior", "loaded"],
     "--prior: the classifier top decides"),
    (["--classes", "3"], "--classes: only with --top classifier"),
    (["--top", "classifier", "--classes", "3", "--features", "4", "--bins", "300"], "--bins"),
])
def test_emit_refuses(tmp_path, capsys, argv: list[str], words: str) -> None:  # noqa: ANN001
    from bayesmachine.cli import main

    out = tmp_path / "x.il"
    assert main(["emit", *argv, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
    assert not out.exists()
