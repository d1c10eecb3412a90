"""The one argument helper of every ``bayesmachine`` command that builds a machine.

Each machine option is declared once, in :data:`MACHINE_OPTIONS`: its ``MachineParams``
field, flag, type, choices and default all come from ``bayesmachine.params``, so ``emit``,
``run``, ``sweep`` (and ``synth``) accept the same spellings (``--seed 0x10`` everywhere)
and show the same defaults. A new machine option (e.g. a random source's own parameter)
is one :func:`add_option` call; commands pick it up through :func:`add_machine_options`
and :func:`machine_params_from_args`.

Type functions raise :class:`argparse.ArgumentTypeError` carrying the project's own
message, so argparse prints it instead of "invalid value"; the generic ones (numbers in ranges,
lists, paths) live in :mod:`bayesmachine.argtypes` and are re-exported here.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from bayesmachine.argtypes import (
    MAX_COUNTER_MAX,
    argument_type,
    choice_of,
    counter_max_list,
    float_arg,
    float_in_range,
    input_path,
    int_arg,
    int_in_range,
    int_of,
    on_off_list,
    output_path,
    positive_float_arg,
    positive_float_at_most,
    size_pair,
    value_list,
)
from bayesmachine.columns import Option, Source
from bayesmachine.integrators import INTEGRATOR_KINDS, IntegratorKind, integrator_kind, unread_fields
from bayesmachine.models import (
    BOARD_MODEL,
    DEFAULT_MODEL,
    MODELS,
    ModelParams,
    all_options,
    disparity_machine,
    machine_layout,
    model_names,
)
from bayesmachine.params import (
    DEFAULT_COUNTER_MAX,
    DEFAULT_DMAX,
    DEFAULT_INTEGRATOR,
    DEFAULT_LFSR_BITS,
    DEFAULT_MAX_CYCLES,
    DEFAULT_RNG,
    DEFAULT_SEED,
    DEFAULT_TIE_BREAK,
    DEFAULT_WORD_BITS,
    DEFAULT_WORDS_PER_BEAT,
    INTEGRATORS,
    PRIORS,
    RNG_KINDS,
    SAMPLES_PER_CLOCK,
    SMTJ_DEFAULTS,
    SMTJ_SHARES,
    STEREO_ROWS_PER_BEAT,
    TIE_BREAKS,
    TIMEOUT_ANSWERS,
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
    "flag_of",
    "with_flag",
    "model_names_from_args",
    "model_list",
    "default_model",
    "output_path",
    "input_path",
    "machine_default",
    "machine_params_from_args",
    "refuse_unread_options",
    "model_params_from_args",
    "options_without_effect",
    "machine_parameters",
    "pass_watchdogs",
    "float_arg",
    "positive_float_arg",
    "positive_float_at_most",
    "float_in_range",
    "size_pair",
    "int_in_range",
    "rng_list",
    "on_off_list",
    "runnable_sources",
    "argument_type",
    "int_arg",
    "counter_max_list",
    "MAX_COUNTER_MAX",
    "value_list",
    "choice_of",
    "int_of",
    "source_kinds",
    "rng_help",
]

# The board's serial link: the baud rate ``board build`` builds for and ``run --engine board`` opens
# the port at, unless told otherwise (here, where both commands' packages can read it).
DEFAULT_BAUD = 3_000_000
# ``run --engine board``'s bounds: the serial port's rates (pyserial overflows past 32 bits; USB-serial
# chips reach 12 Mbaud, the ULX3S's FT231X 3), and seconds of silence before a board is deemed mute.
BAUD_RANGE = (300, 12_000_000)
MAX_SILENCE_S = 600.0


_SMTJ_FIELDS = ("smtj_dwell", "smtj_spread", "smtj_share")


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
    # may use %(default)s; a function when it names the models (read when a parser is built, so that it
    # lists the models registered by then)
    help: str | Callable[[], str]
    type: Callable[[str], Any] = int_arg
    default: Any = None  # None: leave the field to MachineParams.for_disparity
    choices: tuple[str, ...] | None = None
    metavar: str | None = None

    @property
    def is_flag(self) -> bool:
        """A yes/no option (``type=bool``): ``--flag`` / ``--no-flag``, None unless given."""
        return self.type is bool

    @property
    def help_text(self) -> str:
        return self.help() if callable(self.help) else self.help

    def add_to(self, group: argparse._ActionsContainer, **changes: Any) -> argparse.Action:
        if self.is_flag and changes.pop("values", False):
            # A sweep's axis: --x (on), --x on,off (both: a grid axis) and --no-x (off).
            text = changes.pop("help", self.help_text)
            group.add_argument(self.flag, dest=self.field, nargs="?", const=True, type=on_off_list,
                               default=None, metavar="on,off", help=f"{text}; {self.flag} on,off sweeps both")
            return group.add_argument(f"--no-{self.flag[2:]}", dest=self.field, action="store_const",
                                      const=False, help=f"the same as {self.flag} off")
        if self.is_flag:
            flag_kwargs = {"dest": self.field, "default": self.default, "help": self.help_text,
                           "action": argparse.BooleanOptionalAction}
            flag_kwargs.update(changes)
            return group.add_argument(self.flag, **flag_kwargs)
        kwargs: dict[str, Any] = {
            "dest": self.field,
            "type": self.type,
            "default": self.default,
            "help": self.help_text,
            "metavar": self.metavar,
        }
        if self.choices is not None:
            kwargs["choices"] = self.choices
            kwargs.pop("metavar")
            kwargs["type"] = str
        kwargs.update(changes)
        return group.add_argument(self.flag, **kwargs)


MACHINE_OPTIONS: dict[str, MachineOption] = {}


def _machine_layouts() -> dict[str, tuple[str, int]]:
    """Each model's machine (prior, data columns) with its defaults, for the help texts."""
    return {name: machine_layout(ModelParams(name=name).columns) for name in model_names()}


def add_option(option: MachineOption) -> MachineOption:
    """Declare a machine option (once, at import) for every command that builds machines."""
    if option.field in MACHINE_OPTIONS:
        raise ValueError(f"machine option {option.field!r} is declared twice")
    MACHINE_OPTIONS[option.field] = option
    return option


# --columns, --prior and --max-cycles are left at None unless given: the model decides them (its data
# columns, its prior columns, its watchdog), and a given one that contradicts it is refused.
add_option(MachineOption(
    "columns", "--columns", lambda: "data-term operator columns N (default the model's: " + ", ".join(
        f"{data} with --model {name}" for name, (_, data) in _machine_layouts().items()) + ")", metavar="N"))
add_option(MachineOption("word_bits", "--word-bits",
                         "comparator resolution W; likelihood-memory words are W+1 bits "
                         "(default %(default)s)",
                         default=DEFAULT_WORD_BITS, metavar="W"))
add_option(MachineOption("counter_max", "--counter-max",
                         "counter max n_max: a counter overflows on its (n_max+1)-th 1 (default "
                         f"{DEFAULT_COUNTER_MAX})", metavar="N"))
# The stochastic machine's options are None unless given (their defaults are MachineParams'), so that
# an integrator that does not read them can refuse them when given (refuse_unread_options).
add_option(MachineOption("rng", "--rng", rng_help(), choices=RNG_KINDS))
add_option(MachineOption("lfsr_bits", "--lfsr-bits",
                         f"length L of each operator's LFSR, period 2^L-1 (default {DEFAULT_LFSR_BITS})",
                         metavar="L"))
add_option(MachineOption("seed", "--seed",
                         "machine seed: LFSR polynomials and start states; 0x.. accepted "
                         f"(default {DEFAULT_SEED})"))


def _runs(runs: int) -> str:
    n = DEFAULT_COUNTER_MAX
    return f"{runs} x (counter max + 1), {runs * (n + 1)} at counter max {n}"


def _watchdogs() -> str:
    return "; ".join(
        f"with --model {d.name} {_runs(d.watchdog_runs)}"
        + "".join(f", its {p.name} pass {_runs(p.watchdog_runs)}" for p in d.passes if p.watchdog_runs)
        for d in MODELS.values() if d.watchdog_runs)


def _models_with(test: Callable[[Any], bool]) -> str:
    """The models that pass ``test``, as a list in words ("a, b and c")."""
    names = [d.name for d in MODELS.values() if test(d)]
    return " and ".join(filter(None, (", ".join(names[:-1]), names[-1]))) if names else ""


def machine_default(field: str) -> Any:
    """``MachineParams``'s default of ``field`` (an integrator kind's field: that kind's): what the help says
    and a model that decides nothing gets."""
    for kind in INTEGRATOR_KINDS.values():
        if field in kind.defaults:
            return kind.defaults[field]
    return MachineParams.__dataclass_fields__[field].default


add_option(MachineOption("max_cycles", "--max-cycles",
                         lambda: "watchdog: a pixel stops as a timeout after this many cycles (samples) "
                         f"(default {DEFAULT_MAX_CYCLES}; {_watchdogs()})", metavar="N"))
add_option(MachineOption("timeout_answer", "--timeout-answer",
                         lambda: "what a run stopped by the watchdog answers (still flagged timeout): none "
                         "(no match) or leading (the row with the largest count, by the tie rule) (default "
                         f"{machine_default('timeout_answer')}; "
                         f"leading with --model {_models_with(lambda d: d.timeout_answer == 'leading')})",
                         choices=TIMEOUT_ANSWERS))
add_option(MachineOption("samples_per_clock", "--samples-per-clock",
                         "B random samples per operator and clock, one of "
                         f"{', '.join(map(str, SAMPLES_PER_CLOCK))}: the results of B = 1 in "
                         "ceil(cycles / B) clocks (the cycles reported are clocks; --max-cycles counts "
                         f"samples); rng sobol or external (default {machine_default('samples_per_clock')})",
                         metavar="B"))
add_option(MachineOption("normalize", "--normalize-columns",
                         lambda: "per-pixel column normalization: each loaded column's random numbers scaled "
                         "by m / 2^W, m the column's largest word for the pixel (exactly the run on the "
                         "words w * 2^W / m: the same posterior, shorter runs; docs/architecture.md) "
                         f"(default on with --model {_models_with(lambda d: d.normalize)}, "
                         f"{'on' if machine_default('normalize') else 'off'} otherwise)",
                         type=bool))
add_option(MachineOption("integrator", "--integrator",
                         "how a pixel's evidence is integrated: "
                         + "; ".join(f"{k.name} ({k.description})" for k in INTEGRATOR_KINDS.values())
                         + " (default %(default)s)",
                         default=DEFAULT_INTEGRATOR, choices=INTEGRATORS))
add_option(MachineOption("tie_break", "--tie-break",
                         "MAP encoder rule when several counters overflow in one cycle (default %(default)s)",
                         default=DEFAULT_TIE_BREAK, choices=TIE_BREAKS))
add_option(MachineOption("prior", "--prior",
                         lambda: "uniform: always-on 1s enter each row; loaded: an extra operator column 0 "
                         "holds a prior word per row (the host's: a uniform prior, 1.0); neighbour: the "
                         "neighbour prior (a feedback column from the "
                         "machine's own previous result and a loaded column), whose table is the model's "
                         "(default the model's: " + ", ".join(
                             f"{prior} with --model {name}"
                             for name, (prior, _) in _machine_layouts().items()) + ")", choices=PRIORS))
add_option(MachineOption("smtj_dwell", "--smtj-dwell",
                         f"--rng smtj: mean dwell time of a device state, in clock cycles (default "
                         f"{SMTJ_DEFAULTS[0]:g})",
                         type=float_arg, metavar="TAU"))
add_option(MachineOption("smtj_spread", "--smtj-spread",
                         f"--rng smtj: device-to-device spread, log-sd of each dwell time (default "
                         f"{SMTJ_DEFAULTS[1]:g}; 0.05 ~ 5 %%)", type=float_arg, metavar="S"))
add_option(MachineOption("smtj_share", "--smtj-share",
                         "--rng smtj: W devices per operator, or per column shared by its rows "
                         f"(default {SMTJ_DEFAULTS[2]})", type=str, choices=SMTJ_SHARES))
add_option(MachineOption("words_per_beat", "--words-per-beat",
                         f"likelihood-memory words per load beat (default {DEFAULT_WORDS_PER_BEAT}, "
                         f"or one pixel's words if fewer; {STEREO_ROWS_PER_BEAT} rows' words with the "
                         "front end: --feed pixels, --top stereo; census-lr's right pass takes as many "
                         "rows per beat)", metavar="N"))


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


def flag_of(parameter: str | None) -> str | None:
    """The command line's spelling of a library parameter (None: no option sets it)."""
    if parameter is None:
        return None
    if parameter in MACHINE_OPTIONS:
        return MACHINE_OPTIONS[parameter].flag
    if parameter == "dmax":
        return "--dmax"
    if parameter == "name":
        return "--model"
    options = all_options()
    return options[parameter][0].flags if parameter in options else None


def with_flag(exc: ParameterError) -> ParameterError:
    """``exc`` with the flag of the parameter it names in front (``--census-sigma: census_sigma ...``):
    its ``parameter``, or else the parameter its message starts with (the sources' errors)."""
    message = str(exc)
    name = exc.parameter
    if name is None:
        first = re.match(r"[a-z][a-z0-9_]*", message)
        name = first.group(0) if first else None
    flag = flag_of(name)
    if flag is None or message.startswith("--"):
        return exc
    return ParameterError(f"{flag}: {message}", name)


def refuse_unread_options(args: argparse.Namespace, given: Mapping[str, Any],
                          kinds: Iterable[IntegratorKind]) -> None:
    """ParameterError naming every option given (``given``: the machine fields set) that none of the
    integrator ``kinds`` reads (another kind's fields, :func:`~bayesmachine.integrators.unread_fields`;
    and a declared pass's watchdog, census-lr's ``--lr-right-max-cycles``, where none reads
    ``max_cycles``): the machines would ignore them."""
    kinds = list(kinds)
    unread = unread_fields(kinds)
    flags = [_spelt_machine(MACHINE_OPTIONS[f], given[f]) for f in unread if given.get(f) is not None]
    if "max_cycles" in unread:
        flags += [all_options()[k][0].flag for k in sorted(pass_watchdogs())
                  if getattr(args, k, None) is not None]
    if flags:
        titles = " or ".join(k.title for k in kinds)
        names = ",".join(k.name for k in kinds)
        raise ParameterError(f"{', '.join(flags)}: without effect on the {titles} machine (--integrator "
                             f"{names} does not read them): leave them out", "integrator")


def _spelt_machine(option: MachineOption, value: Any) -> str:
    """A machine option as it was given (a yes/no option's --x or --no-x)."""
    return option.flag if not option.is_flag or value else f"--no-{option.flag[2:]}"


def machine_params_from_args(
    args: argparse.Namespace, dmax: int, model: ModelParams | None = None, **overrides: Any
) -> MachineParams:
    """``MachineParams.for_disparity(dmax, ...)`` from the declared options present in ``args``.

    ``overrides`` win over ``args`` (a sweep passes each ``counter_max``). Options left at
    None are left to ``for_disparity``'s defaults. With ``model``, the machine that model needs
    (:func:`~bayesmachine.models.disparity_machine`: its data columns and prior; a contradicting
    ``--columns`` or ``--prior`` is refused). A ParameterError names the option's flag.
    """
    kwargs: dict[str, Any] = {}
    for field in MACHINE_OPTIONS:
        value = getattr(args, field, None)
        if value is not None and not isinstance(value, list):
            kwargs[field] = value
    kwargs.update(overrides)
    refuse_unread_options(args, kwargs, [integrator_kind(kwargs.get("integrator", DEFAULT_INTEGRATOR))])
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
    if kwargs.get("prior") == "neighbour" and (model is None
                                               or machine_layout(model.columns)[0] != "neighbour"):
        with_prior = [n for n, (prior, _) in _machine_layouts().items() if prior == "neighbour"]
        raise ParameterError(f"--prior neighbour: the neighbour prior's machine takes its feedback table "
                             f"from the model: use --model {' or '.join(with_prior)} (and leave --prior out)")
    try:
        if model is not None:
            return disparity_machine(model, **kwargs)
        return MachineParams.for_disparity(dmax, **kwargs)
    except ParameterError as exc:
        raise with_flag(exc) from None


def _paper_options() -> list[Option]:
    return list(MODELS["paper"].options.values())


def _alias_dest(option: Option) -> str:
    return option.alias.lstrip("-").replace("-", "_") if option.alias else option.name


# The options of add_model_options after --dmax (dest, flag): the paper model's, and their aliases.
MODEL_OPTION_FLAGS: tuple[tuple[str, str], ...] = tuple(dict.fromkeys(
    pair for o in _paper_options()
    for pair in ((((_alias_dest(o), o.alias),) if o.alias else ()) + ((o.name, o.flag),))))


def _default_text(option: Option) -> str:
    """What an option's default is, for its help: the kind's, and a model's own where one differs."""
    if option.alias:
        return f"{option.alias}'s"
    if option.kind == "bool":
        text = "on" if option.default else "off"
    elif option.default is None:
        text = option.default_text or "none"
    else:
        text = f"{option.default:g}"
    def shown(v: object) -> str:
        return ("on" if v else "off") if option.kind == "bool" else f"{v:g}"

    own = [f"{shown(d.defaults[option.name])} with --model {d.name}" for d in MODELS.values()
           if option.name in d.defaults]
    return "; ".join([text, *own])


def _add_option(group: argparse._ActionsContainer, option: Option) -> None:
    """One model option, None unless given (the model fills in its default)."""
    text = f"{option.help} (default {_default_text(option)})"
    if option.kind == "bool":
        group.add_argument(option.flag, dest=option.name, action=argparse.BooleanOptionalAction, default=None,
                           help=text)
        return
    parse = int_arg if option.kind == "int" else float_arg
    group.add_argument(option.flag, dest=option.name, type=parse, default=None, help=text)


def add_model_options(
    parser: argparse.ArgumentParser, dmax: bool = True, title: str = "model (paper table 1 defaults)",
    census: bool = False, sweep: bool = False, default: str | None = None,
) -> argparse._ActionsContainer:
    """The paper model's options (its columns' parameters, paper table 1 defaults): ``--dmax`` unless
    ``dmax=False``, ``--p0``, ``--sigma`` / ``--sigma-m|gh|gv``, ``--p-nm0``, ``--sigma-nm``; with
    ``census``, ``--model`` and the other models' options (:func:`add_census_options`; ``sweep``: a
    list; ``default``: the help's words for ``--model``'s default). Every option is None unless given
    (the model fills in its defaults), so that a command can refuse one where it does not apply."""
    g = parser.add_argument_group(title)
    if dmax:
        add_dmax_option(g)
    aliases: set[str] = set()
    for option in _paper_options():
        if option.alias and option.alias not in aliases:
            aliases.add(option.alias)
            sharing = [o.name for o in _paper_options() if o.alias == option.alias]
            g.add_argument(option.alias, dest=_alias_dest(option), type=float_arg, default=None,
                           help=f"sets {', '.join(sharing)} (default {option.default:g})")
        _add_option(g, option)
    if census:
        add_census_options(parser, sweep=sweep, default=default)
    return g


def _model_groups() -> dict[str, list[Option]]:
    """The options of every model but the paper's, grouped by the first model that has them."""
    groups: dict[str, list[Option]] = {}
    for option, owners in all_options().values():
        if "paper" not in owners:
            groups.setdefault(owners[0], []).append(option)
    return groups


def model_list(text: str) -> list[str]:
    """``MODEL,MODEL,...`` models (for sweeps), each one of :data:`~bayesmachine.models.MODELS` (registered
    ones included), no repeats."""
    names = [v.strip() for v in text.split(",") if v.strip()]
    if not names:
        raise argparse.ArgumentTypeError("give at least one model")
    for n in names:
        if n not in MODELS:
            raise argparse.ArgumentTypeError(f"unknown model {n!r}; choose from {', '.join(model_names())}")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"a model is listed twice: {text!r}")
    return names


def default_model(args: argparse.Namespace) -> str:
    """The model a command runs when ``--model`` is not given: :data:`~bayesmachine.models.DEFAULT_MODEL`
    on the host, in simulation, in ``emit`` and ``synth``; :data:`~bayesmachine.models.BOARD_MODEL` for
    what builds or drives a board (``board build``, ``board simulate``, ``run --engine board``), so that a
    default run on a board computes what the default bitstream carries."""
    if getattr(args, "board_command", None) is not None or getattr(args, "engine", None) == "board":
        return BOARD_MODEL
    return DEFAULT_MODEL


def add_census_options(parser: argparse._ActionsContainer, sweep: bool = False,
                       title: str | None = "model", default: str | None = None) -> None:
    """``--model`` and the options of every model but the paper's (each declared by its column kind),
    grouped by model, all None unless given; without ``--model``, :func:`default_model` decides.

    ``sweep``: ``--model`` takes a comma-separated list (:func:`model_list`); ``default``: the help's
    words for its default (``DEFAULT_MODEL`` unless given), the command's case of :func:`default_model`."""
    g = parser.add_argument_group(title) if title else parser
    described = "; ".join(f"{d.name}: {d.description}" for d in MODELS.values())
    default = f"default {DEFAULT_MODEL if default is None else default}"
    if sweep:
        g.add_argument("--model", type=model_list, default=None, metavar="MODEL,MODEL,...",
                       help=f"comma-separated models to compare side by side, each over every random source "
                       f"and counter max ({described}) ({default})")
    else:
        g.add_argument("--model", choices=model_names(), default=None,
                       help=f"the disparity model ({described}) ({default})")
    for owner, options in _model_groups().items():
        others = [n for n in model_names()
                  if n != owner and all(o.name in MODELS[n].options for o in options)]
        label = f"--model {owner}" + "".join(f", {n}" for n in others)
        group = parser.add_argument_group(f"{owner} model ({label})") if title else parser
        for option in options:
            _add_option(group, option)


def model_names_from_args(args: argparse.Namespace) -> list[str]:
    """The model(s) ``--model`` names: a list (a sweep's) or one, :func:`default_model`'s if not given."""
    value = getattr(args, "model", None)
    if value is None:
        return [default_model(args)]
    return list(value) if isinstance(value, list) else [value]


def _spelt(option: Option, value: Any) -> str:
    """An option as it was given (a yes/no option's --x or --no-x)."""
    if option.kind == "bool":
        return option.flag if value else f"--no-{option.flag[2:]}"
    return option.flag


def model_params_from_args(args: argparse.Namespace, name: str | None = None) -> ModelParams:
    """``ModelParams`` of the model options given (an option left at None takes the model's default;
    ``--sigma-X`` wins over its alias ``--sigma``) and ``--model`` (:func:`default_model`'s if not given).
    ``name`` picks one model of a sweep's list; an option that none of the listed models has is refused,
    naming the models that have it."""
    names = model_names_from_args(args)
    name = names[0] if name is None else name
    given: dict[str, Any] = {}
    refused: dict[str, list[str]] = {}
    for key, (option, owners) in all_options().items():
        value = getattr(args, key, None)
        if value is None and option.alias:
            value = getattr(args, _alias_dest(option), None)
        if value is None:
            continue
        if not set(owners) & set(names):
            refused.setdefault(", ".join(owners), []).append(_spelt(option, value))
        elif name in owners:
            given[key] = value
    if refused:
        owners = [n for n in model_names() if any(n in o.split(", ") for o in refused)]
        flags = [f for fs in refused.values() for f in fs]
        raise ParameterError(f"{', '.join(flags)}: options of --model {' and '.join(owners)}, which do not "
                             f"apply to --model {','.join(names)}")
    prior = [f"--{k.replace('_', '-')}" for k in ("prior_eps", "prior_s", "prior_nomatch") if k in given]
    if prior and given.get("neighbour_prior") is False:  # they would be recorded and do nothing
        raise ParameterError(f"{', '.join(prior)}: options of the neighbour prior, which "
                             "--no-neighbour-prior turns off; give one or the other")
    try:
        return ModelParams(name=name, dmax=args.dmax, **given)
    except ParameterError as exc:
        raise with_flag(exc) from None


def pass_watchdogs() -> frozenset[str]:
    """The model parameters that set a declared pass's watchdog (census-lr's lr_right_max_cycles): what
    only a machine's run reads (the models registered by now)."""
    return frozenset(p.watchdog_option for d in MODELS.values() for p in d.passes if p.watchdog_option)


def machine_parameters(name: str) -> frozenset[str]:
    """The parameters of model ``name`` that change its own pass's machine (``emit``/``synth --top
    machine``): the options that change its columns (``ModelDef.layout_options``: the switches, a fused
    column's ``fuse_columns``) and the options of its feedback column (the table the machine forms its
    prior from). The others change only the words the host loads, or other passes."""
    d = MODELS[name]
    own = {o.name for c in d.columns if c.source is Source.FEEDBACK for o in c.options}
    return frozenset({o.name for o in d.layout_options} | own)


def options_without_effect(args: argparse.Namespace, effective: Iterable[str]) -> list[str]:
    """The model options given in ``args`` (an alias counts for each parameter it sets) that set none of
    the parameters ``effective``, as they were spelt: what a command refuses because it would ignore them."""
    effective = set(effective)
    out: list[str] = []
    for key, (option, _) in all_options().items():
        value = getattr(args, key, None)
        if value is not None and key not in effective:
            out.append(_spelt(option, value))
    for dest, flag in MODEL_OPTION_FLAGS:
        sets = [o.name for o in _paper_options() if o.alias == flag]
        if sets and getattr(args, dest, None) is not None and not effective & set(sets):
            out.append(flag)
    return out
