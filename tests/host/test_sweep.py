"""Sweeps over datasets on Dask (issue 20): a LocalCluster of 2 workers on a tiny synthetic dataset,
a raising task reported with its pair and point, a killed sweep resumed to the same sweep.json,
a scheduler that does not answer, the grid, and the per-worker cache."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from bayesmachine.cli import build_parser, main
from bayesmachine.host import sweep as sweep_mod
from bayesmachine.host.sweep import CACHE_STATS, strip_timings, sweep_points
from bayesmachine.models import DEFAULT_MODEL

from .test_datasets import middlebury2014, stereo

# The census model: one pass (the default model, census-sgm, runs two).
SMALL = ["--dmax", "8", "--model", "census", "--quiet"]


def load(out: Path) -> dict:
    return json.loads((out / "sweep.json").read_text())


@pytest.mark.parametrize("processes", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_dataset_sweep_on_two_workers_reports_a_raising_task(tmp_path, capsys, monkeypatch,
                                                           processes) -> None:
    """``--workers 2``: a LocalCluster of two workers (threads in the default suite: two worker processes
    cost ~10 s of start-up, imports and shut-down on a loaded machine; processes under -m slow)."""
    local_cluster = sweep_mod._local_cluster
    monkeypatch.setattr(sweep_mod, "_local_cluster", lambda n, _=True: local_cluster(n, processes))
    root = middlebury2014(tmp_path / "mb", scenes=3, size="Q")
    (root / "Q" / "Scene1" / "im1.png").write_text("not an image")  # this pair's tasks raise
    out = tmp_path / "out"
    argv = ["sweep", "--dataset", str(root), *SMALL, "--counter-max", "2,8", "--workers", "2", "-o", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    sweep = load(out)
    points = [p["id"] for p in sweep["points"]]
    assert points == ["census_sobol_cm2", "census_sobol_cm8"]  # the model, --model census
    # Each of the bad pair's tasks is reported with its pair and point; the other pairs completed.
    assert [(f["pair"], f["point"]) for f in sweep["failures"]] == [("Q/Scene1", p) for p in points]
    assert all("Q/Scene1/im1.png as an image" in f["error"] for f in sweep["failures"])
    why = sweep["failures"][0]["error"]
    assert err[:2] == [f"bayesmachine sweep: task failed: pair Q/Scene1, point {p}: {why}" for p in points]
    assert "2 of 6 tasks failed" in err[2]
    good = [e for e in sweep["pairs"] if e["name"] != "Q/Scene1"]
    assert [len(e["results"]) for e in good] == [2, 2]
    for e in good:
        for point in points:
            path = out / "runs" / e["name"].replace("/", "__") / point / "result.json"
            record = json.loads(path.read_text())
            assert record["report"] == e["results"][point]
    # Pooled: mean and std over the pairs of each figure.
    for p in sweep["points"]:
        assert p["pairs"] == 2 and p["failed"] == 1
        for key in ("rms_error", "cycles_per_pixel_mean", "machine_bad2_nomatch_bad"):
            vals = [e["results"][p["id"]][key] for e in good]
            assert p[key] == pytest.approx(np.mean(vals)) and p["std"][key] == pytest.approx(np.std(vals))
    assert (out / "sweep.png").stat().st_size > 0
    # A pair's figures on the cluster are those of the one-pair sweep (in this process) of that pair.
    scene = root / "Q" / "Scene0"
    one = tmp_path / "one"
    assert main(["sweep", str(scene / "im0.png"), str(scene / "im1.png"), "--gt", str(scene / "disp0.pfm"),
                 *SMALL, "--counter-max", "2,8", "-o", str(one)]) == 0
    assert strip_timings(load(one)["pairs"][0]["results"]) == strip_timings(good[0]["results"])


def _dataset(tmp_path: Path) -> Path:
    root = tmp_path / "list"
    root.mkdir()
    lines = []
    for i in range(3):
        left, right, gt = stereo(50 + i)
        cv2.imwrite(str(root / f"l{i}.png"), left)
        cv2.imwrite(str(root / f"r{i}.png"), right)
        lines.append(f"l{i}.png r{i}.png")
    (root / "pairs.txt").write_text("\n".join(lines) + "\n")
    return root / "pairs.txt"


def test_a_killed_sweep_resumes_to_the_same_sweep_json(tmp_path, capsys) -> None:
    data = _dataset(tmp_path)
    grid = ["--dataset", str(data), "--dmax", "8", "--model", "census", "--no-sgbm", "--counter-max", "2,8"]
    seeds = ["--seed", "1,2"]
    killed = tmp_path / "killed"
    # The last pair's left image is a named pipe nobody writes: its tasks block on reading it, so the
    # sweep is killed with exactly the first two pairs' 8 tasks done, whatever the machine's speed.
    last = data.parent / "l2.png"
    image = last.read_bytes()
    last.unlink()
    os.mkfifo(last)
    proc = subprocess.Popen([sys.executable, "-m", "bayesmachine", "sweep", *grid, *seeds, "--workers", "0",
                             "--quiet", "-o", str(killed)], start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while len(list(killed.glob("runs/*/*/result.json"))) < 8:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the first two pairs did not finish in 120 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    last.unlink()
    last.write_bytes(image)
    done = len(list(killed.glob("runs/*/*/result.json")))
    assert not (killed / "sweep.json").exists() and done == 8
    assert main(["sweep", *grid, *seeds, "--workers", "0", "--resume", "-o", str(killed)]) == 0
    said = capsys.readouterr().out
    assert f"resumed: {done} task(s) complete from an earlier run, {12 - done} run now" in said
    whole = tmp_path / "whole"
    assert main(["sweep", *grid, *seeds, "--workers", "0", "--quiet", "-o", str(whole)]) == 0
    assert strip_timings(load(killed)) == strip_timings(load(whole))
    # Resuming a complete sweep reruns only a damaged result, and runs only the points it lacks.
    result = sorted(whole.glob("runs/*/*/result.json"))[0]
    result.write_text(result.read_text()[:40])
    assert main(["sweep", *grid, "--seed", "1,2,3", "--workers", "0", "--resume", "-o", str(whole)]) == 0
    assert "resumed: 11 task(s) complete from an earlier run, 7 run now" in capsys.readouterr().out
    assert [p["grid"]["seed"] for p in load(whole)["points"]] == [1, 1, 2, 2, 3, 3]


def test_a_scheduler_that_does_not_answer_is_one_error(tmp_path, capsys) -> None:
    import socket

    data = _dataset(tmp_path)
    out = tmp_path / "out"
    # Nothing listens on this machine's port: at once, whatever the timeout.
    t0 = time.monotonic()
    assert main(["sweep", "--dataset", str(data), *SMALL, "--scheduler", "tcp://127.0.0.1:9",
                 "--connect-timeout", "300", "-o", str(out)]) == 2
    assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["bayesmachine sweep: error: --scheduler tcp://127.0.0.1:9: nothing listens there (start "
                   "one with 'dask scheduler --port 9')"]
    # Something listens and never answers: within the timeout.
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        t0 = time.monotonic()
        assert main(["sweep", "--dataset", str(data), *SMALL, "--scheduler", address, "--connect-timeout",
                     "1", "-o", str(out)]) == 2
        assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"bayesmachine sweep: error: --scheduler {address}: no Dask scheduler answered within 1 s"), err
    assert not (out / "sweep.json").exists()
    # A scheduler without workers would take the tasks and never run them: refused too.
    from distributed import LocalCluster

    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0", protocol="tcp://") as cluster:
        assert main(["sweep", "--dataset", str(data), *SMALL, "--scheduler", cluster.scheduler_address,
                     "--connect-timeout", "1", "-o", str(out)]) == 2
    assert "the scheduler has no worker (start some with 'dask worker" in capsys.readouterr().err


def test_the_grid_is_the_product_of_the_list_options() -> None:
    parser = build_parser()
    args = parser.parse_args(["sweep", "--dmax", "8", "--word-bits", "8,10", "--seed", "1,0x2", "--rng",
                              "sobol,lfsr", "--counter-max", "4,2", "-o", "x"])
    points = sweep_points(args)
    assert len(points) == 16 and len({p.id for p in points}) == 16
    got = [(p.machine.rng, p.machine.word_bits, p.machine.seed, p.machine.counter_max) for p in points]
    assert got == [(r, w, s, n) for r in ("sobol", "lfsr") for w in (8, 10) for s in (1, 2) for n in (2, 4)]
    assert points[0].id == f"{DEFAULT_MODEL}_sobol_cm2_word_bits8_seed1"  # the default model first
    # Device options of --rng smtj: a point of another source does not repeat per device value.
    args = parser.parse_args(["sweep", "--dmax", "8", "--rng", "smtj,sobol", "--smtj-dwell", "1,2",
                              "--counter-max", "2", "-o", "x"])
    assert [(p.machine.rng, p.machine.smtj_dwell if p.machine.rng == "smtj" else None)
            for p in sweep_points(args)] == [("smtj", 1.0), ("smtj", 2.0), ("sobol", None)]
    assert main(["sweep", "--word-bits", "8,8", "-o", "x"]) == 2  # a repeated value is refused
    assert main(["sweep", "--workers", "2", "--scheduler", "tcp://127.0.0.1:9", "-o", "x"]) == 2


def test_the_points_of_a_pair_share_its_prepared_features_and_reference(tmp_path, capsys) -> None:
    data = _dataset(tmp_path)
    sweep_mod.clear_cache()
    out = tmp_path / "o"
    assert main(["sweep", "--dataset", str(data), "--pairs", "::2", "--dmax", "8", "--model", "census",
                 "--counter-max", "2,4,8", "--rng", "sobol,lfsr", "--no-sgbm", "--workers", "0",
                 "-o", str(out)]) == 0
    assert CACHE_STATS["pair_loads"] == 2 and CACHE_STATS["prepares"] == 2  # not 2 x 6
    assert [e["name"] for e in load(out)["pairs"]] == ["l0", "l2"]  # --pairs ::2 of l0, l1, l2
    said = capsys.readouterr()
    assert "sweep: 2 pair(s) x 6 point(s) = 12 tasks in this process" in said.out
    assert said.err.splitlines() == [f"note: {n}: no ground truth given" for n in ("l0", "l2")]


def test_a_yes_no_option_is_a_grid_axis_and_every_resolved_value_is_recorded(tmp_path, capsys) -> None:
    """'sweep --normalize-columns true,false' said 'give both LEFT and RIGHT images'; sweep.json said
    null for B = 1, timeout answer none and normalization off (for census, the opposite of what ran)."""
    left, right, _ = stereo(1)
    cv2.imwrite(str(tmp_path / "L.png"), left)
    cv2.imwrite(str(tmp_path / "R.png"), right)
    pair = [str(tmp_path / "L.png"), str(tmp_path / "R.png")]
    small = ["--dmax", "8", "--counter-max", "2", "--no-sgbm", "--quiet"]
    out = tmp_path / "both"
    assert main(["sweep", *pair, *small, "--model", "census,paper", "--normalize-columns", "true,false",
                 "--samples-per-clock", "1", "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["grid"]["normalize"] == [True, False] and sweep["grid"]["samples_per_clock"] == [1]
    got = {(p["model_name"], p["grid"]["normalize"]): p for p in sweep["points"]}
    assert sorted(got) == [("census", False), ("census", True), ("paper", False), ("paper", True)]
    assert sweep["machine"]["samples_per_clock"] == 1
    for (model, _), point in got.items():
        machine = {**sweep["machine"], **point.get("machine", {})}
        assert machine["timeout_answer"] == ("leading" if model == "census" else "none")
        assert machine["normalize"] is point["grid"]["normalize"]
    out = tmp_path / "off"
    assert main(["sweep", *pair, *small, "--model", "census", "--no-normalize-columns", "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["points"][0]["grid"]["normalize"] is False and sweep["machine"]["normalize"] is False
    capsys.readouterr()
    assert main(["sweep", "--normalize-columns", *pair, "-o", str(tmp_path / "x")]) == 2
    assert "argument --normalize-columns: expected on, off or on,off" in capsys.readouterr().err
