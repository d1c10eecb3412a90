"""The engine contract: every engine takes the same input, refuses the same bad input with the same
error, pulls random numbers from a source as it needs them, and follows reset/close the same way.

Every engine, the model included, is held to :func:`_expected`: the machine's per-cycle rules
(``docs/architecture.md``) written out in plain Python, fed the same numbers, independent of
every engine's code."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_results, require_tool, small_params

from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import ENGINES, EngineBase, EngineClosedError, EngineStateError, get_engine
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.results import ArrayNumbers, MachineResult, check_numbers, decode_results
from bayesmachine.sources import SOURCE_KINDS, SourceKind
from bayesmachine.sources.lfsr import lfsr_numbers, lfsr_specs

# W = 10: numbers in [0, 1024); 8 rows x 3 columns. The machine of test_verilator's external test and
# test_smtj's Verilator check (the same RTL): one Verilator build per session serves all three.
EXTERNAL = MachineParams.for_disparity(6, words_per_beat=4, rng="external", max_cycles=60)
LFSR = small_params(rng="lfsr")


def _words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    words = rng.integers(0, params.word_one + 1, size=(pixels, params.rows, params.operator_columns))
    words[rng.random(words.shape) < 0.3] = params.word_one
    return words.astype(np.uint16)


def _numbers(params: MachineParams, rows: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 1 << params.word_bits, size=(rows, params.operators))


def _expected(params: MachineParams, words: np.ndarray, numbers: np.ndarray) -> MachineResult:
    """The results by the rules of docs/architecture.md ("Per-cycle rules"), one compute cycle at a
    time: ``numbers[t, o]`` is operator o's number in the t-th compute cycle since reset. Uniform
    prior: a row fires when all its comparators do."""
    assert params.prior == "uniform"
    rows, cols, n_max = params.rows, params.operator_columns, params.counter_max
    out = MachineResult.zeros(len(words), rows)
    t = 0
    for p, q in enumerate(words):
        counts = [0] * rows
        for k in range(1, params.max_cycles + 1):
            bit = [int(numbers[t, o]) < int(q.flat[o]) for o in range(rows * cols)]  # o = r * cols + c
            fire = [all(bit[r * cols:(r + 1) * cols]) for r in range(rows)]
            t += 1
            over = [fire[r] and counts[r] == n_max for r in range(rows)]  # the (n_max+1)-th 1
            counts = [counts[r] + (fire[r] and not over[r]) for r in range(rows)]
            if any(over) or k == params.max_cycles:
                break
        winners = [r for r in range(rows) if over[r]]
        nomatch = params.nomatch_index
        if params.tie_break == "nomatch-first" and nomatch in winners:
            winner = nomatch
        else:
            winner = winners[0] if winners else 0  # lowest index; map 0 on a timeout
        out.counts[p], out.map[p], out.cycles[p] = counts, winner, k
        out.timeout[p] = not winners
        out.nomatch[p] = bool(winners) and winner == nomatch
    return out


def _lfsr_stream(params: MachineParams, cycles: int) -> np.ndarray:
    """``rng = "lfsr"``: operator o reads its own LFSR, which steps once per compute cycle."""
    assert params.rng == "lfsr"
    return np.array([list(lfsr_numbers(spec, cycles)) for spec in lfsr_specs(params)]).T


def test_the_expectation_is_the_machine() -> None:
    """_expected on hand-checked cases (W = 4, counter max 3): it can tell results apart."""
    p = small_params(rng="external", max_cycles=40)
    ones = np.full((1, p.rows, p.operator_columns), p.word_one, np.uint16)
    zero = np.zeros((40, p.operators), np.uint16)
    got = _expected(p, ones, zero)  # every row fires every cycle: all overflow in cycle 4, no match wins
    assert (got.cycles[0], got.map[0], bool(got.nomatch[0]), got.counts[0].tolist()) == (4, 4, True, [3] * 5)
    words = np.zeros_like(ones)
    words[0, 2] = 8  # row 2 fires on numbers below 8
    nums = np.full((40, p.operators), 8, np.uint16)
    nums[[3, 7, 9, 20], 4:6] = 7  # cycles 4, 8, 10, 21: row 2's operators see 7 < 8
    got = _expected(p, words, nums)
    assert (got.cycles[0], got.map[0], bool(got.timeout[0]), got.counts[0].tolist()) == (21, 2, False,
                                                                                        [0, 0, 3, 0, 0])
    got = _expected(p, np.zeros_like(ones), zero)  # nothing fires: a timeout at max_cycles
    assert (got.cycles[0], got.map[0], bool(got.timeout[0]), bool(got.nomatch[0])) == (40, 0, True, False)


@pytest.fixture(params=[pytest.param(e, marks=pytest.mark.eda) if e == "verilator" else e for e in ENGINES])
def make(request: pytest.FixtureRequest, verilator_cache: Path) -> Iterator[Callable[..., EngineBase]]:
    """A factory of engines of one kind; every engine it made is closed afterwards."""
    name = request.param
    if name == "verilator":
        require_tool("verilator", "g++", "make")
    made: list[EngineBase] = []

    def factory(params: MachineParams) -> EngineBase:
        options = {"build_dir": verilator_cache, "verbose": False} if name == "verilator" else {}
        made.append(get_engine(name, params, **options))  # type: ignore[arg-type]
        return made[-1]

    yield factory
    for engine in made:
        engine.close()


def _error(fn: Callable[[], object]) -> tuple[type, str]:
    with pytest.raises(Exception) as info:  # noqa: B017 - the class itself is what is compared
        fn()
    return type(info.value), str(info.value)


# The bad inputs of the contract, with the error every engine must give for them.
BAD_NUMBERS = {
    "W=10 number 1024": (np.full((50, EXTERNAL.operators), 1024), ValueError,
                         "random numbers must lie in [0, 1024) (W = 10 bits); got [1024, 1024]"),
    "float 3.7": (np.full((50, EXTERNAL.operators), 3.7), ValueError,
                  "random numbers must be integers, got dtype float64"),
    "NaN": (np.full((50, EXTERNAL.operators), np.nan), ValueError,
            "random numbers must be integers, got dtype float64"),
    "bool": (np.ones((50, EXTERNAL.operators), bool), ValueError,
             "random numbers must be integers, got dtype bool"),
    "wrong shape": (np.zeros((50, EXTERNAL.operators + 1), np.uint16), ValueError,
                    "random numbers must have shape (cycles, 24), got (50, 25)"),
}


@pytest.mark.parametrize("case", list(BAD_NUMBERS))
def test_bad_numbers_are_the_same_error_in_every_engine(make: Callable[..., EngineBase], case: str) -> None:
    numbers, cls, message = BAD_NUMBERS[case]
    engine = make(EXTERNAL)
    words = _words(EXTERNAL, 3, 1)
    assert _error(lambda: engine.run(words, numbers)) == (cls, message)
    # Nothing was started: the engine goes on as if the bad call had not happened.
    good = _numbers(EXTERNAL, 2000, 2)
    assert_same_results(engine.run(words, good), _expected(EXTERNAL, words, good))


def test_bad_words_and_misplaced_numbers(make: Callable[..., EngineBase]) -> None:
    lfsr, ext = make(LFSR), make(EXTERNAL)
    over = np.full((1, LFSR.rows, LFSR.operator_columns), LFSR.word_one + 1)
    assert _error(lambda: lfsr.run(over)) == (
        ValueError, "likelihood memory words must lie in [0, 16] (p = q / 2**4); got [17, 17]")
    assert _error(lambda: lfsr.run(np.zeros((1, 3, 3), np.uint16))) == (
        ValueError, "likelihood memories have shape (1, 3, 3); this machine expects (pixels, 5, 2)")
    assert _error(lambda: lfsr.run(_words(LFSR, 1, 0), _numbers(LFSR, 10, 0))) == (
        ValueError,
        "random numbers are only taken by an off-chip source; rng = 'lfsr' generates them on chip")
    assert _error(lambda: ext.run(_words(EXTERNAL, 1, 0))) == (
        ValueError, "rng = 'external': pass the random numbers of every compute cycle "
                    "(numbers=, shape (cycles, operators))")


def test_run_after_close_is_refused(make: Callable[..., EngineBase]) -> None:
    engine = make(LFSR)
    words = _words(LFSR, 4, 3)
    assert_same_results(engine.run(words), _expected(LFSR, words, _lfsr_stream(LFSR, 4 * LFSR.max_cycles)))
    engine.close()
    engine.close()  # closing twice is harmless
    message = "this engine is closed (close() was called): create a new one to run more pixels"
    assert _error(lambda: engine.run(words)) == (EngineClosedError, message)
    assert _error(engine.reset) == (EngineClosedError, message)


def test_numbers_running_out_then_reset(make: Callable[..., EngineBase]) -> None:
    engine = make(EXTERNAL)
    words = _words(EXTERNAL, 6, 4)
    words[0] = 0  # a timeout: 60 cycles, more than the 30 rows given
    assert _error(lambda: engine.run(words, _numbers(EXTERNAL, 30, 5))) == (
        ValueError, "the 30 cycles of random numbers ran out before the run ended")
    good = _numbers(EXTERNAL, 3000, 6)
    cls, message = _error(lambda: engine.run(words, good))
    assert cls is EngineStateError and "call reset()" in message
    engine.reset()
    assert_same_results(engine.run(words, good), _expected(EXTERNAL, words, good))


def test_reset_and_wall_cycles(make: Callable[..., EngineBase]) -> None:
    engine = make(LFSR)
    words = _words(LFSR, 20, 7)
    first = engine.run(words)
    assert_same_results(first, _expected(LFSR, words, _lfsr_stream(LFSR, 20 * LFSR.max_cycles)))
    wall = engine.wall_cycles
    if isinstance(engine, MachineModel):
        assert wall is None  # the model does not time loading
    else:
        assert wall >= int(first.cycles.sum()) + LFSR.beats_per_pixel
    engine.reset()
    assert engine.wall_cycles in (None, 0)
    assert engine.run(words).equal(first)  # the LFSRs are back to their reset state


class _Counter:
    """A deterministic unbounded NumberSource: row t holds (t * 7 + o * 3) mod 2**W for operator o."""

    def __init__(self, params: MachineParams) -> None:
        self.operators = params.operators
        self._top = 1 << params.word_bits
        self.next = 0

    def take(self, count: int) -> np.ndarray:
        t = np.arange(self.next, self.next + count)[:, None]
        self.next += count
        return ((t * 7 + np.arange(self.operators)[None, :] * 3) % self._top).astype(np.uint16)


def test_device_source_streams_across_calls(make: Callable[..., EngineBase],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """An off-chip kind with a device model: run() without numbers pulls from one stream from reset
    on, whatever the calls' sizes, the same stream in every engine; reset() starts a fresh one."""
    monkeypatch.setitem(SOURCE_KINDS, "external",
                        SourceKind("external", False, "a deterministic test stream", numbers=_Counter))
    words = _words(EXTERNAL, 30, 8)
    engine = make(EXTERNAL)
    parts = [engine.run(words[a:b]) for a, b in ((0, 1), (1, 2), (2, 17), (17, 30))]
    got = MachineResult.concatenate(parts, EXTERNAL.rows)
    # Independently: the stream's rows from reset on, as one array.
    stream = _Counter(EXTERNAL).take(30 * EXTERNAL.max_cycles)
    assert_same_results(got, _expected(EXTERNAL, words, stream))
    engine.reset()
    assert_same_results(engine.run(words[:5]), _expected(EXTERNAL, words[:5], stream))


def test_caller_source_object(make: Callable[..., EngineBase]) -> None:
    """A NumberSource passed as numbers= is pulled as needed; rows taken but not used wait for the
    next call with the same source, so the stream is the same as one call's."""
    words = _words(EXTERNAL, 24, 9)
    engine = make(EXTERNAL)
    source = _Counter(EXTERNAL)
    got = MachineResult.concatenate([engine.run(words[:10], source), engine.run(words[10:], source)],
                                    EXTERNAL.rows)
    assert_same_results(got, _expected(EXTERNAL, words, _Counter(EXTERNAL).take(24 * EXTERNAL.max_cycles)))


class _Faulty(_Counter):
    """A device model with a bug: its 100th row holds 2**W, one more than a W-bit number."""

    def take(self, count: int) -> np.ndarray:
        first = self.next
        rows = super().take(count)
        if first <= 99 < first + count:
            # The error names the range of the block taken, and engines take blocks of different
            # sizes: a 0 beside the bad number makes that range [0, 2**W] in every engine.
            rows[99 - first, :2] = (self._top, 0)
        return rows


def test_a_device_models_bad_number_is_refused(make: Callable[..., EngineBase]) -> None:
    engine = make(EXTERNAL)
    words = np.zeros((3, EXTERNAL.rows, EXTERNAL.operator_columns), np.uint16)  # 3 timeouts: 180 rows
    assert _error(lambda: engine.run(words, _Faulty(EXTERNAL))) == (
        ValueError, "random numbers must lie in [0, 1024) (W = 10 bits); got [0, 1024]")


def test_unknown_option_is_a_clear_error() -> None:
    refused = r"engine '{}' does not take option\(s\) {}; it takes {}"
    with pytest.raises(ValueError, match=refused.format("model", "trace", "no options")):
        get_engine("model", LFSR, trace=(0, 1, "x.vcd"))
    with pytest.raises(ValueError, match=refused.format("pysim", "jobs", "load_stall")):
        get_engine("pysim", LFSR, jobs=2)
    with pytest.raises(ValueError, match=r"engine 'verilator' does not take option\(s\) patience, vcd"):
        get_engine("verilator", LFSR, vcd="x.vcd", patience=3)
    with pytest.raises(ValueError, match="unknown engine 'spice'"):
        get_engine("spice", LFSR)


def test_check_numbers_returns_contiguous_uint16() -> None:
    nums = np.arange(2 * EXTERNAL.operators, dtype=np.int64).reshape(EXTERNAL.operators, 2).T % 16
    out = check_numbers(EXTERNAL, nums)
    assert out.dtype == np.uint16 and out.flags.c_contiguous and np.array_equal(out, nums)
    source = ArrayNumbers(EXTERNAL, nums)
    assert [len(source.take(1)), len(source.take(5)), len(source.take(5))] == [1, 1, 0]


def test_decoder_follows_the_layout() -> None:
    """Raw payloads built field by field through the Amaranth layout decode to those fields."""
    from bayesmachine.hdl.machine import result_layout

    params = MachineParams.for_disparity(80)  # 439-bit payloads: fields straddle 32-bit words
    layout = result_layout(params)
    rng = np.random.default_rng(10)
    fields = [dict(map=int(rng.integers(82)), nomatch=int(rng.integers(2)), timeout=int(rng.integers(2)),
                   cycles=int(rng.integers(1 << 20)), counts=rng.integers(0, 17, 82).tolist())
              for _ in range(5)]
    raws = [layout.const(f).as_value().value for f in fields]
    res = decode_results(params, raws)
    assert res.map.tolist() == [f["map"] for f in fields]
    assert res.nomatch.tolist() == [bool(f["nomatch"]) for f in fields]
    assert res.timeout.tolist() == [bool(f["timeout"]) for f in fields]
    assert res.cycles.tolist() == [f["cycles"] for f in fields]
    assert res.counts.tolist() == [f["counts"] for f in fields]
    assert (res.counts.dtype, res.map.dtype, res.cycles.dtype) == (np.uint32, np.int32, np.int64)


def test_results_and_engines_import_no_amaranth() -> None:
    code = ("import sys, bayesmachine.sim.engines, bayesmachine.sim.results, bayesmachine.sources; "
            "print(sorted(m for m in sys.modules if m.startswith('amaranth')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
