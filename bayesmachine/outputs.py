"""Files a command writes are complete or absent.

* :func:`atomic_file`: write one file under a temporary name in the same directory, fsync,
  then ``os.replace`` it onto the final name (``emit -o``, ``reference -o``).
* :class:`OutputDir`: a transaction over a command's output directory (``run``, ``sweep``,
  ``synth``). It locks the directory (a second run into it is refused at once), removes the
  command's files of the previous run there, as the directory's manifest
  (``.bayesmachine-manifest.json``) lists them, the final report first (an interrupted rerun
  never shows an old report beside new files); anything else in the directory is left alone,
  and a file under one of the command's names that no manifest lists is refused before any
  work (it is the user's: never replaced). It stages each new file under a temporary name, and
  on :meth:`OutputDir.commit` records them in the manifest and moves them into place with the
  report last, never over a file that appeared meanwhile: a report's presence means the run is
  complete. On any exception (KeyboardInterrupt and SIGTERM included) the staged
  files are removed. A temporary name holds a random 128-bit token (``.NAME.partial-TOKEN.EXT``),
  so it cannot be a user's file, and is listed in the manifest (``staging``) before anything is
  written under it: a run killed outright (SIGKILL, power loss) leaves its temporary files listed,
  and the next run removes those, never a file by the look of its name.
* :class:`NpzWriter`: an ``.npz`` written array by array, one array possibly streamed in
  chunks along its first axis, so a volume larger than memory never has to be held.
* :func:`require_memory`, :func:`require_disk`: refuse up front, with the size needed.

An OSError while writing names the final path, not the temporary one.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import secrets
import shutil
import zipfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

__all__ = [
    "atomic_file",
    "MANIFEST",
    "OutputBusyError",
    "OutputDir",
    "read_manifest",
    "require_ours",
    "NpzWriter",
    "available_memory",
    "require_memory",
    "require_disk",
    "format_bytes",
]

_TMP_MARK = ".partial-"


def _temp_name(path: Path) -> Path:
    # Hidden, same directory (so os.replace is a rename), same suffix (writers infer formats from
    # it). A random 128-bit token: unique per call (two threads writing the same file, two engines
    # building one cached design, never share one), and never the name of a user's file.
    for _ in range(8):
        tmp = path.with_name(f".{path.stem}{_TMP_MARK}{secrets.token_hex(16)}{path.suffix}")
        if not os.path.lexists(tmp):
            return tmp
    raise FileExistsError(errno.EEXIST, "no free temporary name beside it", str(path))


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):  # not every filesystem lets a directory be fsynced
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _named(exc: OSError, path: Path) -> OSError:
    """The same error, naming the file the user asked for."""
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


def _remove(path: Path) -> None:
    with contextlib.suppress(FileNotFoundError):
        path.unlink()


def _check_target(path: Path) -> None:
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a directory, not a file", str(path))
    parent = path.parent
    if not parent.exists():
        raise FileNotFoundError(errno.ENOENT, "directory does not exist", str(parent))
    if not parent.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "is not a directory", str(parent))


@contextlib.contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path``, on failure it is removed."""
    path = Path(path)
    _check_target(path)
    tmp = _temp_name(path)
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(errno.ENOENT, "the writer produced no file", str(path))
        _fsync_file(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise _named(exc, path) from exc
    except BaseException:
        _remove(tmp)
        raise
    _fsync_dir(path.parent)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    path = Path(path)
    with atomic_file(path) as tmp:
        tmp.write_text(text)
    return path


MANIFEST = ".bayesmachine-manifest.json"


class OutputBusyError(RuntimeError):
    """Another process holds the output directory (a run is writing there now)."""


def _lock(directory: Path) -> int | None:
    """An exclusive lock on ``directory`` itself (flock on its descriptor: no lock file to leave
    behind), held until the descriptor is closed; OutputBusyError if another process holds it."""
    try:
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as exc:
        raise _named(exc, directory) from exc
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise OutputBusyError(
            f"{directory}: another run holds this output directory (it is writing there now); "
            "wait for it to finish or choose another -o"
        ) from None
    except OSError:  # a filesystem without locks: go on unlocked rather than refuse to work
        os.close(fd)
        return None
    return fd


def _plain_name(name: object) -> bool:
    return isinstance(name, str) and name not in ("", ".", "..", MANIFEST) and Path(name).name == name


def _manifest_list(directory: str | Path, key: str) -> list[str]:
    """The plain file names under ``key`` of ``directory``'s manifest (none if unreadable or foreign)."""
    try:
        data = json.loads((Path(directory) / MANIFEST).read_text())
    except (OSError, ValueError):
        return []
    names = data.get(key) if isinstance(data, dict) else None
    if not isinstance(names, list):
        return []
    return [f for f in names if _plain_name(f)]


def read_manifest(directory: str | Path) -> list[str]:
    """The file names ``directory``'s manifest says the project wrote there (none if it has none).

    An unreadable or foreign manifest counts as none: then nothing is known to be ours and
    nothing is removed."""
    return _manifest_list(directory, "files")


def _write_manifest(directory: Path, names: Iterable[str], staging: Iterable[str] = ()) -> None:
    record: dict[str, object] = {
        "about": "files bayesmachine wrote into this directory; its next run here removes them first",
        "files": list(names),
    }
    staging = list(staging)
    if staging:  # temporary files being written: removed by the next run if a killed one left them
        record["staging"] = staging
    path = directory / MANIFEST
    tmp = _temp_name(path)
    try:
        tmp.write_text(json.dumps(record, indent=1) + "\n")
        _fsync_file(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise _named(exc, path) from exc


def _foreign(path: Path) -> FileExistsError:
    return FileExistsError(errno.EEXIST, "exists and bayesmachine did not write it (no manifest of this "
                           "directory lists it): it is left alone; move it away or choose another output",
                           str(path))


def require_ours(path: str | Path) -> None:
    """Refuse (FileExistsError naming it) a file at ``path`` that its directory's manifest does not
    list: a file bayesmachine did not write, which it never replaces."""
    path = Path(path)
    if os.path.lexists(path) and path.name not in read_manifest(path.parent):
        raise _foreign(path)


def _place(tmp: Path, final: Path) -> None:
    """Rename ``tmp`` to ``final`` unless something appeared under that name meanwhile (cleared at the
    start, so anything there now is not ours): a hard link never replaces; without hard links on this
    filesystem, look first."""
    try:
        os.link(tmp, final)
    except FileExistsError:
        raise _foreign(final) from None
    except OSError:
        if os.path.lexists(final):
            raise _foreign(final) from None
        os.replace(tmp, final)
        return
    os.unlink(tmp)


class OutputDir:
    """A transaction over the files one command writes into a directory.

    ``names``: every file name the command can write there; ``last``: the name committed last
    (the report); ``writes``: the names this run may write (default: all of ``names``). Entering
    locks the directory (:class:`OutputBusyError` while another run holds it) and removes this
    command's files of the previous run there, as its manifest
    (``MANIFEST``) lists them, the report first: only files the project wrote, never anything
    else in the directory (another command's outputs listed there stay, and stay listed). A file
    under one of ``writes`` that the manifest does not list is refused (FileExistsError naming
    it). :meth:`commit` records the new files in the manifest, then moves them into place (again
    refusing to replace a file that appeared meanwhile).
    """

    def __init__(self, directory: str | Path, names: Iterable[str], last: str,
                 writes: Iterable[str] | None = None) -> None:
        self.directory = Path(directory)
        self.names = tuple(dict.fromkeys([last, *names]))  # the report first when clearing
        self.last = last
        # The names this run may write (default all): a file of the user's under another stays.
        self.writes = self.names if writes is None else tuple(writes)
        bad = [n for n in (*self.names, *self.writes) if not _plain_name(n)]
        if bad:
            raise ValueError(f"output names must be plain file names, got {bad}")
        if not set(self.writes) <= set(self.names):
            raise ValueError(f"writes {self.writes} must be among the names {self.names}")
        self._staged: dict[str, Path] = {}
        self._committed = False
        self._created: list[Path] = []
        self._lock: int | None = None
        self._kept: list[str] = []
        self._listed: list[str] = []  # the files the manifest lists now

    def __enter__(self) -> OutputDir:
        d = self.directory
        if d.is_symlink() and not d.exists():
            raise FileNotFoundError(errno.ENOENT, f"a symbolic link to {os.readlink(d)}, which does not "
                                    "exist (create that directory, or choose another output)", str(d))
        if d.exists() and not d.is_dir():
            what = "is a file" if d.is_file() else "exists"
            problem = f"{what}, not a directory (the outputs go into a directory)"
            raise NotADirectoryError(errno.ENOTDIR, problem, str(d))
        # The directories this transaction creates go again if it fails while they are empty.
        missing = [p for p in (d, *d.parents) if not p.exists()]
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _named(exc, d) from exc
        self._created = missing
        try:
            if not os.access(d, os.W_OK | os.X_OK):  # refused before any work, not at the first write
                raise PermissionError(errno.EACCES, "cannot write into this directory (permission denied)",
                                      str(d))
            self._lock = _lock(d)
            self._clear()
        except BaseException:
            self._release()
            raise
        return self

    def _clear(self) -> None:
        d = self.directory
        for name in self.names:
            if (d / name).is_dir():
                raise IsADirectoryError(errno.EISDIR, "is a directory (an output file name)", str(d / name))
        previous = read_manifest(d)
        # A name this run writes that no run of ours wrote here is the user's: refused before any work.
        for name in self.writes:
            if name not in previous and os.path.lexists(d / name):
                raise _foreign(d / name)
        # This command's files of the previous run go; another command's files listed there (a
        # sweep's in a run's OUT/) are complete outputs of their own: they stay, and stay listed.
        stale = [n for n in previous if n in self.names]
        self._kept = [n for n in previous if n not in self.names and (d / n).is_file()]
        # The manifest lists them in commit order, the report last: that goes first, so an
        # interrupted clear never leaves the report beside a part of its files.
        for name in reversed(stale):
            target = d / name
            try:
                if not target.is_dir():
                    _remove(target)
            except OSError as exc:
                raise _named(exc, target) from exc
        # Temporary files a run killed outright left behind: the ones its manifest lists, nothing else.
        for name in _manifest_list(d, "staging"):
            if name.startswith(".") and _TMP_MARK in name:
                try:
                    _remove(d / name)
                except OSError as exc:
                    raise _named(exc, d / name) from exc
        self._listed = list(self._kept)
        if self._kept:
            _write_manifest(d, self._kept)
        else:
            try:
                _remove(d / MANIFEST)
            except OSError as exc:
                raise _named(exc, d / MANIFEST) from exc

    def _release(self) -> None:
        if not self._committed:
            for created in self._created:  # innermost first
                with contextlib.suppress(OSError):
                    created.rmdir()  # only if still empty
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None

    def path(self, name: str) -> Path:
        """The temporary path to write ``name`` to (committed under ``name``)."""
        if name not in self.writes:
            raise ValueError(f"{name!r} is not one of this run's outputs {self.writes}")
        tmp = self._staged.get(name)
        if tmp is None:
            tmp = self._staged[name] = _temp_name(self.directory / name)
            # Listed before anything is written under it: the next run removes it if this one is killed.
            _write_manifest(self.directory, self._kept, self._staging())
        return tmp

    def _staging(self) -> list[str]:
        return [tmp.name for tmp in self._staged.values()]

    def write(self, name: str, writer: Callable[[Path], object]) -> Path:
        """Stage ``name`` by calling ``writer(temporary_path)``; an OSError names ``name``'s path."""
        tmp = self.path(name)
        try:
            writer(tmp)
        except OSError as exc:
            raise _named(exc, self.directory / name) from exc
        return self.directory / name

    def commit(self) -> list[Path]:
        """Rename the staged files into place, ``last`` at the very end; returns the final paths.

        The manifest lists them before the first rename, so even a commit cut short leaves
        nothing of this run that the next one would not remove."""
        order = [n for n in self._staged if n != self.last]
        if self.last in self._staged:
            order.append(self.last)
        for name in order:
            if not self._staged[name].exists():
                raise FileNotFoundError(errno.ENOENT, "was never written", str(self.directory / name))
        self._listed = [*self._kept, *order]
        _write_manifest(self.directory, self._listed, self._staging())
        done = []
        for name in order:
            tmp, final = self._staged[name], self.directory / name
            try:
                if not tmp.exists():
                    raise FileNotFoundError(errno.ENOENT, "was never written", str(final))
                _fsync_file(tmp)
                if name == self.last:
                    _fsync_dir(self.directory)  # everything else is in place before the report appears
                _place(tmp, final)
            except FileExistsError:
                raise
            except OSError as exc:
                raise _named(exc, final) from exc
            done.append(final)
        _write_manifest(self.directory, self._listed)  # every temporary file is renamed
        _fsync_dir(self.directory)
        self._committed = True
        return done

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        # Whatever was not committed goes: never a half-written file under any name.
        for tmp in self._staged.values():
            _remove(tmp)
        if self._staged and not self._committed:
            with contextlib.suppress(OSError):  # the temporary files are gone, and so goes their listing
                if self._listed:
                    _write_manifest(self.directory, self._listed)
                else:
                    _remove(self.directory / MANIFEST)
        self._release()
        if kind is None and not self._committed:
            raise RuntimeError("OutputDir left without commit()")


class NpzWriter:
    """Write an uncompressed ``.npz`` (what ``np.savez`` writes) array by array.

    :meth:`add_stream` writes an array from chunks along axis 0, so only one chunk is in
    memory. ``np.load`` reads the file as usual.
    """

    def __init__(self, path: str | Path) -> None:
        self._zip = zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True)

    def __enter__(self) -> NpzWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self._zip.close()

    def add(self, name: str, array: np.ndarray) -> None:
        with self._zip.open(f"{name}.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array(f, np.asanyarray(array), allow_pickle=False)

    def add_stream(
        self, name: str, shape: tuple[int, ...], dtype: np.dtype | type, chunks: Iterable[np.ndarray]
    ) -> None:
        dtype = np.dtype(dtype)
        header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": tuple(shape)}
        rows = 0
        with self._zip.open(f"{name}.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array_header_2_0(f, header)
            for chunk in chunks:
                c = np.ascontiguousarray(chunk, dtype=dtype)
                if c.shape[1:] != tuple(shape[1:]):
                    raise ValueError(f"{name}: chunk of shape {c.shape} does not fit {tuple(shape)}")
                f.write(c.data)
                rows += c.shape[0]
        if rows != shape[0]:
            raise ValueError(f"{name}: chunks gave {rows} rows, the header says {shape[0]}")


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable), None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def require_memory(nbytes: int, what: str, hint: str = "") -> None:
    """Refuse up front (ValueError) when ``nbytes`` exceeds the memory available now."""
    avail = available_memory()
    if avail is not None and nbytes > avail:
        raise ValueError(
            f"{what}: {format_bytes(nbytes)} of memory needed, {format_bytes(avail)} available"
            + (f"; {hint}" if hint else "")
        )


def require_disk(path: str | Path, nbytes: int, what: str, hint: str = "") -> None:
    """Refuse up front (ValueError) when the filesystem of ``path`` has less than ``nbytes`` free."""
    directory = Path(path)
    directory = directory if directory.is_dir() else directory.parent
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        return  # the write itself will say what is wrong with the directory
    if nbytes > free:
        raise ValueError(
            f"{what}: {format_bytes(nbytes)} on disk needed, {directory} has {format_bytes(free)} free"
            + (f"; {hint}" if hint else "")
        )
