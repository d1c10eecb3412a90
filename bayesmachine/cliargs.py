"""The one argument helper of every ``bayesmachine`` command that builds a machine.

Each machine option is declared once, in :data:`MACHINE_OPTIONS`: its ``MachineParams``
field, flag, type, choices and default all come from ``bayesmachine.params``, so ``emit``,
``run``, ``sweep`` (and ``synth``) accept the same spellings (``--seed 0x10`` everywhere)
and show the same defaults. A new machine option (e.g. a random source's own parameter)
is one :func:`add_option` call; commands pick it up through :func:`add_machine_options`
and :func:`machine_params_from_args`.

Type functions raise :class:`argparse.ArgumentTypeError` carrying the project's own
message, so argparse prints it instead of "invalid value".
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from bayesmachine.likelihood import (
    DEFAULT_MODEL,
    HARDWARE_MODEL,
    LR_WATCHDOG_RUNS,
    MODELS,
    ModelParams,
    disparity_machine,
)
from bayesmachine.params import (
    DEFAULT_COLUMNS,
    DEFAULT_COUNTER_MAX,
    DEFAULT_DMAX,
    DEFAULT_LFSR_BITS,
    DEFAULT_MAX_CYCLES,
    DEFAULT_PRIOR,
    DEFAULT_RNG,
    DEFAULT_SEED,
    DEFAULT_TIE_BREAK,
    DEFAULT_WORD_BITS,
    DEFAULT_WORDS_PER_BEAT,
    PRIORS,
    RNG_KINDS,
    SMTJ_SHARES,
    STEREO_ROWS_PER_BEAT,
    TIE_BREAKS,
    MachineParams,
    ParameterError,
)

__all__ = [
    "DEFAULT_BAUD",
    "BAUD_RANGE",
    "MAX_SILENCE_S",
    "MachineOption",
    "MACHINE_OPTIONS",
    "add_option",
    "add_dmax_option",
    "add_machine_options",
    "add_model_options",
    "add_census_options",
    "MODEL_OPTION_FLAGS",
    "CENSUS_OPTION_FLAGS",
    "LR_OPTION_FLAGS",
    "model_list",
    "default_model",
    "output_path",
    "machine_params_from_args",
    "model_params_from_args",
    "float_arg",
    "positive_float_arg",
    "positive_float_at_most",
    "int_in_range",
    "rng_list",
    "runnable_sources",
    "argument_type",
    "int_arg",
    "counter_max_list",
    "source_kinds",
    "rng_help",
]

T = TypeVar("T")

# The board's serial link: the baud rate ``board build`` builds for and ``run --engine board`` opens
# the port at, unless told otherwise (here, where both commands' packages can read it).
DEFAULT_BAUD = 3_000_000
# ``run --engine board``'s bounds: the serial port's rates (pyserial overflows past 32 bits; USB-serial
# chips reach 12 Mbaud, the ULX3S's FT231X 3), and seconds of silence before a board is deemed mute.
BAUD_RANGE = (300, 12_000_000)
MAX_SILENCE_S = 600.0


def int_arg(text: str) -> int:
    """An integer in any Python spelling: ``16``, ``0x10``, ``0b10000``, ``0o20`` (and ``010`` = 10)."""
    s = text.strip().replace("_", "")
    try:
        return int(s, 0)
    except ValueError:
        pass
    try:
        return int(s, 10)  # base 0 refuses leading zeros ("010"); read them as decimal
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer (e.g. 16 or 0x10), got {text!r}") from None


def argument_type(parse: Callable[[str], T], name: str | None = None) -> Callable[[str], T]:
    """Wrap ``parse`` (raising ValueError with a message) as an argparse type keeping that message."""

    def convert(text: str) -> T:
        try:
            return parse(text)
        except argparse.ArgumentTypeError:
            raise
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = name or getattr(parse, "__name__", "value")
    return convert


def output_path(text: str) -> Path:
    """``-o``: a path, never empty or blank (an unset shell variable in ``-o "$OUT"`` would otherwise
    mean the current directory)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            f"the output path is {'empty' if not text else 'blank'} (an unset variable in -o \"$OUT\"?); "
            "name the output"
        )
    return Path(text)


def float_arg(text: str) -> float:
    """A finite float (``nan`` and ``inf`` are refused here, with the option's name)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_float_arg(text: str) -> float:
    """A finite float > 0 (a scale, a divisor)."""
    value = float_arg(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


def int_in_range(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: an integer (:func:`int_arg`'s spellings) in [lo, hi]."""

    def convert(text: str) -> int:
        value = int_arg(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer in [{lo}, {hi}], got {text!r}")
        return value

    convert.__name__ = "integer"
    return convert


def positive_float_at_most(hi: float) -> Callable[[str], float]:
    """An argparse type: a number in (0, hi] (a time out, bounded so that nothing waits for ever)."""

    def convert(text: str) -> float:
        value = positive_float_arg(text)
        if value > hi:
            raise argparse.ArgumentTypeError(f"expected a number in (0, {hi:g}], got {text!r}")
        return value

    convert.__name__ = "number"
    return convert


_SMTJ_FIELDS = ("smtj_dwell", "smtj_spread", "smtj_share")


def counter_max_list(text: str) -> list[int]:
    """``N,N,...`` counter max values, sorted ascending with repeats removed."""
    values = []
    for part in text.split(","):
        if part.strip():
            try:
                values.append(int_arg(part))
            except argparse.ArgumentTypeError:
                raise argparse.ArgumentTypeError(
                    f"counter max values must be comma-separated integers, got {text!r}"
                ) from None
    if not values:
        raise argparse.ArgumentTypeError("give at least one counter max value")
    return sorted(set(values))


def source_kinds() -> Mapping[str, Any]:
    """The random-source registry ``bayesmachine.sources.SOURCE_KINDS``."""
    from bayesmachine.sources import SOURCE_KINDS

    return SOURCE_KINDS


def runnable_sources() -> tuple[str, ...]:
    """Source kinds a run can drive by itself: on-chip ones, and off-chip ones with a device model."""
    return tuple(k for k, kind in source_kinds().items() if kind.on_chip or kind.numbers is not None)


def rng_list(text: str) -> list[str]:
    """``KIND,KIND,...`` random sources (for sweeps), each runnable, no repeats."""
    kinds = [v.strip() for v in text.split(",") if v.strip()]
    if not kinds:
        raise argparse.ArgumentTypeError("give at least one random source")
    runnable = runnable_sources()
    for k in kinds:
        if k not in runnable:
            raise argparse.ArgumentTypeError(
                f"unknown or not runnable random source {k!r}; choose from {', '.join(runnable)}"
            )
    if len(set(kinds)) != len(kinds):
        raise argparse.ArgumentTypeError(f"a random source is listed twice: {text!r}")
    return kinds


def rng_help() -> str:
    kinds = source_kinds()
    described = "; ".join(f"{name}: {kinds[name].description}" for name in RNG_KINDS)
    return f"random source ({described}) (default {DEFAULT_RNG})"


@dataclass(frozen=True)
class MachineOption:
    """One command-line option that sets one :class:`MachineParams` field."""

    field: str  # the MachineParams keyword it sets (and the argparse dest)
    flag: str
    help: str  # may use %(default)s
    type: Callable[[str], Any] = int_arg
    default: Any = None  # None: leave the field to MachineParams.for_disparity
    choices: tuple[str, ...] | None = None
    metavar: str | None = None

    def add_to(self, group: argparse._ActionsContainer, **changes: Any) -> argparse.Action:
        kwargs: dict[str, Any] = {
            "dest": self.field,
            "type": self.type,
            "default": self.default,
            "help": self.help,
            "metavar": self.metavar,
        }
        if self.choices is not None:
            kwargs["choices"] = self.choices
            kwargs.pop("metavar")
            kwargs["type"] = str
        kwargs.update(changes)
        return group.add_argument(self.flag, **kwargs)


MACHINE_OPTIONS: dict[str, MachineOption] = {}


def add_option(option: MachineOption) -> MachineOption:
    """Declare a machine option (once, at import) for every command that builds machines."""
    if option.field in MACHINE_OPTIONS:
        raise ValueError(f"machine option {option.field!r} is declared twice")
    MACHINE_OPTIONS[option.field] = option
    return option


# --columns and --prior are left at None unless given: the model decides them (--model census: 4
# columns and its neighbour prior), and a given one that contradicts it is refused.
add_option(MachineOption("columns", "--columns",
                         f"data-term operator columns N (default {DEFAULT_COLUMNS}; the model's: 4 with "
                         "--model census)", metavar="N"))
add_option(MachineOption("word_bits", "--word-bits",
                         "comparator resolution W; likelihood-memory words are W+1 bits "
                         "(default %(default)s)",
                         default=DEFAULT_WORD_BITS, metavar="W"))
add_option(MachineOption("counter_max", "--counter-max",
                         "counter max n_max: a counter overflows on its (n_max+1)-th 1 (default %(default)s)",
                         default=DEFAULT_COUNTER_MAX, metavar="N"))
add_option(MachineOption("rng", "--rng", rng_help(), default=DEFAULT_RNG, choices=RNG_KINDS))
add_option(MachineOption("lfsr_bits", "--lfsr-bits",
                         "length L of each operator's LFSR, period 2^L-1 (default %(default)s)",
                         default=DEFAULT_LFSR_BITS, metavar="L"))
add_option(MachineOption("seed", "--seed",
                         "machine seed: LFSR polynomials and start states; 0x.. accepted "
                         "(default %(default)s)",
                         default=DEFAULT_SEED))
# --max-cycles is left at None unless given: census-lr's machine has its own default watchdog.
add_option(MachineOption("max_cycles", "--max-cycles",
                         "watchdog: a pixel stops as a timeout (no match) after this many cycles "
                         f"(default {DEFAULT_MAX_CYCLES}; with --model census-lr {LR_WATCHDOG_RUNS} x "
                         f"(counter max + 1), {LR_WATCHDOG_RUNS * (DEFAULT_COUNTER_MAX + 1)} at counter max "
                         f"{DEFAULT_COUNTER_MAX}, for both passes)", metavar="N"))
add_option(MachineOption("tie_break", "--tie-break",
                         "MAP encoder rule when several counters overflow in one cycle (default %(default)s)",
                         default=DEFAULT_TIE_BREAK, choices=TIE_BREAKS))
add_option(MachineOption("prior", "--prior",
                         "uniform: always-on 1s enter each row; loaded: an extra operator column 0 holds a "
                         "prior word per row; neighbour: the census model's neighbour prior (a feedback "
                         "column from the machine's own previous result and a loaded column), which "
                         f"--model census sets (default {DEFAULT_PRIOR}; neighbour with --model census)",
                         choices=PRIORS))
add_option(MachineOption("smtj_dwell", "--smtj-dwell",
                         "--rng smtj: mean dwell time of a device state, in clock cycles (default 1)",
                         type=float_arg, metavar="TAU"))
add_option(MachineOption("smtj_spread", "--smtj-spread",
                         "--rng smtj: device-to-device spread, log-sd of each dwell time (default 0; "
                         "0.05 ~ 5 %%)", type=float_arg, metavar="S"))
add_option(MachineOption("smtj_share", "--smtj-share",
                         "--rng smtj: W devices per operator, or per column shared by its rows "
                         "(default operator)", type=str, choices=SMTJ_SHARES))
add_option(MachineOption("words_per_beat", "--words-per-beat",
                         f"likelihood-memory words per load beat (default {DEFAULT_WORDS_PER_BEAT}, "
                         f"or one pixel's words if fewer; {STEREO_ROWS_PER_BEAT} rows' words with the "
                         "front end: --feed pixels, --top stereo)", metavar="N"))


def add_dmax_option(group: argparse._ActionsContainer) -> argparse.Action:
    """``--dmax``: rows = Dmax + 2 (disparities 0..Dmax and no match)."""
    return group.add_argument("--dmax", type=int_arg, default=DEFAULT_DMAX, metavar="DMAX",
                              help="largest disparity Dmax: the machine has Dmax+2 rows "
                              "(default %(default)s)")


def add_machine_options(
    parser: argparse._ActionsContainer,
    skip: Iterable[str] = (),
    title: str | None = "machine",
    help: Mapping[str, str] | None = None,
    **changes: Mapping[str, Any],
) -> argparse._ActionsContainer:
    """Add every declared machine option except the fields in ``skip``; returns the group.

    ``help`` replaces an option's help text; ``changes`` maps a field to argparse keyword
    overrides (e.g. ``counter_max={"type": counter_max_list, "default": [1, 2]}`` for a sweep).
    """
    skip = set(skip)
    unknown = (skip | set(changes) | set(help or {})) - set(MACHINE_OPTIONS)
    if unknown:
        raise ValueError(f"no machine option named {sorted(unknown)}")
    group = parser.add_argument_group(title) if title else parser
    for field, option in MACHINE_OPTIONS.items():
        if field in skip:
            continue
        extra = dict(changes.get(field, {}))
        if help and field in help:
            extra["help"] = help[field]
        option.add_to(group, **extra)
    return group


def machine_params_from_args(
    args: argparse.Namespace, dmax: int, model: ModelParams | None = None, **overrides: Any
) -> MachineParams:
    """``MachineParams.for_disparity(dmax, ...)`` from the declared options present in ``args``.

    ``overrides`` win over ``args`` (a sweep passes each ``counter_max``). Options left at
    None are left to ``for_disparity``'s defaults. With ``model``, the machine that model needs
    (:func:`~bayesmachine.likelihood.disparity_machine`: its columns, and for the census model its
    neighbour prior; a contradicting ``--columns`` or ``--prior`` is refused). A ParameterError
    names the option's flag.
    """
    kwargs: dict[str, Any] = {}
    for field in MACHINE_OPTIONS:
        value = getattr(args, field, None)
        if value is not None and not isinstance(value, list):
            kwargs[field] = value
    kwargs.update(overrides)
    device = [f for f in _SMTJ_FIELDS if kwargs.get(f) is not None]
    rng = kwargs.get("rng", DEFAULT_RNG)
    if device and rng != "smtj":
        listed = getattr(args, "rng", None)
        if isinstance(listed, list) and "smtj" in listed:
            # A list of sources (sweep): the device options are for its smtj points only.
            for f in device:
                del kwargs[f]
        else:
            flags = ", ".join(MACHINE_OPTIONS[f].flag for f in device)
            got = ",".join(listed) if isinstance(listed, list) else rng
            raise ParameterError(f"{flags}: device options of --rng smtj (got --rng {got})")
    if kwargs.get("prior") == "neighbour" and (model is None or not model.has_prior):
        raise ParameterError("--prior neighbour: the census model's neighbour prior; the machine gets its "
                             "feedback table from the model: use --model census (and leave --prior out)")
    try:
        if model is not None:
            return disparity_machine(model, **kwargs)
        return MachineParams.for_disparity(dmax, **kwargs)
    except ParameterError as exc:
        message = str(exc)
        for field, option in MACHINE_OPTIONS.items():
            if message.startswith(field) and hasattr(args, field):
                raise ParameterError(f"{option.flag}: {message}") from None
        if message.startswith("dmax"):
            raise ParameterError(f"--dmax: {message}") from None
        raise


# The model's options after --dmax (dest, flag), as add_model_options declares them.
MODEL_OPTION_FLAGS: tuple[tuple[str, str], ...] = (
    ("p0", "--p0"), ("sigma", "--sigma"), ("sigma_m", "--sigma-m"), ("sigma_gh", "--sigma-gh"),
    ("sigma_gv", "--sigma-gv"), ("p_nm0", "--p-nm0"), ("sigma_nm", "--sigma-nm"),
)


def add_model_options(
    parser: argparse.ArgumentParser, dmax: bool = True, given_only: bool = False,
    title: str = "model (paper table 1 defaults)", census: bool = False, sweep: bool = False,
    hardware: bool = False, board_engine: bool = False,
) -> argparse._ActionsContainer:
    """The disparity model's options (paper table 1 defaults): ``--dmax`` unless ``dmax=False``,
    ``--p0``, ``--sigma`` / ``--sigma-m|gh|gv``, ``--p-nm0``, ``--sigma-nm``; with ``census``,
    ``--model`` and the census model's options (:func:`add_census_options`; ``sweep``: a list;
    ``hardware``, ``board_engine``: its default, as there).

    ``given_only``: every option but ``--dmax`` stays None unless given (the defaults are filled in
    by :func:`model_params_from_args`), so that a command can refuse them where they do not apply."""
    defaults = ModelParams()
    g = parser.add_argument_group(title)
    if dmax:
        add_dmax_option(g)

    def default(value: float) -> float | None:
        return None if given_only else value

    g.add_argument("--p0", type=float_arg, default=default(defaults.p0),
                   help=f"base match likelihood p0 (default {defaults.p0:g})")
    g.add_argument("--sigma", type=float_arg, default=None,
                   help=f"sigma of all three features (default {defaults.sigma_m:g})")
    for f, name in (("m", "mean"), ("gh", "horizontal gradient"), ("gv", "vertical gradient")):
        g.add_argument(f"--sigma-{f}", type=float_arg, default=None, help=f"sigma of the {name} feature")
    g.add_argument("--p-nm0", type=float_arg, default=default(defaults.p_nm0),
                   help=f"base no-match probability ({defaults.p_nm0:g})")
    g.add_argument("--sigma-nm", type=float_arg, default=default(defaults.sigma_nm),
                   help=f"no-match sigma ({defaults.sigma_nm:g})")
    if census:
        add_census_options(parser, sweep=sweep, hardware=hardware, board_engine=board_engine)
    return g


# The census model's options (dest, flag, ModelParams field, type): None unless given, refused with
# --model paper (they would do nothing).
_CENSUS_OPTIONS: tuple[tuple[str, str, Callable[[str], Any], str], ...] = (
    ("census_window", "--census-window", int_arg, "census window: 7 (7x7, 48 bits) or 5 (5x5, 24 bits) "
     "(default 7)"),
    ("census_p0", "--census-p0", float_arg, "base census likelihood p0 of L_c(h) = p0 + (1 - p0) "
     "exp(-h^2 / (2 sigma_c^2)) (default 0.02)"),
    ("census_sigma", "--census-sigma", float_arg, "census sigma_c (default 6 for 7x7, 3 for 5x5)"),
    ("census_nomatch_h", "--census-nomatch-h", int_arg, "the no-match row's census entry L_c(h_nm): its "
     "Hamming distance (default bits / 8: 6 for 7x7, 3 for 5x5; 0 leaves the row uncalibrated)"),
    ("prior_eps", "--prior-eps", float_arg, "neighbour prior floor eps of f(k) = eps + (1 - eps) "
     "exp(-k^2 / (2 s^2)), k = |d - d_neighbour| (default 0.05)"),
    ("prior_s", "--prior-s", float_arg, "neighbour prior width s (default 4)"),
    ("prior_nomatch", "--prior-nomatch", float_arg, "the no-match row's prior per matched neighbour "
     "(default f(s), 0.626; 0.1 with --model census-lr)"),
)
CENSUS_OPTION_FLAGS: tuple[tuple[str, str], ...] = (
    *((dest, flag) for dest, flag, _, _ in _CENSUS_OPTIONS), ("neighbour_prior", "--no-neighbour-prior"),
)
# The census-lr model's own options (issue 22), refused unless --model names census-lr.
_LR_OPTIONS: tuple[tuple[str, str, Callable[[str], Any], str], ...] = (
    ("lr_beta", "--lr-beta", float_arg, "the consistency column's factor beta of an inconsistent lane, "
     "|d_R(x - d) - d| > tolerance (default 0.1)"),
    ("lr_gamma", "--lr-gamma", float_arg, "the consistency column's no-match factor gamma when any lane is "
     "consistent (1 when none is) (default 0.01)"),
    ("lr_tolerance", "--lr-tolerance", int_arg, "the left-right test's tolerance in disparities (default 1)"),
    ("lr_right_max_cycles", "--lr-right-max-cycles", int_arg, "the right pass's watchdog in cycles: a right "
     "pixel stopped by it has no right MAP (default: the left pass's watchdog, --max-cycles)"),
)
LR_OPTION_FLAGS: tuple[tuple[str, str], ...] = (
    *((dest, flag) for dest, flag, _, _ in _LR_OPTIONS), ("lr_nomatch", "--no-lr-nomatch"),
    ("lr_right_nomatch", "--lr-right-nomatch"), ("lr_neutral", "--lr-neutral"),
)


def model_list(text: str) -> list[str]:
    """``MODEL,MODEL,...`` models (for sweeps), each one of :data:`~bayesmachine.likelihood.MODELS`,
    no repeats."""
    names = [v.strip() for v in text.split(",") if v.strip()]
    if not names:
        raise argparse.ArgumentTypeError("give at least one model")
    for n in names:
        if n not in MODELS:
            raise argparse.ArgumentTypeError(f"unknown model {n!r}; choose from {', '.join(MODELS)}")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"a model is listed twice: {text!r}")
    return names


# Set (True) by add_census_options(hardware=True): the command builds or drives an FPGA design.
_HARDWARE_DEST = "model_default_is_hardware"


def default_model(args: argparse.Namespace) -> str:
    """The model a command runs when ``--model`` is not given, the one rule:
    :data:`~bayesmachine.likelihood.HARDWARE_MODEL` for what builds or drives an FPGA design (a
    command that declared ``add_census_options(hardware=True)``: emit, synth, board; ``run --engine
    board``; ``--machines K`` with K > 1, which census-lr refuses), else
    :data:`~bayesmachine.likelihood.DEFAULT_MODEL` (run, reference, sweep: on the host or in
    simulation)."""
    machines = getattr(args, "machines", None)
    if (getattr(args, _HARDWARE_DEST, False) or getattr(args, "engine", None) == "board"
            or (isinstance(machines, int) and machines > 1)):
        return HARDWARE_MODEL
    return DEFAULT_MODEL


def add_census_options(parser: argparse._ActionsContainer, sweep: bool = False,
                       title: str | None = "census model (--model census; issue 17 defaults)",
                       hardware: bool = False, board_engine: bool = False) -> None:
    """``--model`` (``paper``, or ``census``: + a census column, a calibrated no-match row and the
    raster-order neighbour prior) and the census model's options, all None unless given; without
    ``--model``, :func:`default_model` decides.

    ``sweep``: ``--model`` takes a comma-separated list (:func:`model_list`). ``hardware``: the
    command builds or drives an FPGA design (its default model is
    :data:`~bayesmachine.likelihood.HARDWARE_MODEL`). ``board_engine``: the command has ``--engine
    board`` and ``--machines`` (``run``), which :func:`default_model` reads; its help says so."""
    g = parser.add_argument_group(title) if title else parser
    described = ("paper: the paper's m, gH, gV columns; census: + a census column, a no-match row "
                 "calibrated for it and the raster-order neighbour prior on the machine's own results; "
                 "census-lr: + a left-right consistency column from a right pass")
    why = f"{DEFAULT_MODEL}'s StereoMachine does not place on the ECP5-85F; README, Models"
    if hardware:
        default = f"default {HARDWARE_MODEL}: {why}"
        parser.set_defaults(**{_HARDWARE_DEST: True})
    elif board_engine:
        default = (f"default {DEFAULT_MODEL}; {HARDWARE_MODEL} with --engine board or --machines K > 1: "
                   f"{why}; its right pass runs on one machine")
    else:
        default = f"default {DEFAULT_MODEL}"
    if sweep:
        g.add_argument("--model", type=model_list, default=None, metavar="MODEL,MODEL,...",
                       help=f"comma-separated models to compare side by side, each over every random source "
                       f"and counter max ({described}) ({default})")
    else:
        g.add_argument("--model", choices=MODELS, default=None,
                       help=f"the disparity model ({described}) ({default})")
    for dest, flag, kind, text in _CENSUS_OPTIONS:
        g.add_argument(flag, dest=dest, type=kind, default=None, help=text)
    g.add_argument("--neighbour-prior", dest="neighbour_prior", action=argparse.BooleanOptionalAction,
                   default=None, help="the census model's raster-order neighbour prior (default on)")
    lr = parser.add_argument_group("left-right consistency (--model census-lr; issue 22)") \
        if title else parser
    for dest, flag, kind, text in _LR_OPTIONS:
        lr.add_argument(flag, dest=dest, type=kind, default=None, help=text)
    lr.add_argument("--lr-nomatch", dest="lr_nomatch", action=argparse.BooleanOptionalAction, default=None,
                    help="the left pass's no-match row (default on; off: no no-match row at all)")
    lr.add_argument("--lr-right-nomatch", dest="lr_right_nomatch", action=argparse.BooleanOptionalAction,
                    default=None, help="give the right pass the census model's no-match row (default on; "
                    "off: no no-match row, the issue's right pass)")
    lr.add_argument("--lr-neutral", dest="lr_neutral", action=argparse.BooleanOptionalAction, default=None,
                    help="a lane whose right pixel has no right MAP (the right pass's no match or a timeout) "
                    "gets factor 1, no information (default on; off: beta, the issue's rule)")


def model_names_from_args(args: argparse.Namespace) -> list[str]:
    """The model(s) ``--model`` names: a list (a sweep's) or one, :func:`default_model`'s if not given."""
    value = getattr(args, "model", None)
    if value is None:
        return [default_model(args)]
    return list(value) if isinstance(value, list) else [value]


def _census_kwargs(args: argparse.Namespace, names: list[str]) -> dict[str, Any]:
    given = {dest: getattr(args, dest) for dest, _ in CENSUS_OPTION_FLAGS
             if getattr(args, dest, None) is not None}
    if given and not {"census", "census-lr"} & set(names):
        flags = ", ".join(flag if dest != "neighbour_prior" or not given[dest] else "--neighbour-prior"
                          for dest, flag in CENSUS_OPTION_FLAGS if dest in given)
        raise ParameterError(f"{flags}: options of --model census and census-lr, which do not apply to "
                             f"--model {','.join(names)}")
    prior = [flag for dest, flag in CENSUS_OPTION_FLAGS if dest.startswith("prior_") and dest in given]
    if prior and given.get("neighbour_prior") is False:  # they would be recorded and do nothing
        raise ParameterError(f"{', '.join(prior)}: options of the neighbour prior, which "
                             "--no-neighbour-prior turns off; give one or the other")
    return given


def _lr_kwargs(args: argparse.Namespace, names: list[str]) -> dict[str, Any]:
    given = {dest: getattr(args, dest) for dest, _ in LR_OPTION_FLAGS
             if getattr(args, dest, None) is not None}
    if given and "census-lr" not in names:
        def spelt(dest: str, flag: str) -> str:  # a yes/no option as it was given
            if isinstance(given[dest], bool):
                return "--" + ("" if given[dest] else "no-") + dest.replace("_", "-")
            return flag

        flags = ", ".join(spelt(dest, flag) for dest, flag in LR_OPTION_FLAGS if dest in given)
        raise ParameterError(f"{flags}: options of --model census-lr, which do not apply to --model "
                             f"{','.join(names)}")
    return given


def model_params_from_args(args: argparse.Namespace, name: str | None = None) -> ModelParams:
    """``ModelParams`` from :func:`add_model_options`' options (``--sigma-X`` wins over ``--sigma``;
    an option left at None takes the paper's default) and :func:`add_census_options`' (``--model``,
    :func:`default_model`'s if not given). ``name`` picks one model of a sweep's
    list; census options given with only ``paper`` models are refused."""
    defaults = ModelParams()
    names = model_names_from_args(args)
    census = _census_kwargs(args, names)
    lr = _lr_kwargs(args, names)
    name = names[0] if name is None else name
    if name not in ("census", "census-lr"):
        census = {}
    if name == "census-lr":
        census = {**census, **lr}

    def sigma(f: str) -> float:
        v = getattr(args, f"sigma_{f}")
        if v is not None:
            return float(v)
        return float(args.sigma) if args.sigma is not None else defaults.sigma(f)

    def given(name: str) -> float:
        v = getattr(args, name)
        return getattr(defaults, name) if v is None else float(v)

    return ModelParams(dmax=args.dmax, p0=given("p0"), sigma_m=sigma("m"), sigma_gh=sigma("gh"),
                       sigma_gv=sigma("gv"), p_nm0=given("p_nm0"), sigma_nm=given("sigma_nm"), name=name,
                       **census)
