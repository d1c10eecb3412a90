"""The third hardening round (issue 28): each case a user hit on the new surfaces (dataset sweeps and
their readers, Dask, the board commands, output manifests), on small fabricated inputs. Each gives
the right result or one clear line with the documented exit code."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from host.test_datasets import H, W, kitti, middlebury2014, stereo

from bayesmachine.cli import main
from bayesmachine.host import sweep as sweep_mod
from bayesmachine.host.datasets import PairSpec, load_pair, resolve_dataset
from bayesmachine.host.sweep import RUNS_DIR, make_tasks, pair_dir_name
from bayesmachine.outputs import MANIFEST

EXE = [sys.executable, "-m", "bayesmachine"]
# The census model (one pass), small: what every run here computes, when it computes at all.
SMALL = ["--dmax", "8", "--model", "census", "--counter-max", "2", "--no-sgbm"]


def one_error(capsys: pytest.CaptureFixture[str]) -> str:
    """The one stderr line of a refused command (no traceback, no second line)."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    left, right, _ = stereo(1)
    cv2.imwrite(str(tmp_path / "L.png"), left)
    cv2.imwrite(str(tmp_path / "R.png"), right)
    return tmp_path / "L.png", tmp_path / "R.png"


# --- data loss: a file in OUT that no manifest lists is never replaced ---------------------------


@pytest.mark.parametrize("command, name", [
    ("run", "report.json"), ("run", "disparity.png"), ("sweep", "sweep.json"), ("sweep", "sweep.png"),
    ("sweep", "runs/L/census_sobol_cm2/result.json"),
])
def test_a_users_file_in_out_is_refused_before_any_work(tmp_path, pair, capsys, command, name) -> None:
    out = tmp_path / "o"
    (out / name).parent.mkdir(parents=True)
    (out / name).write_text("notes")
    assert main([command, *map(str, pair), *SMALL, "--quiet", "-o", str(out)]) == 2
    line = one_error(capsys)
    assert str(out / name) in line and "bayesmachine did not write it" in line
    assert (out / name).read_text() == "notes"
    written = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert written == [name]  # nothing else: refused before any work


def test_a_read_only_output_is_refused_before_any_work(tmp_path, pair, capsys, monkeypatch) -> None:
    out = tmp_path / "o"
    out.mkdir()
    real = os.access  # a directory of another user's (as root, chmod cannot make one)
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: Path(p) != out and real(p, mode, **kw))
    assert main(["sweep", *map(str, pair), *SMALL, "-o", str(out)]) == 2
    assert one_error(capsys).endswith(f"{out}: cannot write into this directory (permission denied)")
    assert list(out.iterdir()) == []


def test_an_output_that_is_a_dangling_symlink_is_one_clear_error(tmp_path, pair, capsys) -> None:
    (tmp_path / "o").symlink_to(tmp_path / "gone")
    assert main(["run", *map(str, pair), *SMALL, "-o", str(tmp_path / "o")]) == 2
    want = f"{tmp_path / 'o'}: a symbolic link to {tmp_path / 'gone'}, which does not exist"
    assert want in one_error(capsys)


# --- datasets: nothing skipped without being named ------------------------------------------------


def _scandir_refusing(monkeypatch: pytest.MonkeyPatch, refused: Path) -> None:
    """``os.scandir`` refusing one directory (a directory of another user's, mode 0: as root, the
    suite's user here, chmod cannot make one)."""
    real = os.scandir

    def scandir(path: object = ".") -> object:
        if Path(os.fspath(path)) == refused:
            raise PermissionError(13, "Permission denied", os.fspath(path))
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir)


def test_symlinked_scenes_are_followed_loops_and_unreadable_directories_named(tmp_path, monkeypatch) -> None:
    root = middlebury2014(tmp_path / "mb", scenes=1, size="Q")
    middlebury2014(tmp_path / "other", scenes=2, size="Q")
    (root / "Q" / "Linked").symlink_to(tmp_path / "other" / "Q" / "Scene1")  # a scene elsewhere
    (root / "Q" / "again").symlink_to(tmp_path / "other" / "Q" / "Scene1")  # the same one twice
    (root / "Q" / "loop").symlink_to(root)  # back up to the root
    (root / "Q" / "locked").mkdir()
    _scandir_refusing(monkeypatch, root / "Q" / "locked")
    ds = resolve_dataset([str(root)])
    assert [p.name for p in ds.pairs] == ["Q/Linked", "Q/Scene0", "Q/locked"]
    assert ds.skipped == ["Q/again: the same directory as Q/Linked, searched once",
                          "Q/loop: a link back to the dataset directory (a loop), not followed"]
    np.testing.assert_array_equal(load_pair(ds.pairs[0])[0], stereo(1)[0])  # the linked scene's pair
    with pytest.raises(ValueError, match=r"locked: cannot list this directory \(Permission denied\)"):
        load_pair(ds.pairs[2])


def test_a_sweep_names_what_it_skipped_and_the_pairs_it_could_not_read(tmp_path, monkeypatch, capsys) -> None:
    """Through the command: the loop is a note and in sweep.json; the unreadable directory a failed pair
    (every task here fails: the crop fits no pair, so nothing is computed)."""
    root = middlebury2014(tmp_path / "mb", scenes=1, size="Q")
    (root / "Q" / "loop").symlink_to(root / "Q")
    (root / "Q" / "locked").mkdir()
    _scandir_refusing(monkeypatch, root / "Q" / "locked")
    out = tmp_path / "o"
    assert main(["sweep", "--dataset", str(root), *SMALL, "--crop", f"0,0,{W + 1},{H}", "--workers", "0",
                 "--quiet", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "note: skipped Q/loop: a link back to Q (a loop), not followed" in err
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["dataset"]["pairs_found"] == 2
    assert sweep["dataset"]["skipped"] == ["Q/loop: a link back to Q (a loop), not followed"]
    reasons = {f["pair"]: f["error"] for f in sweep["failures"]}
    assert "cannot list this directory (Permission denied)" in reasons["Q/locked"]
    assert "lies outside" in reasons["Q/Scene0"]


def test_kitti_ground_truth_that_is_not_16_bit_is_refused_or_read_as_told(tmp_path) -> None:
    root = kitti(tmp_path / "kitti", 2015, frames=2)  # the second frame has no ground truth
    gt_path = root / "training" / "disp_noc_0" / "000000_10.png"
    gt = np.where(np.isfinite(stereo(20)[2]), stereo(20)[2], 0).astype(np.uint8)
    cv2.imwrite(str(gt_path), gt)
    spec = resolve_dataset([str(root)]).pairs[0]
    with pytest.raises(ValueError, match=f"{gt_path}: 8-bit ground truth, where this layout's is 16-bit"):
        load_pair(spec)
    spec = resolve_dataset([str(root)], gt_scale=1).pairs[0]  # --gt-scale 1: as the user says
    loaded = load_pair(spec)[2]
    np.testing.assert_array_equal(loaded, np.where(gt > 0, gt, np.inf).astype(np.float32))


def test_pair_names_are_safe_path_components_and_stay_unique(tmp_path) -> None:
    names = ["..", ".", "...", "../x", "a/../b", "a b", "a-b", ".hidden", "Q/Scene1"]
    pairs = [PairSpec(n, "l", "r") for n in names]
    points = sweep_mod.sweep_points(_sweep_args())
    out = tmp_path / "out"
    tasks = make_tasks(pairs, points, out, None, "model", False)
    dirs = [Path(t.result).parent.parent for t in tasks]
    assert len(set(dirs)) == len(names)  # "a b" and "a-b" both make "a-b": numbered apart
    for d in dirs:
        assert d.parent == out / RUNS_DIR and d.name not in ("", ".", "..") and not d.name.startswith(".")
    assert pair_dir_name("...") == "x" and pair_dir_name("Q/Scene1") == "Q__Scene1"


def _sweep_args(*extra: str):  # noqa: ANN202
    from bayesmachine.cli import build_parser

    return build_parser().parse_args(["sweep", *SMALL, *extra, "-o", "x"])


def test_a_list_pair_named_dots_writes_under_runs(tmp_path, capsys) -> None:
    left, right, _ = stereo(3)
    cv2.imwrite(str(tmp_path / "...png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    (tmp_path / "pairs.txt").write_text("...png r.png\n")
    out = tmp_path / "o"
    assert main(["sweep", "--dataset", str(tmp_path / "pairs.txt"), *SMALL, "--workers", "0", "--quiet",
                 "-o", str(out)]) == 0
    results = sorted(p.relative_to(out) for p in out.rglob("result.json"))
    assert results == [Path("runs/x/census_sobol_cm2/result.json")]


@pytest.mark.parametrize("line, gt, scale, note", [
    ("l.png,r.png,,256", None, None, "no ground truth given (its gt_scale 256 scales nothing)"),
    ('"l#1.png" r.png g.pfm  # a comment', "g.pfm", None, None),
    ('"l#1.png",r.png,g.pfm,2 # a comment', "g.pfm", 2.0, None),
])
def test_list_lines_keep_empty_fields_and_quoted_hashes(tmp_path, line, gt, scale, note) -> None:
    (tmp_path / "pairs.txt").write_text(line + "\n")
    (spec,) = resolve_dataset([str(tmp_path / "pairs.txt")]).pairs
    assert Path(spec.left).name in ("l.png", "l#1.png") and Path(spec.right).name == "r.png"
    assert (spec.gt and Path(spec.gt).name) == gt and spec.gt_scale == scale and spec.note == note


# --- a hang: bounded waits, at once when nothing can answer ----------------------------------------


@pytest.mark.parametrize("argv, message", [
    (["sweep", "--connect-timeout", "1e300"], "argument --connect-timeout: expected a number in (0, 600]"),
    (["sweep", "--workers", "1000"], "argument --workers: expected 0 (this process) to"),
    (["run", "--engine", "board", "--port", "p", "--baud", "99999999999"],
     "argument --baud: expected an integer in [300, 12000000]"),
    (["run", "--engine", "board", "--port", "p", "--board-timeout", "1e9"],
     "argument --board-timeout: expected a number in (0, 600]"),
    (["board", "build", "--pnr-seed", "99999999999999999999"], "argument --pnr-seed: expected an integer in"),
    (["sweep", "--scheduler", ""], "the scheduler's address is empty"),
    (["sweep", "--scheduler", "localhost"], "expected a Dask scheduler's address tcp://HOST:PORT"),
    (["sweep", "--scheduler", "http://localhost:8786"], "(not tcp://)"),
    (["sweep", "--scheduler", "garbage://x:1"], "(not tcp://)"),
    (["sweep", "--scheduler", "tcp://host:99999"], "port 1 to 65535"),
])
def test_numeric_and_address_options_are_bounded(argv, message, tmp_path, capsys) -> None:
    assert main([*argv, "-o", str(tmp_path / "o")] if "-o" not in argv else argv) == 2
    assert message in one_error(capsys)
    assert not (tmp_path / "o").exists()


def test_a_malformed_scheduler_is_refused_at_once_without_noise(tmp_path, pair) -> None:
    t0 = time.monotonic()
    done = subprocess.run([*EXE, "sweep", *map(str, pair), *SMALL, "--scheduler", "localhost",
                           "--connect-timeout", "60", "-o", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and time.monotonic() - t0 < 30
    assert done.stderr.strip().splitlines() == [
        "bayesmachine sweep: error: argument --scheduler: expected a Dask scheduler's address "
        "tcp://HOST:PORT (port 1 to 65535; Dask's default is 8786), got 'localhost' (no port)"]
    assert done.stdout == ""  # no "on a local Dask cluster" first


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_connection_refused_on_this_machine_fails_at_once(tmp_path, pair, capsys) -> None:
    port = _free_port()
    t0 = time.monotonic()
    assert main(["sweep", *map(str, pair), *SMALL, "--scheduler", f"127.0.0.1:{port}", "--connect-timeout",
                 "300", "-o", str(tmp_path / "o")]) == 2
    assert time.monotonic() - t0 < 10
    assert one_error(capsys) == (f"bayesmachine sweep: error: --scheduler tcp://127.0.0.1:{port}: nothing "
                                 f"listens there (start one with 'dask scheduler --port {port}')")


def test_a_listener_that_is_not_dask_is_one_line_without_noise(tmp_path, pair) -> None:
    """Something answers on the port, but not Dask (an HTTP server here): one line, within the timeout,
    and no "Exception ignored in: Client.__del__" after it."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()

    def answer() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\nconnection: close\r\n\r\n")

    threading.Thread(target=answer, daemon=True).start()
    try:
        port = server.getsockname()[1]
        done = subprocess.run([*EXE, "sweep", *map(str, pair), *SMALL, "--quiet", "--scheduler",
                               f"tcp://127.0.0.1:{port}", "--connect-timeout", "3", "-o",
                               str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    finally:
        server.close()
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith(f"bayesmachine sweep: error: --scheduler tcp://127.0.0.1:{port}: ")


# --- tracebacks ----------------------------------------------------------------------------------


_BAD_HEADERS = {
    "zero.pgm": (b"P5\n0 0\n255\n", "declares 0 x 0 pixels"),
    "negative.pgm": (b"P5\n-5 10\n255\n" + bytes(50), "declares -5 x 10 pixels"),
    "huge.pgm": (b"P5\n40000 40000\n255\n" + bytes(50), "declares 40000 x 40000 pixels"),
    "zero.pfm": (b"Pf\n0 0\n-1.0\n", "declares 0 x 0 pixels"),
    "negative.pfm": (b"Pf\n-4 3\n-1.0\n" + bytes(48), "declares -4 x 3 pixels"),
    "huge.pfm": (b"Pf\n70000 70000\n-1.0\n" + bytes(48), "declares 70000 x 70000 pixels"),
    "garbage.pfm": (b"Pf\nhello world\n-1.0\n" + bytes(48), "OpenCV refuses its header"),
}


@pytest.mark.parametrize("name", sorted(_BAD_HEADERS))
@pytest.mark.parametrize("role", ["left", "gt"])
def test_an_image_header_of_impossible_size_is_one_line(tmp_path, pair, capsys, name, role) -> None:
    data, message = _BAD_HEADERS[name]
    bad = tmp_path / name
    bad.write_bytes(data)
    files = [str(bad), str(pair[1])] if role == "left" else [*map(str, pair), "--gt", str(bad)]
    assert main(["run", *files, *SMALL, "-o", str(tmp_path / "o")]) == 2
    line = one_error(capsys)
    assert f"cannot read {bad}: " in line and message in line


def test_an_impossible_header_in_a_dataset_is_the_tasks_reason(tmp_path) -> None:
    root = middlebury2014(tmp_path / "mb", scenes=1, size="Q")
    scene = root / "Q" / "Scene0"
    (scene / "disp0.pfm").write_bytes(_BAD_HEADERS["huge.pfm"][0])
    (spec,) = resolve_dataset([str(root)]).pairs
    with pytest.raises(ValueError) as info:
        load_pair(spec)
    assert sweep_mod._describe(info.value) == (f"cannot read {scene / 'disp0.pfm'}: its header declares "
                                               "70000 x 70000 pixels (an image holds 1 to 2^30)")


def _empty_videos(tmp_path: Path) -> list[str]:
    paths = []
    for name in ("a.avi", "b.avi"):
        writer = cv2.VideoWriter(str(tmp_path / name), cv2.VideoWriter_fourcc(*"MJPG"), 10, (W, H))
        if not writer.isOpened():
            pytest.skip("this OpenCV cannot write MJPEG .avi")
        writer.release()
        paths.append(str(tmp_path / name))
    return paths


def test_a_source_without_pairs_is_one_line(tmp_path, capsys) -> None:
    for d in ("fa", "fb"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "notes.txt").write_text("no frames here")
    for paths, message in (([str(tmp_path / "fa"), str(tmp_path / "fb")], "neither directory holds a frame"),
                           (_empty_videos(tmp_path), "neither video holds a frame")):
        assert main(["sweep", "--dataset", *paths, *SMALL, "-o", str(tmp_path / "o")]) == 2
        assert message in one_error(capsys)


def test_a_video_that_cannot_be_read_says_why_without_ffmpegs_lines(tmp_path, monkeypatch) -> None:
    (tmp_path / "a.mp4").write_bytes(b"garbage" * 10)
    (tmp_path / "b.mp4").write_bytes(b"garbage" * 10)
    done = subprocess.run([*EXE, "sweep", "--dataset", str(tmp_path / "a.mp4"), str(tmp_path / "b.mp4"),
                           *SMALL, "-o", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"bayesmachine sweep: error: --dataset: cannot open {tmp_path / 'a.mp4'} as a video"]  # no FFmpeg
    real = os.access  # a file of another user's (as root, chmod cannot make one)
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: not str(p).endswith("a.mp4") and real(p, mode))
    with pytest.raises(PermissionError, match="permission denied"):
        resolve_dataset([str(tmp_path / "a.mp4"), str(tmp_path / "b.mp4")])


# --- every task failed: sweep.json lists why, no plot of nothing, exit 1 ---------------------------


@pytest.mark.parametrize("case", ["crop", "runs-a-file", "kitti-8-bit"])
def test_when_every_task_fails_sweep_json_lists_them(tmp_path, capsys, case) -> None:
    out = tmp_path / "o"
    extra: list[str] = []
    if case == "kitti-8-bit":
        root = kitti(tmp_path / "kitti", 2015, frames=2)
        for gt in (root / "training" / "disp_noc_0").iterdir():
            cv2.imwrite(str(gt), np.full((H, W), 7, np.uint8))
        (root / "training" / "disp_noc_0" / "000001_10.png").write_bytes(
            (root / "training" / "disp_noc_0" / "000000_10.png").read_bytes())
    else:
        root = middlebury2014(tmp_path / "mb", scenes=2, size="Q")
        extra = ["--crop", f"0,0,{W},{H + 1}"] if case == "crop" else []
    if case == "runs-a-file":
        out.mkdir()
        (out / "runs").write_text("a file")
    assert main(["sweep", "--dataset", str(root), *SMALL, "--counter-max", "2,4", *extra, "--workers", "0",
                 "--quiet", "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert "Data cannot be log-scaled" not in "\n".join(err)
    assert err[-1].startswith(f"bayesmachine sweep: all 4 tasks failed; their reasons are in {out}/sweep")
    sweep = json.loads((out / "sweep.json").read_text())
    assert [(f["pair"], f["point"]) for f in sweep["failures"]] == [
        (p["name"], point) for p in sweep["pairs"] for point in ("census_sobol_cm2", "census_sobol_cm4")]
    want = {"crop": "lies outside", "runs-a-file": str(out / "runs"), "kitti-8-bit": "8-bit ground truth"}
    assert all(want[case] in f["error"] for f in sweep["failures"])
    assert [p["pairs"] for p in sweep["points"]] == [0, 0]
    assert not (out / "sweep.png").exists()


# --- ignored options are refused -------------------------------------------------------------------


@pytest.mark.parametrize("argv, message", [
    (["run", "--model", "census", "--no-neighbour-prior", "--prior-eps", "0.1"],
     "--prior-eps: options of the neighbour prior, which --no-neighbour-prior turns off"),
    (["sweep", "--model", "census", "--no-neighbour-prior", "--prior-s", "2", "--prior-nomatch", "0.2"],
     "--prior-s, --prior-nomatch: options of the neighbour prior"),
    (["reference", "L", "R", "--model", "census", "--no-neighbour-prior", "--prior-eps", "0.1"],
     "--prior-eps: options of the neighbour prior"),
    (["board", "simulate", "--dmax", "4", "--width", "16", "--no-neighbour-prior", "--prior-eps", "0.1"],
     "--prior-eps: options of the neighbour prior"),
    (["run", "--engine", "board", "--port", "p", "--feed", "words"], "--engine board --feed words"),
    (["sweep", "--kitti-gt", "occ"], "--kitti-gt: options of --dataset"),
    (["sweep", "--pairs", "0:1"], "--pairs: options of --dataset"),
])
def test_options_that_would_be_ignored_are_refused(argv, message, tmp_path, capsys) -> None:
    out = [] if argv[0] == "board" else ["-o", str(tmp_path / "o")]
    assert main([*argv, *out]) == 2
    assert message in one_error(capsys)


def test_kitti_gt_on_a_dataset_without_kitti_pairs_is_refused(tmp_path, capsys) -> None:
    root = middlebury2014(tmp_path / "mb", scenes=1, size="Q")
    assert main(["sweep", "--dataset", str(root), *SMALL, "--kitti-gt", "occ", "-o", str(tmp_path)]) == 2
    assert "--kitti-gt occ: the dataset has no KITTI pairs (its layout: middlebury2014)" in one_error(capsys)


# --- noise -----------------------------------------------------------------------------------------


def test_a_local_cluster_beside_another_dashboard_says_nothing(recwarn) -> None:
    held = socket.socket()
    held.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        held.bind(("", 8787))
    except OSError:
        pass  # another cluster holds it already: the case itself
    held.listen()
    try:
        client, cluster = sweep_mod._local_cluster(1, processes=False)
        client.close()
        cluster.close()
    finally:
        held.close()
    assert [str(w.message) for w in recwarn if "already in use" in str(w.message)] == []


def _stand_in_verilator(tmp_path: Path) -> dict[str, str]:
    """An environment whose Verilator is a stand-in that starts a child and never finishes (a compile
    that takes a while), recording both process ids; its own build cache."""
    tool = tmp_path / "verilator"
    tool.write_text('#!/bin/sh\ncase "$1" in --version) echo "Verilator 0 (stand-in)"; exit 0;; '
                    '--getenv) exit 1;; esac\nsleep 600 &\necho "$$ $!" >> "$BM_TEST_PIDS"\nwait\n')
    tool.chmod(0o755)
    return {**os.environ, "BAYESMACHINE_VERILATOR": str(tool), "BM_TEST_PIDS": str(tmp_path / "pids"),
            "BAYESMACHINE_CACHE_DIR": str(tmp_path / "cache")}


def _compiles(tmp_path: Path, proc: subprocess.Popen, n: int) -> list[int]:
    """The process ids of the stand-in compiles once ``n`` of them run."""
    pids = tmp_path / "pids"
    deadline = time.monotonic() + 180
    while not (pids.exists() and len(pids.read_text().split()) >= 2 * n):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"{n} compile(s) never started: {proc.communicate()[1][-2000:]}")
        time.sleep(0.05)
    return [int(p) for p in pids.read_text().split()]


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _end(pids: list[int]) -> None:
    for pid in pids:  # the stand-ins this test started, if anything left them running
        if _alive(pid):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.eda  # Amaranth's Yosys writes the Verilog the stand-in compiles
def test_sigterm_during_a_compile_in_run_says_terminated(tmp_path, pair) -> None:
    env = _stand_in_verilator(tmp_path)
    proc = subprocess.Popen([*EXE, "run", *map(str, pair), *SMALL, "--engine", "verilator", "-o",
                             str(tmp_path / "o")], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    pids = _compiles(tmp_path, proc, 1)
    try:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 143, err
        assert err.strip().splitlines()[-1] == ("bayesmachine run: terminated (SIGTERM); no output was left "
                                                "half-written, no tool left running")
        assert list((tmp_path / "cache" / "verilator").glob(".build-*")) == []
        time.sleep(0.5)
        assert not any(_alive(p) for p in pids)
    finally:
        _end(pids)


@pytest.mark.eda  # Amaranth's Yosys writes the Verilog the stand-in compiles
def test_sigterm_to_a_sweep_whose_workers_compile_leaves_no_temporaries(tmp_path, pair) -> None:
    """Two worker processes each compiling a design when the sweep gets SIGTERM: exit 143, no
    ``.build-*`` directory left in the cache and no compiler left running."""
    env = _stand_in_verilator(tmp_path)
    proc = subprocess.Popen([*EXE, "sweep", *map(str, pair), *SMALL, "--counter-max", "2,4", "--engine",
                             "verilator", "--workers", "2", "-o", str(tmp_path / "o")], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pids = _compiles(tmp_path, proc, 2)
    try:
        assert len(list((tmp_path / "cache" / "verilator").glob(".build-*"))) == 2
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 143, err
        assert list((tmp_path / "cache" / "verilator").glob(".build-*")) == []
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in pids)
    finally:
        _end(pids)


def test_the_board_top_elaborates_without_deprecated_requests() -> None:
    """``platform.request(..., dir="-")`` and ``amaranth.lib.io`` buffers: no DeprecationWarning."""
    import warnings

    from amaranth_boards.ulx3s import ULX3S_85F_Platform

    from bayesmachine.fpga.boards.core import BoardCore
    from bayesmachine.fpga.boards.devices import pll_config
    from bayesmachine.fpga.boards.ulx3s import ULX3STop
    from bayesmachine.hdl.frontend.stereo import stereo_machine_params
    from bayesmachine.models import ModelParams

    model = ModelParams(name="paper", dmax=4)
    core = BoardCore(params=stereo_machine_params(4, model=model), model=model, width=16, clocks_per_bit=15,
                     rx_fifo_log2=12)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        plan = ULX3S_85F_Platform().prepare(ULX3STop(core=core, pll=pll_config(45.0)), name="top")
    lpf = plan.files["top.lpf"]
    for pin in ("clk25_0__io", "button_fire_0__io", "uart_0__rx__io", "uart_0__tx__io", "led_7__io"):
        assert f'LOCATE COMP "{pin}"' in lpf
    assert 'FREQUENCY PORT "clk25_0__io" 25000000' in lpf


def test_a_run_refuses_only_the_users_files_it_would_write(tmp_path, pair, capsys) -> None:
    """A user's file under an output name this run does not write (``cloud.ply`` without ``--calib``,
    ``waves.vcd`` without ``--waves``) stays and does not stop it; the run's own files are listed, so
    a rerun replaces them; ``calibration.png`` of the user's with ``--gt`` is refused."""
    out = tmp_path / "o"
    out.mkdir()
    for name in ("cloud.ply", "waves.vcd"):
        (out / name).write_text("the user's")
    for _ in range(2):
        assert main(["run", *map(str, pair), *SMALL, "--quiet", "-o", str(out)]) == 0
    listed = json.loads((out / MANIFEST).read_text())["files"]
    assert sorted(listed) == sorted(p.name for p in out.iterdir() if p.name not in (MANIFEST, "cloud.ply",
                                                                                  "waves.vcd"))
    assert listed[-1] == "report.json" and (out / "cloud.ply").read_text() == "the user's"
    np.save(tmp_path / "gt.npy", stereo(1)[2])
    (out / "calibration.png").write_text("the user's")
    assert main(["run", *map(str, pair), *SMALL, "--gt", str(tmp_path / "gt.npy"), "-o", str(out)]) == 2
    assert f"{out / 'calibration.png'}: exists and bayesmachine did not write it" in one_error(capsys)


def test_a_sweeps_results_are_listed_in_their_manifests(tmp_path, pair) -> None:
    out = tmp_path / "o"
    for _ in range(2):
        assert main(["sweep", *map(str, pair), *SMALL, "--quiet", "-o", str(out)]) == 0
    result = out / "runs" / "L" / "census_sobol_cm2"
    assert json.loads((result / MANIFEST).read_text())["files"] == ["result.json"]
