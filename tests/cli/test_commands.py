"""CLI smoke tests: run/reference/sweep on small crops with the model engine; clear errors."""

import json

import cv2
import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.models import DEFAULT_MODEL
from bayesmachine.params import STOCHASTIC_FIELDS

REPORT_KEYS = set(
    "engine counter_max pixels cycles_per_pixel_mean cycles_per_pixel_std cycles_per_pixel_p99 rms_error "
    "nomatch_f1 map_agreement seconds reference_seconds timeouts machine model "
    "machine_bad1 machine_bad2 sgbm_bad1 sgbm_bad2".split()
)


def test_run_on_bundled_crop(tmp_path):
    out = tmp_path / "out"
    # A 140x40 crop of Motorcycle with Dmax 40, the census 7x7 model (one pass: the default
    # census-lr's two would double the time): its output region keeps every 7x7 window inside the
    # image, (40-6) x (140-6-40) output pixels.
    rc = main(["run", "--crop", "300,200,140,40", "--dmax", "40", "--model", "census", "--counter-max", "8",
               "--quiet", "-o", str(out)])
    assert rc == 0
    report = json.loads((out / "report.json").read_text())
    assert REPORT_KEYS <= report.keys()
    assert report["engine"] == "model" and report["counter_max"] == 8 and report["pixels"] == 34 * 94
    assert report["machine"]["rows"] == 42 and report["model"]["dmax"] == 40
    res = np.load(out / "result.npz")
    assert res["map"].shape == (34, 94) and res["map"].dtype == np.int16
    assert res["counts"].shape == (34, 94, 42) and res["cycles"].shape == (34, 94)
    assert report["model_name"] == "census" and report["machine"]["prior"] == "neighbour"
    assert res["map"].min() >= -1 and res["map"].max() <= 40
    assert (out / "disparity.png").stat().st_size > 0


def _write_pair(tmp_path, width=50):
    left, right, gt = random_dot_stereogram(height=20, width=width, seed=4)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), cv2.cvtColor(right, cv2.COLOR_GRAY2BGR))  # colour is converted
    np.save(tmp_path / "gt.npy", gt)
    return tmp_path / "l.png", tmp_path / "r.png", tmp_path / "gt.npy"


def test_reference_command(tmp_path):
    left, right, _ = _write_pair(tmp_path)
    out = tmp_path / "ref.npz"
    assert (
        main(["reference", str(left), str(right), "--model", "paper", "--dmax", "16", "--sigma", "12", "-o",
              str(out), "--quiet"])
        == 0
    )
    ref = np.load(out)
    assert ref["posterior"].shape == (16, 50 - 4 - 16, 18) and ref["posterior"].dtype == np.float64
    np.testing.assert_allclose(ref["posterior"].sum(axis=-1), 1.0)
    assert ref["map"].dtype == np.int16 and ref["map"].shape == (16, 30)


def test_reference_output_name_gets_npz(tmp_path, capsys):
    left, right, _ = _write_pair(tmp_path)
    assert main(["reference", str(left), str(right), "--dmax", "8", "-o", str(tmp_path / "ref")]) == 0
    assert (tmp_path / "ref.npz").exists()
    assert str(tmp_path / "ref.npz") in capsys.readouterr().out


def test_run_on_a_crop_too_narrow_for_sgbm(tmp_path):
    """Width 98 leaves the (census) machine 12 columns with Dmax 80, but OpenCV's SGBM (96 disparities)
    cannot run: the report goes without SGBM figures instead of failing."""
    out = tmp_path / "narrow"
    assert main(["run", "--crop", "300,200,98,10", "--model", "census", "--quiet", "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["pixels"] == 4 * 12 and "machine_bad2" in report
    assert not any(k.startswith("sgbm_") for k in report)


def test_small_dmax_runs(tmp_path):
    """Dmax 0 and 3: 6 and 15 words per pixel, less than the default 16 lanes."""
    left, right, _ = _write_pair(tmp_path)
    for dmax in (0, 3):
        out = tmp_path / f"d{dmax}"
        # The default model (census-sgm): both passes at Dmax 0 and 3.
        assert main(["run", str(left), str(right), "--dmax", str(dmax), "--quiet", "-o", str(out)]) == 0
        report = json.loads((out / "report.json").read_text())
        assert report["model_name"] == DEFAULT_MODEL and report["machine"]["rows"] == dmax + 2
        assert report["right_pass_pixels"] > 0


def test_sweep_command(tmp_path):
    left, right, gt = _write_pair(tmp_path)
    out = tmp_path / "sweep"
    args = [
        "sweep",
        str(left),
        str(right),
        "--gt",
        str(gt),
        "--dmax",
        "16",
        "--counter-max",
        "1,4",
        "--model",
        "census",
        "--quiet",
    ]
    assert main([*args, "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert [p["counter_max"] for p in sweep["points"]] == [1, 4]
    assert all(
        "rms_error" in p and "nomatch_f1" in p and "cycles_per_pixel_std" in p for p in sweep["points"]
    )
    assert (out / "sweep.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["reference", "{l}", "{missing}"], "not found"),
        (["reference", "{l}", "{junk}"], "cannot read"),
        (["reference", "{l}", "{narrow}"], "differ in shape"),
        (["reference", "{l}", "{r}", "--dmax", "46"], "usable width"),
        (["run", "{l}", "{r}", "--crop", "40,0,20,10"], "outside"),
        (["run", "{l}"], "both LEFT and RIGHT"),
        (["run", "{l}", "{r}", "--counter-max", "0"], "counter_max"),
        (["reference", "{l}", "{r}", "--p0", "2"], "p0"),
        (["reference", "{l}", "{r}", "--p-nm0", "0"], "p_nm0 must be > 0"),
        (["run", "{l}", "{r}", "--dmax", "8", "--p-nm0", "0.0001"], "quantizes to 0"),
        (["run", "{l}", "{r}", "--dmax", "8", "-o", "{l}"], "not a directory"),
        (["run", "{l}", "{r}", "--engine", "model", "--waves", "1:2"], "--waves needs --engine verilator"),
    ],
)
def test_errors_are_one_clear_line(tmp_path, capsys, argv, message):
    left, right, _ = _write_pair(tmp_path)
    cv2.imwrite(str(tmp_path / "narrow.png"), np.zeros((20, 49), np.uint8))
    (tmp_path / "junk.png").write_bytes(b"junk")
    names = {
        "l": left,
        "r": right,
        "missing": tmp_path / "nope.png",
        "junk": tmp_path / "junk.png",
        "narrow": tmp_path / "narrow.png",
    }
    argv = [a.format(**{k: str(v) for k, v in names.items()}) for a in argv]
    if "-o" not in argv:
        argv += ["-o", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_run_cli_log(tmp_path) -> None:
    out = tmp_path / "out"
    assert main(["run", "--integrator", "log", "--crop", "200,200,200,60", "--model", "census", "--quiet",
                 "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["integrator"] == "log" and report["machine"]["integrator"] == "log"
    # No stochastic field with a value: none in its machine, null where a report names one.
    assert not set(STOCHASTIC_FIELDS) & set(report["machine"]), report["machine"]
    assert (report["rng"], report["counter_max"], report["samples_per_clock"]) == (None, None, None)
    # Measured on this crop (the model engine, the weights read as the counters are).
    assert report["pixels"] == 6156
    assert report["machine_bad2"] == pytest.approx(0.15407, abs=1e-4)
    assert report["confidence"]["machine"]["ece"] == pytest.approx(0.13309, abs=1e-4)
    assert report["cycles_per_pixel_mean"] == pytest.approx(1.9912, abs=1e-3)
    assert (out / "confidence.png").stat().st_size > 0 and (out / "calibration.png").stat().st_size > 0
    assert np.load(out / "result.npz")["counts"].max() == 1024


def test_emit_log_machine(tmp_path, capsys) -> None:
    assert main(["emit", "--integrator", "log", "--model", "paper", "--dmax", "4", "-o",
                 str(tmp_path / "log.il")]) == 0
    out = capsys.readouterr().out
    assert "integrator: log" in out and "9-bit energy codes" in out and "random source" not in out
    assert (tmp_path / "log.il").stat().st_size > 0


def test_sweep_integrator_axis(tmp_path) -> None:
    """sweep --integrator stochastic,log: a grid axis, one point per integrator."""
    out = tmp_path / "sweep"
    assert main(["sweep", "--integrator", "stochastic,log", "--counter-max", "8", "--crop", "250,200,80,20",
                 "--dmax", "16", "--model", "paper", "--quiet", "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    points = sweep["points"]
    # The log machine's id names no random source or counter max: it has neither.
    assert [p["id"] for p in points] == ["paper_sobol_cm8_integratorstochastic", "paper_integratorlog"]
    # What every point shares: no stochastic field (the log point has none), each the stochastic point's.
    assert not set(STOCHASTIC_FIELDS) & set(sweep["machine"]), sweep["machine"]
    assert not set(STOCHASTIC_FIELDS) & set(points[1].get("machine", {}))
    assert {"seed", "lfsr_bits", "max_cycles"} <= set(points[0]["machine"])
    assert points[1]["grid"]["seed"] is None and points[1]["grid"]["lfsr_bits"] is None
