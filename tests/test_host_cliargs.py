"""The shared CLI argument helper: one declaration per machine option, the same in every command."""

import argparse
import dataclasses

import pytest

from bayesmachine import cliargs
from bayesmachine.cli import build_parser
from bayesmachine.params import PRIORS, RNG_KINDS, TIE_BREAKS, MachineParams, ParameterError


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


@pytest.mark.parametrize("command", ["emit", "run", "sweep"])
def test_commands_share_spellings_and_defaults(command):
    parser = build_parser()
    args = parser.parse_args([command, "--seed", "0x10", "--max-cycles", "0x400", "-o", "x"])
    assert args.seed == 16 and args.max_cycles == 1024 and args.dmax == 80
    machine = cliargs.machine_params_from_args(args, args.dmax, counter_max=4)
    assert machine == MachineParams.for_disparity(80, seed=16, max_cycles=1024, counter_max=4)
    # --prior is left to the model unless given (the census model's is 'neighbour'); the machine's is uniform.
    assert args.tie_break == "nomatch-first" and args.prior is None and machine.prior == "uniform"
    assert args.rng == (["sobol"] if command == "sweep" else "sobol")  # a sweep compares a list of sources


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
