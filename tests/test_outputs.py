"""Atomic outputs: a file is complete or absent; an output directory never mixes two runs."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from bayesmachine import outputs
from bayesmachine.outputs import (
    MANIFEST,
    NpzWriter,
    OutputBusyError,
    OutputDir,
    atomic_file,
    atomic_write_text,
    format_bytes,
    read_manifest,
)


def names(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir())


def test_atomic_file_replaces_only_on_success(tmp_path: Path) -> None:
    target = tmp_path / "a.txt"
    atomic_write_text(target, "old")
    with pytest.raises(RuntimeError), atomic_file(target) as tmp:
        tmp.write_text("new but half")
        raise RuntimeError("writer failed")
    assert target.read_text() == "old" and names(tmp_path) == ["a.txt"]
    with atomic_file(target) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".txt" and tmp.name.startswith(".")
        tmp.write_text("new")
    assert target.read_text() == "new" and names(tmp_path) == ["a.txt"]


def test_atomic_file_overlapping_writers_of_one_file(tmp_path: Path) -> None:
    """Two writers of the same file in one process (two threads building one cached design) each
    get their own temporary file; both commit, the last one wins, nothing is left behind."""
    import threading

    target = tmp_path / "shared.v"
    with atomic_file(target) as first, atomic_file(target) as second:
        assert first != second
        first.write_text("first")
        second.write_text("second")
    assert target.read_text() == "first" and names(tmp_path) == ["shared.v"]

    barrier = threading.Barrier(4)
    errors: list[BaseException] = []

    def write(text: str) -> None:
        try:
            with atomic_file(target) as tmp:
                tmp.write_text(text)
                barrier.wait(timeout=10)  # every thread holds its temporary file at once
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=write, args=(f"t{i}",)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert target.read_text() in {"t0", "t1", "t2", "t3"} and names(tmp_path) == ["shared.v"]


def test_atomic_file_os_error_names_the_target(tmp_path: Path) -> None:
    target = tmp_path / "b.bin"
    with pytest.raises(OSError) as info, atomic_file(target) as tmp:
        tmp.write_bytes(b"x")
        raise OSError(27, "File too large")
    assert info.value.filename == str(target) and info.value.strerror == "File too large"
    assert names(tmp_path) == []
    with pytest.raises(IsADirectoryError), atomic_file(tmp_path):
        pass
    with pytest.raises(FileNotFoundError, match="does not exist"), atomic_file(tmp_path / "no" / "c"):
        pass


def _transaction(out: Path, files: dict[str, str]) -> list[Path]:
    with OutputDir(out, ("report.json", "data.npz", "waves.vcd"), last="report.json") as od:
        for name, text in files.items():
            od.write(name, lambda p, text=text: p.write_text(text))
        return od.commit()


def test_output_dir_commits_report_last_and_clears_its_own_stale_files(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "out"
    # An earlier run of ours wrote three files (a trace among them); a killed one left a temporary file.
    _transaction(out, {"report.json": "old", "data.npz": "old", "waves.vcd": "old"})
    assert names(out) == [MANIFEST, "data.npz", "report.json", "waves.vcd"]
    assert read_manifest(out) == ["data.npz", "waves.vcd", "report.json"]  # commit order, report last
    # A run killed outright listed its temporary file in the manifest before writing it.
    killed = ".data.partial-" + "0" * 32 + ".npz"
    record = json.loads((out / MANIFEST).read_text())
    (out / MANIFEST).write_text(json.dumps({**record, "staging": [killed]}))
    (out / killed).write_text("stale")
    (out / "notes.txt").write_text("the user's")
    # The user's files named like temporary files, which no manifest lists: never removed.
    users = [".report.partial-mine.json", ".data.partial-keep.npz"]
    for name in users:
        (out / name).write_text("the user's")
    renamed = []
    removed = []
    real_replace, real_unlink = os.replace, Path.unlink

    def spy(src, dst):
        renamed.append(Path(dst).name)
        real_replace(src, dst)

    real_link = os.link

    def spy_link(src, dst):
        renamed.append(Path(dst).name)
        real_link(src, dst)

    def spy_unlink(self, *args, **kwargs):
        removed.append(self.name)
        real_unlink(self, *args, **kwargs)

    monkeypatch.setattr(outputs.os, "replace", spy)
    monkeypatch.setattr(outputs.os, "link", spy_link)
    monkeypatch.setattr(Path, "unlink", spy_unlink)
    with OutputDir(out, ["report.json", "data.npz", "waves.vcd"], last="report.json") as od:
        assert names(out) == sorted([*users, "notes.txt"])  # every stale output of ours is gone first
        assert removed[0] == "report.json"  # the old report first: never beside a part of its run
        od.write("report.json", lambda p: p.write_text("{}"))  # staged first, still committed last
        od.write("data.npz", lambda p: np.savez(p, a=np.arange(3)))
        staged = [n for n in names(out) if n not in ("notes.txt", MANIFEST, *users)]
        assert len(staged) == 2 and all(n.startswith(".") and ".partial-" in n for n in staged)
        # Listed before they were written: a run killed now leaves nothing the next one cannot find.
        assert sorted(json.loads((out / MANIFEST).read_text())["staging"]) == sorted(staged)
        written = od.commit()
    moved = [n for n in renamed if n != MANIFEST]
    assert moved[-2:] == ["data.npz", "report.json"] and [p.name for p in written] == moved[-2:]
    # No trace of the old run; the user's hidden files stay.
    assert names(out) == sorted([MANIFEST, "data.npz", "notes.txt", "report.json", *users])
    assert read_manifest(out) == ["data.npz", "report.json"]
    assert "staging" not in json.loads((out / MANIFEST).read_text())
    assert all((out / name).read_text() == "the user's" for name in users)
    np.testing.assert_array_equal(np.load(out / "data.npz")["a"], np.arange(3))


def test_output_dir_never_replaces_files_it_did_not_write(tmp_path: Path) -> None:
    """A file under an output's name that no run of ours wrote there (no manifest lists it) is
    refused before any work, naming it, and stays as it is; files under other names stay too."""
    out = tmp_path
    (out / "notes.txt").write_text("the user's")
    for name in ("waves.vcd", "report.json", "data.npz"):
        (out / name).write_text("the user's")
        with pytest.raises(FileExistsError, match="bayesmachine did not write it") as info:
            with OutputDir(out, ["report.json", "data.npz", "waves.vcd"], last="report.json"):
                raise AssertionError("entered")
        assert info.value.filename == str(out / name)
        assert (out / name).read_text() == "the user's"
        (out / name).unlink()
    # A run that does not write a name (no --waves): the user's file under it stays, and the run goes.
    (out / "waves.vcd").write_text("the user's")
    with OutputDir(out, ["report.json", "waves.vcd"], last="report.json", writes=["report.json"]) as od:
        with pytest.raises(ValueError, match="not one of this run's outputs"):
            od.path("waves.vcd")
        od.write("report.json", lambda p: p.write_text("{}"))
        od.commit()
    assert (out / "waves.vcd").read_text() == "the user's" and read_manifest(out) == ["report.json"]
    (out / "waves.vcd").unlink()
    (out / "report.json").unlink()
    # A dangling symbolic link under an output's name is not replaced either.
    (out / "data.npz").symlink_to(tmp_path / "nowhere")
    with pytest.raises(FileExistsError):
        _transaction(out, {"report.json": "new"})
    (out / "data.npz").unlink()
    _transaction(out, {"report.json": "new"})
    assert (out / "notes.txt").read_text() == "the user's" and (out / "report.json").read_text() == "new"
    _transaction(out, {"report.json": "newer"})
    assert names(out) == [MANIFEST, "notes.txt", "report.json"]
    # Another command's outputs listed in the manifest (a sweep's, in a run's OUT/) stay, and stay listed.
    with OutputDir(out, ["sweep.json"], last="sweep.json") as od:
        od.write("sweep.json", lambda p: p.write_text("sweep"))
        od.commit()
    _transaction(out, {"report.json": "again"})
    assert (out / "sweep.json").read_text() == "sweep"
    assert read_manifest(out) == ["sweep.json", "report.json"]
    with OutputDir(out, ["sweep.json"], last="sweep.json") as od:  # the sweep's rerun removes its own
        assert not (out / "sweep.json").exists() and (out / "report.json").read_text() == "again"
        od.write("sweep.json", lambda p: p.write_text("sweep 2"))
        od.commit()
    assert read_manifest(out) == ["report.json", "sweep.json"]
    # A manifest that is not ours, or names outside the directory, removes nothing.
    (out / MANIFEST).write_text('{"files": ["../x", "/etc/passwd", "waves.vcd/..", ".", 3]}')
    (tmp_path.parent / "x").write_text("outside")
    (out / "waves.vcd").write_text("the user's")
    with OutputDir(out, ["other.json"], last="other.json") as od:
        od.write("other.json", lambda p: p.write_text("{}"))
        od.commit()
    assert (tmp_path.parent / "x").exists() and (out / "waves.vcd").exists()
    assert (out / "report.json").exists()


def test_output_dir_commit_never_replaces_a_file_that_appeared_meanwhile(tmp_path: Path) -> None:
    """Checked before any work, and again when committing: a file the user put under an output's
    name while the run was going stays, the commit stops there with one error naming it."""
    out = tmp_path / "out"
    with pytest.raises(FileExistsError, match="did not write it") as info:
        with OutputDir(out, ["report.json", "data.npz"], last="report.json") as od:
            od.write("data.npz", lambda p: p.write_text("ours"))
            od.write("report.json", lambda p: p.write_text("ours"))
            (out / "report.json").write_text("the user's, written during the run")
            od.commit()
    assert info.value.filename == str(out / "report.json")
    assert (out / "report.json").read_text() == "the user's, written during the run"
    assert [n for n in names(out) if ".partial-" in n] == []  # the staged report went


def test_output_dir_is_held_by_one_run(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with OutputDir(out, ["r.json"], last="r.json") as od:
        with pytest.raises(OutputBusyError, match="another run holds this output directory"):
            with OutputDir(out, ["r.json"], last="r.json"):
                pass
        od.write("r.json", lambda p: p.write_text("{}"))
        od.commit()
    _transaction(out, {"report.json": "{}"})  # released: the next run goes ahead


def _disk_full(path: Path) -> None:
    path.write_text("{")
    raise OSError(28, "No space left on device")


def test_output_dir_failure_removes_staged_files_and_new_directories(tmp_path: Path) -> None:
    out = tmp_path / "new" / "out"
    with pytest.raises(OSError) as info, OutputDir(out, ["r.json", "big.npz"], last="r.json") as od:
        od.write("big.npz", lambda p: p.write_bytes(b"PK partial"))
        od.write("r.json", _disk_full)
    assert info.value.filename == str(out / "r.json")
    assert not (tmp_path / "new").exists()  # created by this transaction, empty again: removed


def test_output_dir_rejects_unknown_names_and_uncommitted_exit(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not one of"), OutputDir(tmp_path, ["a"], last="a") as od:
        od.path("b")
    with pytest.raises(RuntimeError, match="without commit"), OutputDir(tmp_path, ["a"], last="a") as od:
        od.write("a", lambda p: p.write_text("x"))
    assert names(tmp_path) == []
    f = tmp_path / "file"
    f.write_text("")
    with pytest.raises(NotADirectoryError, match="is a file, not a directory"):
        with OutputDir(f, ["a"], last="a"):
            pass


def test_npz_writer_streams_chunks(tmp_path: Path) -> None:
    vol = np.random.default_rng(0).random((7, 5, 3))
    with NpzWriter(tmp_path / "v.npz") as npz:
        npz.add_stream("posterior", vol.shape, np.float64, (vol[i : i + 3] for i in range(0, 7, 3)))
        npz.add("map", np.arange(4, dtype=np.int16))
    z = np.load(tmp_path / "v.npz")
    np.testing.assert_array_equal(z["posterior"], vol)
    assert z["map"].dtype == np.int16 and z["map"].tolist() == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="chunks gave 3 rows"), NpzWriter(tmp_path / "w.npz") as npz:
        npz.add_stream("p", (4, 2), np.float64, [np.zeros((3, 2))])
    with pytest.raises(ValueError, match="does not fit"), NpzWriter(tmp_path / "w.npz") as npz:
        npz.add_stream("p", (4, 2), np.float64, [np.zeros((4, 3))])


def test_format_bytes() -> None:
    assert format_bytes(512) == "512 B" and format_bytes(1536) == "1.5 KiB"
    assert format_bytes(3 * 1024**3) == "3.0 GiB" and format_bytes(5000 * 1024**3) == "5000.0 GiB"
