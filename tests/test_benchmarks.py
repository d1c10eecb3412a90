"""The benchmark scripts (benchmarks/*.py) follow the commands' rules: bad input is one error line and
exit code 2, before any work (every numeric option bounded when parsed), and their figures compare
what they say they compare. Each script is imported and its ``main(argv)`` run in this process under
``bayesmachine.cli.run_script``; a value its parser accepted would start the benchmark, so the parser
is stopped right after parsing."""

from __future__ import annotations

import argparse
import importlib.util
import json
import re
import sys
from pathlib import Path
from types import ModuleType, SimpleNamespace

import numpy as np
import pytest

from bayesmachine import cli

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"
SCRIPTS = sorted(p.stem for p in BENCHMARKS.glob("*.py"))
# Out of every numeric option's range (2^64 is one past the largest seed), and not numbers at all.
OUT_OF_RANGE = ("18446744073709551616", "-18446744073709551617", "nan", "1e400")


class Parsed(BaseException):
    """Raised right after a script's arguments parsed: nothing of the benchmark runs."""


def load(name: str) -> ModuleType:
    if str(BENCHMARKS) not in sys.path:  # the scripts import each other (bench_normalize, ...)
        sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(f"benchmark_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


@pytest.fixture
def stop_after_parsing(monkeypatch: pytest.MonkeyPatch) -> list[argparse.ArgumentParser]:
    """Every script parser's parse stops the script once it has parsed (its parsers, recorded)."""
    parsers: list[argparse.ArgumentParser] = []
    real = cli.Parser.parse_known_args

    def parse(self, args=None, namespace=None):  # noqa: ANN001, ANN202
        parsers.append(self)
        real(self, args, namespace)
        raise Parsed

    monkeypatch.setattr(cli.Parser, "parse_known_args", parse)
    return parsers


def constrained(parser: argparse.ArgumentParser) -> list[tuple[str | None, str]]:
    """(flag, name in messages) of the arguments whose type refuses a word (numbers, lists of numbers,
    K:DIR:DIR...); flag None for a positional one."""
    out = []
    for action in parser._actions:
        if action.type is None or action.nargs == 0 or action.dest == "help":
            continue
        try:
            action.type("x")
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            flag = action.option_strings[-1] if action.option_strings else None
            out.append((flag, flag or action.metavar or action.dest))
    return out


def _minimal(name: str) -> list[str]:
    """The positional arguments a script needs to parse at all."""
    return {"bench_machines": ["1:-:-"], "frontend_equivalence": ["check", "x"],
            "golden_snapshot": ["check", "x"], "study_camera_budget": ["report.json"],
            "study_cost_operators": ["words:1"], "bench_stereo_blocks": ["OUT"]}.get(name, [])


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_numeric_argument_of_a_script_is_bounded_when_parsed(name, stop_after_parsing, capsys) -> None:
    module = load(name)
    with pytest.raises(Parsed):
        cli.run_script(name, module.main, _minimal(name))
    arguments = constrained(stop_after_parsing[-1])
    assert arguments or name in ("frontend_equivalence", "golden_snapshot"), name
    capsys.readouterr()
    for flag, said in arguments:
        for value in OUT_OF_RANGE:
            argv = [*_minimal(name), f"{flag}={value}"] if flag else [value]
            assert cli.run_script(name, module.main, argv) == 2, (said, value)
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and f"argument {said}" in err[0] and "Traceback" not in err[0], err


@pytest.mark.parametrize("name", SCRIPTS)
def test_a_script_s_help_says_its_whole_summary(name, capsys) -> None:
    """``--help`` gives at least the docstring's first paragraph, whole: bench_activity's stopped at its
    first line's end, mid-sentence ("... on a crop of the")."""
    module = load(name)
    assert cli.run_script(name, module.main, ["--help"]) == 0
    summary = " ".join(module.__doc__.split("\n\n")[0].split())
    assert summary[-1] in ".?:", summary
    shown = " ".join(capsys.readouterr().out.split())
    assert summary in shown, summary
    assert not re.search(r"\bissues? \d", shown), "history belongs in docs/changelog.md"


@pytest.mark.parametrize("name, argv, message", [
    ("bench_samples", ["--samples", "x"], "argument --samples: expected an integer"),
    ("bench_samples", ["--samples", ""], "argument --samples: give at least one B"),
    ("bench_samples", ["--samples", "3"], "argument --samples: expected one of 1, 2, 4, 8, 16, got '3'"),
    ("bench_samples", ["--samples", "0"], "argument --samples: expected one of 1, 2, 4, 8, 16, got '0'"),
    ("bench_samples", ["--samples", "8,8"], "argument --samples: a B is listed twice"),
    ("bench_samples", ["--models", "bogus"], "argument --models: unknown model 'bogus'"),
    ("bench_model", ["--rng", "sobol,bogus"], "argument --rng: unknown or not runnable random source"),
    ("bench_lr_cycles", ["--variants", "zz=1"], "'zz=1': unknown key 'zz'"),
    ("bench_lr_cycles", ["--variants", "beta=2"], "lr_beta must be a probability in [0, 1], got 2"),
    ("bench_lr_cycles", ["--rows", "9,3"], "argument --rows: expected 0 <= START < STOP <= 494"),
    ("bench_frontend", ["--crop", "1,2,3"], "argument --crop:"),
    ("bench_memory", ["--sizes", "640x480,10"], "argument --sizes: expected WxH, got '10'"),
    ("bench_sweep", ["--size", "0x0"], "argument --size: H must be 16 .. 500"),
    ("bench_machines", ["2:x"], "'2:x' is not K:SYNTH_DIR:RUN_DIR"),
    ("study_cost_operators", ["words:3"], "B must be one of 1, 2, 4, 8, 16"),
    ("study_smtj", ["--baselines", "lfsr,bogus"], "argument --baselines: expected one of lfsr"),
    ("study_fused", ["--models", "paper"], "argument --models: the paper model has no fused column"),
    ("golden_snapshot", ["check", "x", "--only", "bogus"], "--only: no configuration bogus"),
    ("bench_synth_samples", ["--counter-max", "0"], "--counter-max: counter_max must be in [1, 16777215]"),
    ("bench_synth_samples", ["--frobnicate"], "unrecognized arguments: --frobnicate"),
])
def test_bad_script_input_is_one_line_and_exit_2(name, argv, message, capsys) -> None:
    assert cli.run_script(name, load(name).main, argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0], err


def test_bench_samples_compares_every_b_with_b_1_whatever_the_order(monkeypatch, capsys) -> None:
    """``--samples 8,1`` once computed its ratios against B = 8 (the first given): B = 1 runs first."""
    module = load("bench_samples")
    monkeypatch.setattr(module, "bundled_pair", lambda: (None, None, None))
    monkeypatch.setattr(module, "prepare", lambda *args, **kwargs: None)
    cycles = {1: 80.0, 8: 10.0}  # clocks per pixel: B = 8 takes 1/8 of B = 1's
    maps = {1: np.array([3, 4]), 8: np.array([3, 5])}  # B = 8's map differs: '= B=1' must say False

    def measure(prep, model, b):  # noqa: ANN001, ANN202
        run = SimpleNamespace(map=maps[b], nomatch=maps[b] < 0, timeout=np.zeros(2, bool), counts=maps[b],
                              cycles=np.full(2, cycles[b]), passes={})
        return {"machine": SimpleNamespace(samples_per_clock=b), "run": run, "seconds": 0.0,
                "cycles_per_pixel": cycles[b], "wall_cycles_per_pixel": 0.0,
                "wall_cycles_per_pixel_one_beat": 0.0, "timeouts": 0}

    monkeypatch.setattr(module, "measure", measure)
    assert cli.run_script("bench_samples", module.main, ["--models", "census", "--samples", "8,1"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]]
    assert [(r[1], r[6], r[-3]) for r in rows] == [("1", "1.000", "True"), ("8", "0.125", "False")]


def _run_report(tmp_path: Path, **changes: object) -> str:
    """A run's report.json as study_camera_budget reads it (census-lr: both passes), with ``changes``."""
    machine = {"rows": 10, "columns": 5, "prior": "neighbour", "nomatch_row": True, "max_cycles": 45,
               "words_per_beat": 30, "feedback_words": [1024, 994, 910, 786, 641, 497, 367, 262, 183],
               "feedback_nomatch_word": 641}
    report = {"model_name": "census-lr", "pixels": 100, "samples_per_clock": 1, "cycles_per_pixel_mean": 60.0,
              "left_pass_cycles_per_pixel_mean": 30.0, "right_pass_cycles_per_pixel_mean": 20.0,
              "right_pass_pixels": 150, "machine": machine,
              "right_pass_machine": {**machine, "columns": 4}, **changes}
    path = tmp_path / f"report-{len(list(tmp_path.iterdir()))}.json"
    path.write_text(json.dumps(report))
    return str(path)


@pytest.mark.parametrize("changes, message", [
    ({"cycles_per_pixel_mean": None, "left_pass_cycles_per_pixel_mean": None}, "cycles per pixel are null"),
    ({"right_pass_cycles_per_pixel_mean": None}, "cycles per pixel are null"),
    ({"pixels": 0}, "it has no output pixel"),  # was a ZeroDivisionError with a right pass
    ({"machine": None}, "is not a report.json of bayesmachine run"),
])
def test_study_camera_budget_names_what_a_report_lacks(tmp_path, capsys, changes, message) -> None:
    module = load("study_camera_budget")
    path = _run_report(tmp_path, **changes)
    assert cli.run_script("study_camera_budget", module.main, [path]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and path in err[0] and message in err[0], err


def test_study_camera_budget_counts_both_passes(tmp_path, capsys) -> None:
    module = load("study_camera_budget")
    assert cli.run_script("study_camera_budget", module.main, [_run_report(tmp_path), "--clocks", "60"]) == 0
    row = capsys.readouterr().out.splitlines()[1]
    # Left 30 cycles x 70 operators (10 rows x 7 columns) + right 20 x 1.5 pixels x 60 operators = 3,900.
    assert "| census-lr, B = 1 | 100 | 3,900 (2,100 + 1,800) |" in row


def test_bench_activity_checks_against_the_model_and_divides_by_output_pixels(monkeypatch, tmp_path) -> None:
    """bench_activity's measure: an activity run whose results differ from the model's is refused; its
    wall cycles are per output pixel (the crop's 6 here)."""
    module = load("bench_activity")
    monkeypatch.setattr(module, "bundled_pair", lambda: (np.zeros((500, 741)), np.zeros((500, 741)), None))
    monkeypatch.setattr(module, "prepare", lambda *args, **kwargs: None)
    monkeypatch.setattr(module, "directory_activity", lambda directory, pixels, blocks: pixels)
    runs = {"verilator": SimpleNamespace(map=np.arange(6).reshape(2, 3), counts=np.ones((2, 3, 4)),
                                         cycles=np.full((2, 3), 5), wall_cycles=45)}
    runs["model"] = SimpleNamespace(**{**vars(runs["verilator"]), "wall_cycles": None})
    monkeypatch.setattr(module, "run_machine", lambda prep, machine, engine, **kwargs: runs[engine])
    m = module.measure("census", "log", "words", (0, 0, 3, 2), 4, tmp_path)
    assert (m["activity"], m["cycles"], m["wall"]) == (6, 5.0, 7.5)
    runs["model"].counts = np.zeros((2, 3, 4))
    with pytest.raises(ValueError, match="census, log: the activity build's results differ"):
        module.measure("census", "log", "words", (0, 0, 3, 2), 4, tmp_path)


def test_bench_stereo_blocks_counts_a_block_with_the_blocks_inside_it(tmp_path, capsys) -> None:
    """A block's cells are its module's and its submodules' (deeper ones folded into their ancestor at
    ``--depth``), its logic cells LUT4 + 2 per CCU2C + 6 per LUT RAM, and --against gives the
    difference of the same block."""
    def stat(extra_lut: int) -> dict:
        return {"modules": {
            "\\top": {"num_cells_by_type": {"LUT4": 1, "top.core": 1}},
            "\\top.core": {"num_cells_by_type": {"LUT4": 10, "CCU2C": 2}},
            "\\top.core.gen": {"num_cells_by_type": {"LUT4": 100 + extra_lut, "TRELLIS_DPR16X4": 1}},
            "\\top.core.gen.sums": {"num_cells_by_type": {"DP16KD": 3, "LUT4": 5}}}}
    module = load("bench_stereo_blocks")
    for name, extra in (("sgm", 7), ("lr", 0)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "top.il").write_text("")
        (tmp_path / name / "blocks.json").write_text(json.dumps(stat(extra)))
        (tmp_path / name / "blocks.key").write_text(module.blocks_key(b""))
    argv = [str(tmp_path / "sgm"), "--against", str(tmp_path / "lr"), "--depth", "3"]
    assert cli.run_script("bench_stereo_blocks", module.main, argv) == 0
    rows = {line.split()[0]: line.split()[1:] for line in capsys.readouterr().out.splitlines()[2:]}
    # top.core.gen: 107 + 5 LUT4, 1 LUT RAM, the 3 DP16KD of its submodule; 112 + 6 logic cells, +7.
    assert rows["top.core.gen"] == ["112", "0", "0", "1", "3", "118", "+7"]
    assert rows["top.core"] == ["122", "2", "0", "1", "3", "132", "+7"]
    assert rows["top"] == ["123", "2", "0", "1", "3", "133", "+7"]
    assert "top.core.gen.sums" not in rows


def test_bench_stereo_blocks_wants_a_synth_output(tmp_path, capsys) -> None:
    assert cli.run_script("bench_stereo_blocks", load("bench_stereo_blocks").main, [str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has no top.il" in err[0], err
