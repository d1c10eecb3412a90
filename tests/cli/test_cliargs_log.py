"""The logarithmic machine's commands refuse the stochastic machine's options (they would do nothing), and a
sweep does not multiply its points over them."""

from __future__ import annotations

import pytest

from bayesmachine.cli import build_parser, main
from bayesmachine.host.sweep import sweep_points
from bayesmachine.params import STOCHASTIC_FIELDS


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
