"""``--model`` on the command line: run, reference, sweep and emit with the census model."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from bayesmachine import cliargs
from bayesmachine.cli import build_parser, main
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.reference import reference_map
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import (
    BOARD_MODEL,
    DEFAULT_MODEL,
    ModelParams,
    disparity_machine,
)

DMAX = 12


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("pair")
    left, right, gt = random_dot_stereogram(height=24, width=60, background=3, square=9, seed=2)
    cv2.imwrite(str(d / "l.png"), left)
    cv2.imwrite(str(d / "r.png"), right)
    np.save(d / "gt.npy", gt.astype(np.float64))
    return d, left, right, gt


def _args(pair, *extra: str) -> list[str]:
    d = pair[0]
    return [str(d / "l.png"), str(d / "r.png"), "--gt", str(d / "gt.npy"), "--dmax", str(DMAX), "--quiet",
            *extra]


def test_run_census_is_the_neighbour_machine_of_the_model(pair, tmp_path):
    out = tmp_path / "run"
    assert main(["run", *_args(pair, "--model", "census", "--counter-max", "8", "--prior-s", "3"),
                 "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    model = ModelParams(dmax=DMAX, name="census", prior_s=3.0)
    machine = disparity_machine(model, counter_max=8)
    assert report["model_name"] == "census" and report["model"] == model.to_dict()
    assert report["machine"] == machine.to_dict(complete=True) and report["machine"]["prior"] == "neighbour"
    for key in ("machine_bad2", "machine_bad2_nomatch_bad", "sgbm_bad2", "bm_bad2", "bm_bad2_nomatch_bad",
                "machine_nomatch_occluded", "reference_nomatch_occluded"):
        assert key in report, key
    # The command's map is the run API's (the above column and line starts from the machine's results),
    # on the census model's own output region (margin 3: every 7x7 window inside the image).
    _, left, right, gt = pair
    assert report["output_shape"] == [left.shape[0] - 6, left.shape[1] - 6 - DMAX]
    want = run_machine(prepare(left, right, model, gt), machine, "model", progress=False)
    np.testing.assert_array_equal(np.load(out / "result.npz")["map"], want.map)


def test_default_model_is_one_rule(pair, tmp_path, monkeypatch):
    # census-sgm is the default of the library and of every command but the board's (it wins on the
    # measurements: README, docs/models.md "Which model by default"); the board's is census-lr (its
    # StereoMachine meets the ULX3S-85F's clock); the paper's model stays one option away and its report
    # is what it always was.
    assert (DEFAULT_MODEL, BOARD_MODEL) == ("census-sgm", "census-lr")
    assert ModelParams().name == "census-sgm"
    assert ModelParams() == ModelParams(name=DEFAULT_MODEL)  # the library's default is the command's
    out = tmp_path / "default"
    assert main(["run", *_args(pair, "--counter-max", "4", "--no-sgbm"), "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model_name"] == "census-sgm"
    assert report["model"] == ModelParams(dmax=DMAX, name="census-sgm").to_dict()
    assert report["machine"]["prior"] == "neighbour" and report["machine"]["columns"] == 2  # semi-global, lr
    assert "right_pass_machine" in report and report["right_pass_pixels"] > 0
    assert report["fill"] == "background"  # run fills the no-match pixels by default
    out = tmp_path / "paper"
    argv = _args(pair, "--model", "paper", "--counter-max", "4", "--no-sgbm")
    assert main(["run", *argv, "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model_name"] == "paper" and report["machine"]["prior"] == "uniform"
    assert report["model"] == ModelParams(name="paper", dmax=DMAX).to_dict()
    # One constant each: the rule reads them, no command spells a model.
    monkeypatch.setattr(cliargs, "DEFAULT_MODEL", "paper")
    out = tmp_path / "switched"
    assert main(["run", *_args(pair, "--counter-max", "4", "--no-sgbm"), "-o", str(out)]) == 0
    assert json.loads((out / "report.json").read_text())["machine"]["prior"] == "uniform"


# Without --model: census-sgm on the host, in simulation and for what emits or synthesizes a design (on
# K machines too: the run then refuses K > 1 by name); census-lr for what builds or drives a board.
DEFAULTS = [
    (["run", "-o", "x"], "census-sgm"),
    (["run", "--engine", "pysim", "-o", "x"], "census-sgm"),
    (["run", "--engine", "verilator", "--feed", "pixels", "-o", "x"], "census-sgm"),
    (["run", "--machines", "1", "-o", "x"], "census-sgm"),
    (["reference", "l.png", "r.png", "-o", "x"], "census-sgm"),
    (["run", "--engine", "board", "--port", "/dev/null", "-o", "x"], "census-lr"),
    (["run", "--machines", "2", "-o", "x"], "census-sgm"),
    (["run", "--engine", "verilator", "--feed", "pixels", "--machines", "2", "-o", "x"], "census-sgm"),
    (["emit"], "census-sgm"),
    (["emit", "--top", "stereo"], "census-sgm"),
    (["synth", "--target", "ecp5-85k"], "census-sgm"),
    (["synth", "--target", "ecp5-85k", "--top", "stereo"], "census-sgm"),
    (["board", "build"], "census-lr"),
    (["board", "simulate"], "census-lr"),
]


@pytest.mark.parametrize(("argv", "want"), DEFAULTS)
def test_each_command_resolves_its_default_model(argv, want):
    args = build_parser().parse_args(argv)
    assert cliargs.default_model(args) == want
    assert cliargs.model_params_from_args(args).name == want
    # An explicit --model wins everywhere.
    args = build_parser().parse_args([*argv, "--model", "paper"])
    assert cliargs.model_params_from_args(args).name == "paper"


@pytest.mark.parametrize(("argv", "message"), [
    # The board's default is census-lr: the semi-global options are refused as with --model census-lr.
    (["board", "build", "--sgm-paths", "4"], "--sgm-paths: options of --model census-sg and census-sgm, "
     "which do not apply to --model census-lr"),
    (["run", "--engine", "board", "--port", "/dev/null", "--sgm-p1", "2"], "--sgm-p1: options of --model "
     "census-sg and census-sgm, which do not apply to --model census-lr"),
    # census-sgm runs on one machine a pass: K machines without --model are refused by name.
    (["run", "--machines", "2", "--dmax", "4"], "machines = 2: the census-sgm model's semiglobal column "
     "continues from the row above on one machine"),
])
def test_what_the_default_model_does_not_run_is_one_line(tmp_path, capsys, argv, message):
    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists()


def test_sweep_defaults_to_census_sgm():
    args = build_parser().parse_args(["sweep", "-o", "x"])
    assert cliargs.model_names_from_args(args) == ["census-sgm"]
    args = build_parser().parse_args(["sweep", "--model", "paper,census", "-o", "x"])
    assert cliargs.model_names_from_args(args) == ["paper", "census"]


def test_help_states_each_commands_default(capsys):
    def model_help(*command):
        with pytest.raises(SystemExit):
            build_parser().parse_args([*command, "--help"])
        text = " ".join(capsys.readouterr().out.split())  # argparse wraps the lines
        # --model's: the last model's description, then its default
        return text.split("over its fused column, both passes", 1)[1].split("(default ", 1)[1]

    for command in (["reference"], ["sweep"], ["emit"], ["synth"]):
        assert model_help(*command).startswith("census-sgm)"), command
    assert model_help("run").startswith("census-sgm; census-lr with --engine board,")
    for command in (["board", "build"], ["board", "simulate"]):
        assert model_help(*command).startswith("census-lr, the board's:"), command


def test_what_builds_a_design_without_a_model_takes_the_default_model():
    """stereo_machine_params and synth without a model: DEFAULT_MODEL, as the commands' rule."""
    from bayesmachine.fpga.synth import throughput_model
    from bayesmachine.hdl.frontend.stereo import stereo_machine_params

    default = ModelParams(name=DEFAULT_MODEL, dmax=6)
    params = stereo_machine_params(6, counter_max=4)
    assert params == stereo_machine_params(6, model=default, counter_max=4) and params.prior == "neighbour"
    assert throughput_model(params, None) == default
    args = build_parser().parse_args(["synth", "--target", "ecp5-85k", "--dmax", "6"])
    assert cliargs.model_params_from_args(args) == default


@pytest.mark.parametrize("command", [["run"], ["reference"], ["sweep"], ["emit"], ["synth"],
                                     ["board", "build"], ["board", "simulate"]])
def test_help_is_text(command, capsys):
    """Every help text is words: a help given as a function (read when the parser is built) is called,
    never shown as its repr (sweep's --normalize-columns once read "<function <lambda> at 0x...>")."""
    with pytest.raises(SystemExit):
        build_parser().parse_args([*command, "--help"])
    text = capsys.readouterr().out
    assert "<function" not in text and " at 0x" not in text, command


@pytest.mark.parametrize("argv", [["emit", "--top", "stereo", "-o", "{o}"], ["board", "simulate"],
                                  ["run", "--engine", "board", "--port", "/dev/null", "-o", "{o}"]])
def test_census_lr_options_are_refused_for_census_on_hardware(argv, tmp_path, capsys):
    argv = [a.replace("{o}", str(tmp_path / "o")) for a in argv]
    assert main([*argv, "--model", "census", "--lr-beta", "0.2"]) == 2
    assert not (tmp_path / "o").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and ("--lr-beta: options of --model census-lr and census-sgm, which do not apply to "
                              "--model census") in err[0], err


def test_reference_census(pair, tmp_path):
    out = tmp_path / "ref.npz"
    assert main(["reference", *_args(pair, "--model", "census")[:2], "--dmax", str(DMAX), "--model", "census",
                 "--quiet", "-o", str(out)]) == 0
    _, left, right, _ = pair
    model = ModelParams(dmax=DMAX, name="census")
    want = reference_map(model_planes(left, model), model_planes(right, model), model)
    np.testing.assert_array_equal(np.load(out)["map"], want)


def test_sweep_puts_models_side_by_side(pair, tmp_path):
    out = tmp_path / "sweep"
    argv = _args(pair, "--model", "paper,census", "--counter-max", "2,4", "--rng", "sobol,lfsr", "--no-sgbm")
    assert main(["sweep", *argv, "-o", str(out)]) == 0
    sweep = json.loads((out / "sweep.json").read_text())
    assert sweep["models"] == ["paper", "census"]
    got = [(p["model_name"], p["rng"], p["counter_max"]) for p in sweep["points"]]
    assert got == [(m, r, n) for m in ("paper", "census") for r in ("sobol", "lfsr") for n in (2, 4)]
    census = disparity_machine(ModelParams(dmax=DMAX, name="census"))
    h, w = pair[1].shape
    assert sweep["output_shape"] == [h - 4, w - 4 - DMAX]  # the first model's region
    for p in sweep["points"]:
        assert p["model"] == ModelParams(dmax=DMAX, name=p["model_name"]).to_dict()
        if p["model_name"] == "census":
            # Its own output region: every 7x7 window inside the image (margin 3).
            assert p["output_shape"] == [h - 6, w - 6 - DMAX]
            assert p["machine"]["prior"] == "neighbour" and p["machine"]["columns"] == 1  # fused
            assert p["machine"]["feedback_words"] == list(census.feedback_words)
        else:
            assert "output_shape" not in p
            assert p["machine"]["prior"] == "uniform" and p["machine"]["columns"] == 3
    assert "prior" not in sweep["machine"] and sweep["machine"]["rows"] == DMAX + 2
    assert set(sweep["reference_seconds"]) == {"paper", "census"}
    # The census points are better than the paper's on these textured dots.
    best = {m: min(p["machine_bad2_nomatch_bad"] for p in sweep["points"] if p["model_name"] == m)
            for m in ("paper", "census")}
    assert best["census"] < best["paper"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "--model", "paper", "--census-sigma", "3"], "--census-sigma: options of --model census"),
        (["run", "--model", "paper", "--no-neighbour-prior", "--prior-eps", "0.1"],
         "--no-neighbour-prior, --prior-eps: options of --model census"),
        (["sweep", "--model", "paper", "--census-window", "5"],
         "--census-window: options of --model census"),
        (["run", "--model", "census", "--prior", "loaded"], "--prior: prior: the census model"),
        (["run", "--model", "census", "--no-neighbour-prior", "--prior", "neighbour"], "--prior neighbour"),
        (["run", "--model", "paper", "--prior", "neighbour"],
         "--prior neighbour: the neighbour prior's machine"),
        (["run", "--model", "census", "--census-window", "6"],
         "--census-window: census_window must be 5 or 7"),
        (["run", "--model", "census", "--prior-s", "0"], "--prior-s: prior_s must be"),
        pytest.param(["run", "--model", "census", "--engine", "verilator", "--feed", "pixels",
                      "--words-per-beat", "13"], "multiple of the loaded columns", marks=pytest.mark.eda),
        (["sweep", "--model", "paper,paper"], "listed twice"),
        (["sweep", "--model", "sgbm"], "unknown model"),
        (["run", "--model", "sgbm"], "invalid choice"),
        (["emit", "--top", "stereo", "--model", "census", "--words-per-beat", "13"],
         "multiple of the loaded columns (2)"),
        (["emit", "--model", "paper", "--census-window", "5"], "--census-window: options of --model census"),
        (["emit", "--model", "census", "--columns", "3"], "--columns: columns: the census model has 1"),
        (["emit", "--model", "census", "--prior", "uniform"], "--prior: prior:"),
    ],
)
def test_refusals_are_one_line(pair, tmp_path, capsys, argv, message):
    if argv[0] in ("run", "sweep"):
        argv = [argv[0], *_args(pair, *argv[1:])]
    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


@pytest.mark.eda
def test_emit_census_machine(tmp_path, capsys):
    """The census model's machine: its neighbour prior's two prior columns, the line_start flag and its
    fused image column (one operator column each per column with ``--no-fuse-columns``)."""
    out = tmp_path / "census.v"
    rc = main(["emit", "--model", "census", "--dmax", "6", "--counter-max", "3", "-o", str(out)])
    text = capsys.readouterr()
    assert rc == 0 and "3 operator columns" in text.out
    verilog = out.read_text()
    assert "prev_row" in verilog and "line_start" in verilog  # the feedback column is formed on chip
    out = tmp_path / "per-column.v"
    assert main(["emit", "--model", "census", "--no-fuse-columns", "--dmax", "6", "-o", str(out)]) == 0
    assert "6 operator columns" in capsys.readouterr().out and out.stat().st_size > 0
    # Without the prior the census machine is its one fused column, or 4 columns per column.
    for fuse, columns in (("--fuse-columns", 1), ("--no-fuse-columns", 4)):
        out = tmp_path / f"no-prior{fuse}.v"
        argv = ["emit", "--model", "census", "--no-neighbour-prior", fuse, "--dmax", "6", "-o", str(out)]
        assert main(argv) == 0
        assert f"{columns} operator columns" in capsys.readouterr().out and out.stat().st_size > 0


# --- issue 38: the watchdog the user can change; options where they have no effect -----------------


def test_a_watchdog_error_names_the_option_that_sets_it(pair, tmp_path, capsys):
    """census-lr at counter max 1 with B = 16: the right pass's 8 runs x 2 = 16 cycles do not exceed B;
    the error blamed --max-cycles, which the user never gave and which does not set that watchdog."""
    from bayesmachine.models import CENSUS_WATCHDOG_RUNS, pass_machine
    from bayesmachine.params import ParameterError

    model = ModelParams(name="census-lr", dmax=DMAX)
    machine = disparity_machine(model, counter_max=1, samples_per_clock=16)
    watchdog = r"the right pass's watchdog \(16 cycles: by default 8 runs"
    with pytest.raises(ParameterError, match=watchdog) as e:
        pass_machine(model, machine, "right")
    assert e.value.parameter == "lr_right_max_cycles"
    argv = _args(pair, "--model", "census-lr", "--counter-max", "1", "--samples-per-clock", "16")
    assert main(["run", *argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("bayesmachine run: error: --lr-right-max-cycles: the right pass's")
    assert "give a longer lr_right_max_cycles" in err[0] and not (tmp_path / "o").exists()
    # A counter max the census watchdog covers was refused for the machine's default one (2^20 - 1).
    for name in ("census", "census-lr"):
        big = disparity_machine(ModelParams(name=name, dmax=DMAX), counter_max=(1 << 20) - 1)
        assert big.max_cycles == CENSUS_WATCHDOG_RUNS << 20


@pytest.mark.parametrize("argv, message", [
    (["reference", "L", "R", "--model", "census-lr", "--lr-right-max-cycles", "100"],
     "--lr-right-max-cycles: the watchdog of a machine's pass; reference computes the exact float64"),
    (["emit", "--model", "census-lr", "--lr-right-max-cycles", "100"],
     "--lr-right-max-cycles: only with --top stereo (got --top machine"),
    (["synth", "--target", "ecp5-85k", "--model", "census-lr", "--lr-beta", "0.2",
      "--lr-right-max-cycles", "9"],
     "--lr-beta, --lr-right-max-cycles: only with --top stereo"),
    (["emit", "--model", "census", "--census-sigma", "3", "--sigma", "2"],
     "--census-sigma, --sigma: only with --top stereo"),
    (["emit", "--model", "paper", "--census-sigma", "3"], "--census-sigma: options of --model census"),
])
def test_an_option_where_it_has_no_effect_is_refused(argv, message, tmp_path, capsys):
    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [
    ["emit", "--model", "paper", "--gradient-magnitude"],  # a fourth data column: another machine
    ["emit", "--model", "census", "--prior-eps", "0.2", "--no-neighbour-prior"],
    ["emit", "--model", "census-lr", "--top", "stereo", "--lr-right-max-cycles", "100", "--lr-beta", "0.2"],
])
def test_an_option_that_changes_the_machine_is_taken(argv):
    from bayesmachine.hdl.frontend.cli import check_top

    args = build_parser().parse_args(argv)
    if "--prior-eps" in argv:  # the model refuses it for its own reason (the prior it sets is off)
        with pytest.raises(ValueError, match="--no-neighbour-prior turns off"):
            check_top(args)
        return
    check_top(args)
    assert cliargs.machine_params_from_args(args, args.dmax, model=cliargs.model_params_from_args(args))


@pytest.mark.parametrize("argv, name", [
    (["run", "", ""], "left"), (["run", "--gt", ""], "--gt"), (["run", "--calib", " "], "--calib"),
    (["sweep", "--dataset", ""], "--dataset"), (["run", "--engine", "board", "--port", ""], "--port"),
    (["reference", "l.png", ""], "right"),
])
def test_an_empty_input_path_is_refused(argv, name, tmp_path, capsys):
    """--gt '' was no ground truth, --dataset '' the current directory, LEFT '' and --calib '' said
    '.: Is a directory'."""
    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"argument {name}: the path is " in err[0] and "(an unset variable?)" in err[0]
