"""The shared CLI argument helper: one declaration per machine option, the same in every command."""

import argparse
import dataclasses
import re

import pytest

from bayesmachine import cliargs
from bayesmachine.cli import build_parser, main
from bayesmachine.host.sweep import sweep_points
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.params import (
    PRIORS,
    RNG_KINDS,
    STOCHASTIC_FIELDS,
    TIE_BREAKS,
    MachineParams,
    ParameterError,
)


@pytest.mark.parametrize(("text", "value"), [("16", 16), ("0x10", 16), ("0b101", 5), ("0o17", 15),
                                             ("010", 10), (" 7 ", 7), ("1_000", 1000)])
def test_int_arg(text, value):
    assert cliargs.int_arg(text) == value


def test_int_arg_error_keeps_the_text():
    with pytest.raises(argparse.ArgumentTypeError, match="expected an integer.*'1.5'"):
        cliargs.int_arg("1.5")


def test_counter_max_list_is_sorted_without_repeats():
    assert cliargs.counter_max_list("8,1,4,2,4") == [1, 2, 4, 8]
    assert cliargs.counter_max_list("0x10, 2,") == [2, 16]
    with pytest.raises(argparse.ArgumentTypeError, match="comma-separated integers"):
        cliargs.counter_max_list("1,x")
    with pytest.raises(argparse.ArgumentTypeError, match="at least one"):
        cliargs.counter_max_list(",")


def test_argument_type_keeps_the_project_message():
    def parse(text):
        raise ValueError(f"no good: {text}")

    with pytest.raises(argparse.ArgumentTypeError, match="no good: z"):
        cliargs.argument_type(parse, "thing")("z")


def test_every_option_default_is_the_machine_default():
    """The CLI shows and uses the defaults MachineParams has (from the constants in params.py)."""
    fields = {f.name: f.default for f in dataclasses.fields(MachineParams)}
    for field, option in cliargs.MACHINE_OPTIONS.items():
        assert field in fields, field
        if option.default is not None:
            assert option.default == fields[field], field
    assert cliargs.MACHINE_OPTIONS["rng"].choices == RNG_KINDS
    assert cliargs.MACHINE_OPTIONS["tie_break"].choices == TIE_BREAKS
    assert cliargs.MACHINE_OPTIONS["prior"].choices == PRIORS


@pytest.mark.parametrize("argv", [[], ["--model", "paper"], ["--model", "census"], ["--model", "census-lr"]])
def test_the_librarys_machine_is_the_commands(argv):
    """Without machine options a command runs the library's machine of its model,
    ``disparity_machine(ModelParams(...))`` (``ModelParams()`` without ``--model``), field by field."""
    args = build_parser().parse_args(["run", *argv, "-o", "x"])
    model = cliargs.model_params_from_args(args)
    assert model == (ModelParams(name=argv[1]) if argv else ModelParams())
    assert cliargs.machine_params_from_args(args, args.dmax, model) == disparity_machine(model)


def test_machine_defaults_are_the_commands(capsys):
    """MachineParams' defaults are the command's: a model that decides nothing of its machine (the
    paper's: no watchdog, timeout answer or normalization of its own) gets every one of them, and the
    help says them where the model may decide (timeout answer, normalization, samples per clock)."""
    defaults = MachineParams.for_disparity(8).kind.defaults  # the stochastic machine's
    assert [defaults[f] for f in ("timeout_answer", "normalize", "samples_per_clock")] == ["none", False, 1]
    args = build_parser().parse_args(["run", "--model", "paper", "-o", "x"])
    machine = cliargs.machine_params_from_args(args, args.dmax, cliargs.model_params_from_args(args))
    for f in dataclasses.fields(MachineParams):
        if f.name not in ("rows", "nomatch_row", "words_per_beat"):  # the disparity machine's own
            assert getattr(machine, f.name) == defaults.get(f.name, f.default), f.name
    assert machine == MachineParams.for_disparity(args.dmax)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", "--help"])
    # one line of words; argparse may wrap a model's name at its hyphen ("census- sg")
    text = re.sub(r"(\w)- (\w)", r"\1-\2", " ".join(capsys.readouterr().out.split()))
    assert "(default none; leading with --model census, census-lr, census-sg and census-sgm)" in text
    assert "(default on with --model census, census-lr, census-sg and census-sgm, off otherwise)" in text
    assert "rng sobol or external (default 1)" in text
    assert "(default 1)" in text.split("--smtj-dwell TAU", 2)[2]


@pytest.mark.parametrize("command", ["emit", "run", "sweep"])
def test_commands_share_spellings_and_defaults(command):
    parser = build_parser()
    args = parser.parse_args([command, "--seed", "0x10", "--max-cycles", "0x400", "-o", "x"])
    assert args.seed == 16 and args.max_cycles == 1024 and args.dmax == 80
    machine = cliargs.machine_params_from_args(args, args.dmax, counter_max=4)
    assert machine == MachineParams.for_disparity(80, seed=16, max_cycles=1024, counter_max=4)
    # --prior is left to the model unless given (the census model's is 'neighbour'); the machine's is uniform.
    assert args.tie_break == "nomatch-first" and args.prior is None and machine.prior == "uniform"
    # A sweep compares a list of sources; elsewhere --rng is None unless given (--integrator log refuses
    # it then), the machine's default.
    assert args.rng == (["sobol"] if command == "sweep" else None) and machine.rng == "sobol"


def test_sweep_counter_max_default_and_run_counter_max():
    parser = build_parser()
    assert parser.parse_args(["sweep", "-o", "x"]).counter_max == [1, 2, 4, 8, 16, 32]
    assert parser.parse_args(["sweep", "--counter-max", "4,2,2", "-o", "x"]).counter_max == [2, 4]
    args = parser.parse_args(["run", "-o", "x"])
    assert cliargs.machine_params_from_args(args, 80).counter_max == 16


def test_parameter_errors_name_the_flag():
    args = build_parser().parse_args(["run", "--counter-max", "0", "-o", "x"])
    with pytest.raises(ParameterError, match=r"^--counter-max: counter_max must be"):
        cliargs.machine_params_from_args(args, 80)
    args = build_parser().parse_args(["emit", "--lfsr-bits", "8"])
    with pytest.raises(ParameterError, match=r"^--lfsr-bits: lfsr_bits \(8\) must be at least"):
        cliargs.machine_params_from_args(args, args.dmax)


def test_a_new_option_is_one_declaration(monkeypatch):
    """A new machine option reaches every command's parser and MachineParams through the helper."""
    monkeypatch.setattr(cliargs, "MACHINE_OPTIONS", dict(cliargs.MACHINE_OPTIONS))
    with pytest.raises(ValueError, match="declared twice"):
        cliargs.add_option(cliargs.MachineOption("seed", "--seed2", "again"))
    cliargs.MACHINE_OPTIONS.pop("words_per_beat")
    cliargs.add_option(cliargs.MachineOption("words_per_beat", "--load-lanes", "lanes, respelled", default=4))
    args = build_parser().parse_args(["emit", "--dmax", "3", "--load-lanes", "0x5"])
    assert cliargs.machine_params_from_args(args, args.dmax).words_per_beat == 5
    with pytest.raises(ValueError, match="no machine option"):
        cliargs.add_machine_options(argparse.ArgumentParser(), skip=("colour",))


# --- every numeric option of every command: out of range, one line and exit 2, before any work -------

_COMMANDS = {  # a command line that parses, before -o; {tmp}: the test's directory, {L} {R}: a tiny pair
    "emit": ["emit", "--dmax", "4"],
    "reference": ["reference", "{L}", "{R}", "--dmax", "8"],
    "run": ["run", "{L}", "{R}", "--dmax", "8", "--no-sgbm", "--quiet"],
    "sweep": ["sweep", "{L}", "{R}", "--dmax", "8", "--no-sgbm", "--quiet"],
    "synth": ["synth", "--target", "ecp5-85k", "--dmax", "4"],
    "board build": ["board", "build", "--dmax", "4", "--width", "32"],
    "board simulate": ["board", "simulate", "--dmax", "4", "--width", "32"],
    "classify": ["classify", "iris", "--quiet"],
}
_INTS = ("18446744073709551616", "-18446744073709551617")  # 2^64: one past the largest seed
_FLOATS = ("1e300", "-1e300", "nan")


def _numeric_options(command: str) -> list[tuple[str, str, bool]]:
    """(flag, dest, integer?) of the command's options whose type takes numbers."""
    parser = build_parser()
    for word in command.split():
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[word]
    out = []
    for action in parser._actions:
        if not action.option_strings or action.type is None or action.nargs == 0:
            continue
        try:
            action.type("7")
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            continue  # not a number (a crop, a scheduler's address, a path refusing nothing is skipped below)
        try:
            action.type("x")
            continue  # a word too: a path
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            pass
        try:
            action.type("1.5")
            integer = False
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            integer = True
        out.append((action.option_strings[-1], action.dest, integer))
    return out


@pytest.mark.parametrize("command", list(_COMMANDS))
def test_every_numeric_option_of_every_command_is_bounded_before_any_work(command, tmp_path, capsys) -> None:
    """2^64 (past every integer option: --confidence-t once wrapped in int64 after the run), 1e300 and NaN:
    one line naming the option, exit 2, and no output (an option accepted would run the command: emit and
    synth reach Yosys, which the default tier refuses)."""
    import cv2

    from bayesmachine.cli import main
    from bayesmachine.host.images import random_dot_stereogram

    left, right, _ = random_dot_stereogram(height=16, width=40, seed=3)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    base = [a.format(L=tmp_path / "l.png", R=tmp_path / "r.png") for a in _COMMANDS[command]]
    options = _numeric_options(command)
    assert len(options) >= 5, options
    capsys.readouterr()
    for flag, dest, integer in options:
        for value in _INTS if integer else _FLOATS:
            out = tmp_path / "out"
            argv = [*base, f"{flag}={value}"] + ([] if command == "board simulate" else ["-o", str(out)])
            assert main(argv) == 2, (flag, value)
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "Traceback" not in err[0], err
            assert flag in err[0] or dest in err[0], (flag, err[0])
            assert not out.exists(), (flag, value)


@pytest.mark.parametrize("options", [
    ["--counter-max", "8"], ["--rng", "lfsr"], ["--rng", "sobol"], ["--seed", "3"], ["--lfsr-bits", "20"],
    ["--max-cycles", "100"], ["--timeout-answer", "leading"], ["--samples-per-clock", "4"],
    ["--normalize-columns"], ["--no-normalize-columns"], ["--smtj-dwell", "3"],
    ["--model", "census-lr", "--lr-right-max-cycles", "100"],
])
def test_run_refuses_a_stochastic_option_in_one_line(options, tmp_path, capsys) -> None:
    out = tmp_path / "r"
    argv = ["run", "--integrator", "log", "--crop", "250,200,60,12", "--dmax", "8", *options, "-o", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    flag = options[-2] if len(options) > 1 else options[0]
    assert len(err) == 1 and flag in err[0] and "without effect on the logarithmic machine" in err[0], err
    assert not out.exists()


@pytest.mark.parametrize("argv", [["emit", "--top", "stereo", "--counter-max", "4", "-o", "x.v"],
                                  ["synth", "--target", "ecp5-85k", "--seed", "2", "-o", "s"]])
def test_emit_and_synth_refuse_them_too(argv, tmp_path, capsys) -> None:
    argv = [str(tmp_path / a) if a in ("x.v", "s") else a for a in argv]
    assert main([*argv, "--integrator", "log"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "without effect on the logarithmic machine" in err[0], err
    assert not (tmp_path / "x.v").exists() and not (tmp_path / "s").exists()


def test_every_stochastic_field_has_an_option() -> None:
    """Each field the log machine refuses is an option a command takes (so the refusal can name it)."""
    from bayesmachine.cliargs import MACHINE_OPTIONS

    assert set(STOCHASTIC_FIELDS) <= set(MACHINE_OPTIONS)


def _ids(argv: list[str]) -> list[str]:
    return [p.id for p in sweep_points(build_parser().parse_args(["sweep", *argv, "-o", "x"]))]


def test_sweep_does_not_multiply_log_points() -> None:
    """A log point over the stochastic points' counter max, sources and seeds is one point; the stochastic
    points keep their grid (and their ids)."""
    assert _ids(["--integrator", "stochastic,log", "--counter-max", "4,8", "--seed", "2", "--model",
                 "paper"]) == ["paper_sobol_cm4_integratorstochastic", "paper_sobol_cm8_integratorstochastic",
                               "paper_integratorlog"]
    # An axis the log machine reads still multiplies its points.
    assert _ids(["--integrator", "log", "--tie-break", "nomatch-first,lowest-index", "--model", "paper"]) == [
        "paper_log_tie_breaknomatch-first", "paper_log_tie_breaklowest-index"]


@pytest.mark.parametrize("options", [["--counter-max", "2"], ["--rng", "lfsr,sobol"], ["--max-cycles", "40"],
                                     ["--no-normalize-columns"], ["--counter-max", "4,8", "--seed", "3"]])
def test_sweep_refuses_them_where_no_point_is_stochastic(options, tmp_path, capsys) -> None:
    """As run does: one line naming the option, exit 2, nothing written."""
    out = tmp_path / "s"
    argv = ["sweep", "--integrator", "log", "--crop", "250,200,60,12", "--dmax", "8", *options, "-o",
            str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and options[0] in err[0], err
    assert "without effect on the logarithmic machine" in err[0], err
    assert not out.exists()
