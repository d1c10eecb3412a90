"""``bayesmachine classify`` (host/cli/classify.py): its report and figure, a CSV with --label, and bad
input as one error line, exit code 2, no output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bayesmachine.cli import main


def _error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["classify", "--help"]) == 0
    text = capsys.readouterr().out
    for flag in ("--label", "--folds", "--test-size", "--bins", "--alpha", "--fuse", "--integrator",
                 "--counter-max", "--engine"):
        assert flag in text
    assert "--prior" not in text and "--normalize-columns" not in text  # the classifier's own layout


def test_iris_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["classify", "iris", "--folds", "3", "-o", str(out)]) == 0
    assert "accuracy: machine" in capsys.readouterr().out
    r = json.loads((out / "report.json").read_text())
    assert (out / "reliability.png").stat().st_size > 0
    assert r["split"] == {"kind": "k-fold", "folds": 3, "seed": 0}
    assert (r["samples"], r["features"], r["classes"], r["operator_columns"]) == (150, 4, 3, 1)
    assert len(r["folds"]) == 3 and sum(f["test"] for f in r["folds"]) == 150
    assert set(r["accuracy"]) == {"machine", "exact_nb", "energy_nb", "categorical_nb", "gaussian_nb"}
    # CategoricalNB on the same bins and alpha is the exact naive Bayes
    assert r["accuracy"]["categorical_nb"] == r["accuracy"]["exact_nb"]
    assert r["cycles_per_decision"] == {"mean": 17.0, "std": 0.0, "max": 17}
    assert 0 <= r["confidence"]["machine"]["ece"] <= 1
    assert sum(b["count"] for b in r["confidence"]["machine"]["reliability"]) == 150
    assert r["machine"]["counter_max"] == 16 and r["machine"]["rows"] == 3


def test_csv_with_a_label_column(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    y = rng.integers(0, 2, 60)
    x = rng.normal(size=(60, 3)) + y[:, None] * 2.0
    path = tmp_path / "data.csv"
    rows = zip(x, y, strict=True)
    lines = ["a,kind,b,c"] + [f"{r[0]},{'yes' if c else 'no'},{r[1]},{r[2]}" for r, c in rows]
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    assert main(["classify", str(path), "--label", "kind", "--test-size", "0.25", "--integrator", "log",
                 "--fuse", "none", "--quiet", "-o", str(out)]) == 0
    r = json.loads((out / "report.json").read_text())
    assert r["labels"] == ["no", "yes"] and r["features"] == 3 and r["operator_columns"] == 4
    assert r["split"]["kind"] == "train-test" and r["folds"][0]["test"] == 15
    assert r["accuracy"]["machine"] > 0.8 and r["machine"]["integrator"] == "log"


@pytest.mark.parametrize(("argv", "words"), [
    (["nowhere"], "neither a bundled data set"),
    (["iris", "--label", "x"], "--label"),
    (["iris", "--folds", "3", "--test-size", "0.2"], "give one split"),
    (["iris", "--folds", "1"], "--folds"),
    (["iris", "--bins", "0"], "--bins"),
    (["iris", "--alpha", "0"], "--alpha"),
    (["iris", "--fuse", "9"], "--fuse"),
    (["iris", "--fuse", "0"], "--fuse"),
    (["iris", "--integrator", "log", "--counter-max", "8"], "--counter-max"),
    (["iris", "--counter-max", "0"], "--counter-max"),
    (["breast_cancer", "--fuse", "none"], "16 operator columns"),
    (["digits", "--fuse", "none", "--rng", "lfsr"], "65 operator columns"),
])
def test_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
                               words: str) -> None:
    out = tmp_path / "out"
    line = _error(capsys, ["classify", *argv, "-o", str(out)])
    assert words in line and "Traceback" not in line
    assert not (out / "report.json").exists()


@pytest.mark.parametrize(("text", "words"), [
    ("a,b\n1,x\n", "no column 'kind'"),
    ("a,kind\n1,x\nz,y\n", "line 3 column 'a': 'z' is not a finite number"),
    ("a,kind\n1,x\nnan,y\n", "line 3 column 'a'"),
    ("a,kind\n1,x\n2\n", "line 3: 1 fields"),
    ("", "empty"),
    ("a,kind\n", "no data rows"),
    ("kind\nx\n", "no feature column"),
    ("a,kind\n1,x\n2,x\n3,y\n", "the smallest class has 1 samples"),
])
def test_bad_csv_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str,
                             words: str) -> None:
    path = tmp_path / "d.csv"
    path.write_text(text)
    line = _error(capsys, ["classify", str(path), "--label", "kind", "-o", str(tmp_path / "out")])
    assert words in line


def test_a_csv_without_label(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "d.csv"
    path.write_text("a,kind\n1,x\n")
    assert "--label COLUMN" in _error(capsys, ["classify", str(path), "-o", str(tmp_path / "out")])
