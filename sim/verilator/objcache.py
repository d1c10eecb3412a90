"""Verilator's runtime objects, compiled once per cache: a compiler wrapper for ``OBJCACHE``.

Every harness build compiles Verilator's runtime (``verilated.cpp``, ``verilated_threads.cpp``
and, with a trace, the trace writers) with the same command, whatever the design: seconds of CPU
each. ``build_design`` runs make with ``OBJCACHE`` set to a wrapper that calls :func:`main`,
which make puts in front of every compile command. A compile of a file from Verilator's
``include`` directory is looked up in ``<cache>/runtime/`` under a key hashing the Verilator
version, the whole command, the source's content, the include directory's headers (size, mtime)
and the compiler (path, size, mtime): a hit
copies the object, a miss compiles it and stores it (written under a temporary name and renamed:
concurrent builds store the same bytes, and an entry is complete or absent). Every other compile
(the design's, the harness's) runs unchanged.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

__all__ = ["RUNTIME_DIR", "main", "wrapper_script"]

RUNTIME_DIR = "runtime"  # under the build cache's root


def _option(args: list[str], flag: str) -> str | None:
    for i, a in enumerate(args[:-1]):
        if a == flag:
            return args[i + 1]
    return None


def _key(store: Path, version: str, args: list[str], source: Path) -> Path:
    h = hashlib.sha256(version.encode())
    for a in args:
        h.update(a.encode())
        h.update(b"\0")
    h.update(source.read_bytes())
    # The headers it includes: a Verilator reinstalled under the same version string changes them.
    for f in sorted(source.parent.rglob("*.h")):
        st = f.stat()
        h.update(f"{f.relative_to(source.parent)} {st.st_size} {st.st_mtime_ns}\0".encode())
    compiler = shutil.which(args[0])
    if compiler is not None:
        st = os.stat(compiler)
        h.update(f"{os.path.realpath(compiler)} {st.st_size} {st.st_mtime_ns}".encode())
    return store / f"{source.stem}-{h.hexdigest()[:24]}.o"


def main(argv: list[str]) -> int:
    """``objcache STORE INCLUDE_DIR VERSION COMPILER ARGS...``: compile, or copy a cached runtime object."""
    store, include, version, args = Path(argv[0]), Path(argv[1]).resolve(), argv[2], argv[3:]
    out = _option(args, "-o")
    sources = [Path(a) for a in args if a.endswith((".cpp", ".cc"))]
    cacheable = ("-c" in args and out is not None and len(sources) == 1 and sources[0].is_absolute()
                 and sources[0].resolve().parent == include)
    if not cacheable:
        os.execvp(args[0], args)
    cached = _key(store, version, args, sources[0])
    if cached.is_file():
        tmp = Path(f"{out}.tmp-{os.getpid()}")
        shutil.copyfile(cached, tmp)
        os.replace(tmp, out)
        print(f"objcache: {out} from {cached}", flush=True)  # into build.log
        return 0
    code = subprocess.call(args)
    if code == 0:
        store.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".tmp-{os.getpid()}-", dir=store)
        try:
            with os.fdopen(fd, "wb") as f, open(out, "rb") as src:
                shutil.copyfileobj(src, f)
            os.chmod(tmp_name, 0o644)
            os.replace(tmp_name, cached)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise
    return code


def wrapper_script(store: Path, include: Path, version: str) -> str:
    """A shell script for ``OBJCACHE``: this module's :func:`main` with the store, the Verilator
    include directory and version baked in (make passes the compile command after them)."""
    import shlex

    parts = [sys.executable, str(Path(__file__).resolve()), str(store), str(include), version]
    return "#!/bin/sh\nexec " + " ".join(shlex.quote(p) for p in parts) + ' "$@"\n'


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
