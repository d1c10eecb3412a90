"""The classifier top (``hdl.classifier.ClassifierTop``) compiled with Verilator: its tables and
observations as raw load beats (``sim.classifier_top.load_beats``, the beats pysim is fed), the
machine's results back; with ``activity``, every register bit's toggles of the observations' batch
(``bayesmachine.sim.activity``, the StereoMachine's mechanism).

Everything but the design and the harness's protocol is the Verilator engine's: the wrapper and
header helpers (``codegen``), the build cache (``build.build_design``: builds under
``<cache>/classifier-<key>/``), the harness process and the result decoding
(``engine.HarnessProcess``). The harness is ``harness/classifier.cpp`` (with ``harness/common.h``).
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
import time
from pathlib import Path
from typing import Any

import numpy as np

from bayesmachine.classify.machine import ClassifierMachine
from bayesmachine.params import MachineParams
from bayesmachine.sim.activity import ACTIVITY_FLAGS, activity_env
from bayesmachine.sim.classifier_top import TopRun, load_beats
from bayesmachine.sim.verilator import VerilatorError, cache_dir, find_toolchain
from bayesmachine.sim.verilator.build import HarnessSources, VerilatorBuild, build_design, cached_verilog
from bayesmachine.sim.verilator.codegen import header_prologue, wrapper_verilog
from bayesmachine.sim.verilator.engine import HarnessProcess

__all__ = ["ClassifierVerilator", "build_classifier_harness", "run_classifier_verilator"]

HEADER = "classifier_design.h"
_MAGIC_BATCH = 0x4C434D42  # "BMCL", see harness/classifier.cpp


def _load_words(params: MachineParams, features: int, bins: int) -> int:
    from bayesmachine.hdl.classifier import beat_layout

    return (beat_layout(params.rows, features, bins).size + 31) // 32


def build_classifier_harness(params: MachineParams, features: int, bins: int, *, activity: bool = False,
                             build_dir: str | os.PathLike[str] | None = None,
                             **options: Any) -> VerilatorBuild:
    """Compile (or find in the cache) the classifier top's harness (``options``: ``jobs``, ``verbose``,
    as :func:`~bayesmachine.sim.verilator.build.build_design`). ``activity``: a build that counts every
    signal bit's toggles."""
    from bayesmachine.hdl.classifier import ClassifierTop, classifier_signature

    find_toolchain()  # a missing tool is reported before the seconds of emitting the Verilog
    if params.takes_numbers:
        raise ValueError(f"the classifier top needs an on-chip random source, not {params.rng!r}")
    signature = classifier_signature(params, features, bins)
    root = Path(build_dir) if build_dir is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    key = json.dumps([params.to_dict(), features, bins])
    name = f"classifier-{hashlib.sha256(key.encode()).hexdigest()[:20]}"
    ports = {"LOAD_PAYLOAD": ("load", "payload"), "LOAD_VALID": ("load", "valid"),
             "LOAD_READY": ("load", "ready"), "RESULT_PAYLOAD": ("result", "payload"),
             "RESULT_VALID": ("result", "valid")}
    # A hung design: nothing taken nor returned for longer than a forming, a whole run and its beats.
    hang = params.max_clocks + 8 * params.beats_per_pixel + 64
    header = header_prologue(signature, params, ports, hang_cycles=hang,
                             generator="bayesmachine.sim.classifier_verilator")
    words = _load_words(params, features, bins)
    header += f"#define BM_EXTERNAL 0\nstatic const unsigned LOAD_WORDS = {words};\n"

    def build_top() -> ClassifierTop:
        return ClassifierTop(params=params, features=features, bins=bins)

    design = HarnessSources(
        verilog=cached_verilog(name, build_top, root),
        wrapper=wrapper_verilog(signature), header=header, sources=("classifier.cpp",),
        label=f"the classifier top, {params.rows} classes, {features} features, {bins} bins,",
        header_name=HEADER, extra_flags=ACTIVITY_FLAGS if activity else (),
        info={"params": params.to_dict(), "features": features, "bins": bins, "activity": activity},
        prefix="classifier-")
    return build_design(design, build_dir=root, **options)


class ClassifierVerilator(HarnessProcess):
    """A persistent harness of the classifier top of ``params`` (``features`` memories of ``bins``
    rows): ``run(beats, decisions)`` sends raw load beats, returns the ``decisions`` results; the
    tables and random sources stay from one batch to the next. ``activity``: a directory where the
    harness, built to count toggles, writes each batch's (:func:`~bayesmachine.sim.activity.activity_env`).
    ``close()`` ends the harness."""

    def __init__(self, params: MachineParams, features: int, bins: int, *,
                 activity: str | os.PathLike[str] | None = None,
                 build_dir: str | os.PathLike[str] | None = None,
                 jobs: int = 2, verbose: bool = False) -> None:
        self.params = params
        self._words = _load_words(params, features, bins)
        self._args: list[str] = []
        self.build = build_classifier_harness(params, features, bins, activity=activity is not None,
                                              build_dir=build_dir, jobs=jobs, verbose=verbose)
        self._env = activity_env(activity, self.build)
        self._init_process()

    def run(self, beats: list[int], decisions: int) -> TopRun:
        mask = (1 << 32) - 1
        raw = np.array([[(b >> (32 * i)) & mask for i in range(self._words)] for b in beats], "<u4")
        proc = self._start()
        t0 = time.perf_counter()
        try:
            self._write(proc, struct.pack("<IIII", _MAGIC_BATCH, 0, len(beats), decisions), raw.tobytes())
            self._serve_numbers(proc, None)
            return TopRun(self._read_results(proc, decisions, t0), self.last_wall_cycles)
        except (VerilatorError, ValueError):
            raise
        except BaseException:
            self._kill()  # an interrupt leaves the pipes mid-batch
            raise

    def close(self) -> None:
        self._stop()


def run_classifier_verilator(machine: ClassifierMachine, observed: np.ndarray, bins: int, *,
                             activity: str | os.PathLike[str] | None = None, **options: Any) -> TopRun:
    """As :func:`~bayesmachine.sim.classifier_top.run_classifier_top` under Verilator: the tables in one
    batch, then ``observed`` in another (the batch whose toggles ``activity`` holds), from reset."""
    beats, rows = load_beats(machine, bins, observed)
    engine = ClassifierVerilator(machine.params, machine.tables.features, bins, activity=activity, **options)
    try:
        engine.run(beats[:rows], 0)
        return engine.run(beats[rows:], len(beats) - rows)
    finally:
        engine.close()
