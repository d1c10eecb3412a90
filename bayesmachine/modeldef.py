"""A model's definition: data, checked once, from the package or from a user's own file.

A :class:`ModelDef` lists column kinds (:mod:`bayesmachine.columns`) in operator order with a no-match
rule, the switches that leave columns out, the passes run before its own (:class:`PassDef`) and the
defaults of its machine; :func:`bayesmachine.models.register_model` makes it a model of the library and
of every command. Building one checks its structure, each problem one error naming the model: a column
that is not a :class:`~bayesmachine.columns.Column` kind, a column listed twice, two columns owning one
option, a switch, default or requirement naming no option of the model, a machine layout no machine
runs (with every switch on or off), a pass of a bad kind or reading no declared pass. What depends on
the other models (a name already taken, a pass naming an unknown model, a cycle of passes) is checked
by ``register_model``.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from bayesmachine.checks import plain
from bayesmachine.columns import Column, NoMatchFloor, Option, Source, Term
from bayesmachine.integrators.stochastic import STOCHASTIC
from bayesmachine.params import DEFAULT_COUNTER_MAX, TIMEOUT_ANSWERS, ParameterError

__all__ = ["PassDef", "ModelDef", "OWN_PASS", "REFERENCES", "MODEL_NAME", "MAX_WATCHDOG", "MAX_WATCHDOG_RUNS",
           "check_model_name", "machine_layout"]

# The model's own pass (its output: the left image as reference) is named so.
OWN_PASS = "left"
# A pass's reference image: lane d pairs reference map column x with x - d ("left") or x + d ("right").
REFERENCES = ("left", "right")
# Data columns a machine takes (MachineParams.columns).
MAX_DATA_COLUMNS = 64
# The largest watchdog a machine counts (MachineParams.max_cycles), and a model's or a pass's largest
# watchdog_runs: the runs of n_max + 1 cycles that fit it at the default counter max.
MAX_WATCHDOG = (1 << 32) - 1
MAX_WATCHDOG_RUNS = MAX_WATCHDOG // (DEFAULT_COUNTER_MAX + 1)
# A model's name: a value of --model and of a comma-separated list of models (sweep's), so no comma,
# space or leading "-" (argparse would read it as an option).
MODEL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")


@dataclass(frozen=True, kw_only=True)
class PassDef:
    """A pass a model runs before its own: the columns of model ``model`` over the pixels of the
    ``reference`` image ("right": lane d pairs right map column x_r with left map column x_r + d), on
    machine ``machine_index`` (>= 1) of a row (:func:`~bayesmachine.params.nth_machine`: its own seed).

    ``nomatch_option``: the model's yes/no option giving the pass ``model``'s no-match row (off: word 0,
    the row never fires; None: always); ``watchdog_option``: the model's option giving its watchdog in
    cycles (None left there: ``watchdog_runs`` runs of n_max + 1 cycles, or the machine's);
    ``not_inherited``: the model's options the pass does not take (it keeps ``model``'s defaults);
    ``options``: options of the pass's own (census-lr's ``lr_right_nomatch``, ``lr_right_max_cycles``),
    options of the model as its columns' are, which ``nomatch_option`` and ``watchdog_option`` may name;
    ``sets``: (option of ``model``, option of the model) pairs, the pass's option given by the model's,
    in place of the inherited value (census-sgm's ``lr_right_sgm_paths`` gives its right pass's
    ``sgm_paths``). A column reads the pass by its ``name`` (:func:`~bayesmachine.columns.consistency`)."""

    name: str
    model: str
    reference: str
    machine_index: int
    nomatch_option: str | None = None
    watchdog_option: str | None = None
    not_inherited: tuple[str, ...] = ()
    watchdog_runs: int | None = None
    options: tuple[Option, ...] = ()
    sets: tuple[tuple[str, str], ...] = ()


def _frozen(value: Any) -> Mapping[Any, Any]:
    return MappingProxyType(dict(value))


def check_model_name(name: object) -> None:
    """TypeError unless ``name`` is a string; ValueError unless it spells a model name
    (:data:`MODEL_NAME`): a value of ``--model`` and of a comma-separated list of models."""
    if not isinstance(name, str):
        raise TypeError(f"ModelDef: name must be a string, got {type(name).__name__} {name!r}")
    if not MODEL_NAME.fullmatch(name):
        raise ValueError(f"ModelDef: name {name!r} is not a model name: a letter, then letters, digits, '-' "
                         "or '_' (no spaces, commas or leading '-': it is a value of --model)")


def _sequence(d: ModelDef, field: str, value: Any, of: str) -> tuple[Any, ...]:
    """``value`` (a tuple or list) as a tuple; TypeError naming the model and the field otherwise (a
    single column kind or PassDef among them)."""
    if not isinstance(value, (tuple, list)):
        what = value.__name__ if isinstance(value, type) else repr(value)
        raise TypeError(f"model {d.name!r}: {field} must be a tuple (or list) of {of}, got {what}")
    return tuple(value)


def _mapping(d: ModelDef, field: str, value: Any) -> Mapping[Any, Any]:
    """``value`` if a mapping; TypeError naming the model and the field otherwise."""
    if not isinstance(value, Mapping):
        raise TypeError(f"model {d.name!r}: {field} must be a mapping (a dict), got {value!r}")
    return value


@dataclass(frozen=True, kw_only=True, eq=False)
class ModelDef:
    """A model as data (module text): columns in operator order and their no-match rule.

    Parameters
    ----------
    name, description : str
        The model's name (``--model NAME``: a letter, then letters, digits, ``-`` or ``_``,
        :data:`MODEL_NAME`) and one line for ``--help``.
    columns : sequence of Column kinds
        Its own pass's operator columns, in order: FEEDBACK then ABOVE columns first (the machine's prior
        columns), at least one FEATURES column.
    nomatch : NoMatchFloor kind
        Its no-match rule (default the paper's).
    switches : Mapping[Option, sequence of Column kinds]
        A yes/no option and the columns present only when it is on.
    passes : sequence of PassDef
        The passes run before its own, in order (their results feed its PASS columns).
    defaults : Mapping[str, value]
        Its own defaults for its columns' options.
    requires : Mapping[str, (value, reason)]
        Option values it needs, with the reason.
    watchdog_runs : int or None
        Its machine's default watchdog, in runs of n_max + 1 cycles, 1 .. :data:`MAX_WATCHDOG_RUNS` (None:
        the machine's default).
    timeout_answer : str
        Its machine's default answer to a timeout (:data:`~bayesmachine.params.TIMEOUT_ANSWERS`; default
        ``MachineParams``'s).
    normalize : bool
        Whether its machine normalizes its columns by default (``MachineParams.normalize``; default
        ``MachineParams``'s).
    """

    name: str
    description: str
    columns: tuple[type[Column], ...]
    nomatch: type[Term] = NoMatchFloor
    switches: Mapping[Option, tuple[type[Column], ...]] = field(default_factory=dict)
    passes: tuple[PassDef, ...] = ()
    defaults: Mapping[str, Any] = field(default_factory=dict)
    requires: Mapping[str, tuple[Any, str]] = field(default_factory=dict)
    watchdog_runs: int | None = None
    # The stochastic machine's defaults, not a copy of them.
    timeout_answer: str = STOCHASTIC.defaults["timeout_answer"]  # type: ignore[assignment]
    normalize: bool = STOCHASTIC.defaults["normalize"]  # type: ignore[assignment]

    def __post_init__(self) -> None:
        check_model_name(self.name)
        switches = _mapping(self, "switches", self.switches)
        for name, value in (("columns", _sequence(self, "columns", self.columns, "column kinds")),
                            ("passes", _sequence(self, "passes", self.passes, "PassDef")),
                            ("switches", _frozen({k: _sequence(self, f"switches[{getattr(k, 'name', k)}]", v,
                                                               "column kinds")
                                                  for k, v in switches.items()})),
                            ("defaults", _frozen(_mapping(self, "defaults", self.defaults))),
                            ("requires", _frozen(_mapping(self, "requires", self.requires)))):
            object.__setattr__(self, name, value)
        _check_kinds(self)
        _check_switches(self)
        object.__setattr__(self, "_options", _collect_options(self))  # two columns owning one option
        _check_names(self)
        _check_layouts(self)
        _check_passes(self)

    def _error(self, message: str) -> ValueError:
        return ValueError(f"model {self.name!r}: {message}")

    @property
    def options(self) -> dict[str, Option]:
        """Every parameter of the model, in order: its FEATURES columns', the no-match rule's, the other
        columns', its PASS columns', its passes' own; a switch just before the options of the first
        column it switches."""
        return dict(self._options)  # type: ignore[attr-defined]

    def resolve(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """The values of every option: given ones checked, the others their defaults (keys already
        known to be options)."""
        values: dict[str, Any] = {}
        for name, option in self.options.items():
            v = given.get(name)
            if v is None:
                v = self.defaults.get(name, option.default)
            if v is None and option.resolve is not None:
                v = option.resolve(values)
            if v is not None or not option.optional:
                option.check(name, v, values)
            values[name] = plain(v)  # np.int64(7) is 7: the model's values are plain Python values
        for name, (want, why) in self.requires.items():
            if values[name] != want:
                said = {True: "on", False: "off"}.get(want, repr(want))
                raise ParameterError(f"{name} must be {said} for the {self.name} model ({why})", name)
        return values

    def present(self, values: Mapping[str, Any]) -> tuple[type[Column], ...]:
        """Its columns with the switches of ``values``, each as it expands with them (a fused column with
        ``fuse_columns`` off: its members)."""
        off = {c for option, kinds in self.switches.items() if not values[option.name] for c in kinds}
        return tuple(k for c in self.columns if c not in off for k in c.expand(values))

    @property
    def layout_options(self) -> tuple[Option, ...]:
        """The yes/no options that change its columns: its switches, then its columns' own (a fused
        column's ``fuse_columns``)."""
        own = {o.name: o for c in self.columns for o in c.layout_options()}
        return (*self.switches, *own.values())


def _collect_options(d: ModelDef) -> dict[str, Option]:
    data = [c for c in d.columns if c.source in (Source.FEATURES, Source.PASS)]
    kinds: list[type[Term]] = [*(c for c in data if c.source is Source.FEATURES), d.nomatch,
                               *(c for c in d.columns if c not in data),
                               *(c for c in data if c.source is Source.PASS)]
    before: dict[type[Term], list[Option]] = {}
    for switch, switched in d.switches.items():
        lead = next((k for k in kinds if k in switched), None)
        before.setdefault(lead, []).append(switch)  # type: ignore[arg-type]
    owners: list[tuple[str, tuple[Option, ...]]] = [
        (kind.__name__, (*before.get(kind, ()), *kind.options)) for kind in kinds]
    owners += [(f"pass {p.name}", _pass_options(d, p)) for p in d.passes if isinstance(p, PassDef)]
    out: dict[str, Option] = {}
    owner: dict[str, str] = {}
    for who, options in owners:
        for option in options:
            if out.setdefault(option.name, option) is not option:
                raise d._error(f"option {option.name} is declared twice (by {owner[option.name]} and "
                               f"{who}): one option, one owner")
            owner.setdefault(option.name, who)
    return out


def _pass_options(d: ModelDef, p: PassDef) -> tuple[Option, ...]:
    """A pass's own options, each an :class:`~bayesmachine.columns.Option` (TypeError naming the model)."""
    options = p.options if isinstance(p.options, (tuple, list)) else None
    if options is None or not all(isinstance(o, Option) for o in options):
        raise TypeError(f"model {d.name!r}: pass {p.name}: options must be a tuple of Options "
                        f"(bayesmachine.columns.Option), got {p.options!r}")
    return tuple(options)


def _check_kinds(d: ModelDef) -> None:
    """Every column a Column kind (once), the rule a no-match rule, at least one FEATURES column."""
    if not d.columns:
        raise d._error("a model needs columns")
    for i, kind in enumerate(d.columns):
        column = isinstance(kind, type) and issubclass(kind, Column)
        if not (column and isinstance(getattr(kind, "source", None), Source)):
            raise TypeError(f"model {d.name!r}: columns[{i}] = {kind!r} is not a column kind (a subclass of "
                            "bayesmachine.columns.Column with a source)")
    names = [k.name for k in d.columns]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise d._error(f"column {twice[0]} is listed twice")
    if not (isinstance(d.nomatch, type) and issubclass(d.nomatch, NoMatchFloor)):
        raise TypeError(f"model {d.name!r}: nomatch = {d.nomatch!r} is not a no-match rule (a subclass of "
                        "bayesmachine.columns.NoMatchFloor)")
    _check_watchdog_runs(d, "watchdog_runs", d.watchdog_runs)
    if not isinstance(d.normalize, bool):
        raise d._error(f"normalize must be True or False, got {d.normalize!r}")
    if d.timeout_answer not in TIMEOUT_ANSWERS:
        raise d._error(f"timeout_answer must be one of {', '.join(TIMEOUT_ANSWERS)}, got "
                       f"{d.timeout_answer!r}")


def _check_watchdog_runs(d: ModelDef, field: str, runs: object) -> None:
    """None, or runs whose watchdog a machine counts at the default counter max."""
    if runs is None:
        return
    if isinstance(runs, bool) or not isinstance(runs, int):
        raise d._error(f"{field} must be an integer or None, got {runs!r}")
    if not 1 <= runs <= MAX_WATCHDOG_RUNS:
        raise d._error(f"{field} must be in [1, {MAX_WATCHDOG_RUNS}] runs of counter max + 1 cycles (a "
                       f"machine's watchdog counts at most {MAX_WATCHDOG} cycles: {MAX_WATCHDOG_RUNS} runs "
                       f"at the default counter max {DEFAULT_COUNTER_MAX}), got {runs}")


def _check_switches(d: ModelDef) -> None:
    """Switches are yes/no options over the model's columns."""
    for option, kinds in d.switches.items():
        if not isinstance(option, Option) or option.kind != "bool":
            raise d._error(f"a switch must be a yes/no Option (kind 'bool'), got {option!r}")
        stray = [getattr(k, "__name__", repr(k)) for k in kinds if k not in d.columns]
        if not kinds or stray:
            raise d._error(f"switch {option.name} must name some of the model's columns, got "
                           f"{stray or 'none'}")


def _check_names(d: ModelDef) -> None:
    options = d.options
    for name, need in d.requires.items():
        if not (isinstance(need, tuple) and len(need) == 2 and isinstance(need[1], str)):
            raise TypeError(f"model {d.name!r}: requires[{name!r}] must be a (value, reason) pair, got "
                            f"{need!r}")
    for what, names in (("defaults", d.defaults), ("requires", d.requires)):
        for name in names:
            if name not in options:
                raise d._error(f"{what} names {name!r}, not an option of the model's columns "
                               f"({', '.join(options)})")


def machine_layout(columns: tuple[Any, ...]) -> tuple[str, int]:
    """(prior, data columns) of the machine that runs ``columns`` (kinds or columns): its leading FEEDBACK
    and ABOVE columns are the machine's prior columns (``"neighbour"``: feedback then loaded;
    ``"loaded"``: one loaded; ``"uniform"``: none), the rest its data columns."""
    lead = [c.source for c in columns if c.source in (Source.FEEDBACK, Source.ABOVE)]
    prior = {(): "uniform", (Source.ABOVE,): "loaded", (Source.FEEDBACK, Source.ABOVE): "neighbour"}.get(
        tuple(lead))
    if prior is None or tuple(c.source for c in columns[: len(lead)]) != tuple(lead):
        raise ValueError(f"no machine runs columns {[c.name for c in columns]}: its prior columns lead, "
                         "a feedback column before a loaded one")
    return prior, len(columns) - len(lead)


def _check_layouts(d: ModelDef) -> None:
    """A machine runs the columns with every combination of switches (and layout options); each keeps a
    FEATURES column, lists no column twice, and a fused column is its pass's only FEATURES column."""
    options = d.layout_options
    for on in itertools.product((True, False), repeat=len(options)):
        values = {option.name: state for option, state in zip(options, on, strict=True)}
        columns = d.present(values)
        names = [c.name for c in columns]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise d._error(f"column {twice[0]} is listed twice{_switched(values)}")
        try:
            _, data = machine_layout(columns)
        except ValueError as exc:
            raise d._error(f"{exc}{_switched(values)}") from None
        features = [c for c in columns if c.source is Source.FEATURES]
        if not features:
            raise d._error(f"no FEATURES column{_switched(values)}: the no-match rule sits in the first one")
        if any(c.holds_rule for c in features) and len(features) > 1:
            raise d._error(f"a fused column beside other FEATURES columns{_switched(values)}: it takes every "
                           "FEATURES column of its pass (list them among its members)")
        if data > MAX_DATA_COLUMNS:
            raise d._error(f"{data} data columns: a machine takes at most {MAX_DATA_COLUMNS}")


def _switched(values: Mapping[str, bool]) -> str:
    off = [name for name, on in values.items() if not on]
    return f" (with {', '.join(off)} off)" if off else ""


def _check_sets(d: ModelDef, p: PassDef) -> None:
    """``p.sets``: pairs of option names, the second an option of the model (the first, an option of the
    pass's model, is checked when the model is registered)."""
    pairs = _sequence(d, f"pass {p.name}: sets", p.sets, "(option, option) pairs")
    for pair in pairs:
        if not (isinstance(pair, tuple) and len(pair) == 2 and all(isinstance(n, str) for n in pair)):
            raise TypeError(f"model {d.name!r}: pass {p.name}: sets takes (option, option) pairs of names, "
                            f"got {pair!r}")
        if pair[1] not in d.options:
            raise d._error(f"pass {p.name}: sets {pair[0]} from {pair[1]!r}, not an option of the model")


def _check_passes(d: ModelDef) -> None:
    """Passes of the right kind, one name and one machine each; every PASS column reads a declared pass."""
    options = d.options
    names: list[str] = []
    for p in d.passes:
        if not isinstance(p, PassDef):
            raise TypeError(f"model {d.name!r}: a pass must be a PassDef, got {p!r}")
        if not isinstance(p.name, str) or not p.name or p.name == OWN_PASS or p.name in names:
            raise d._error(f"pass name {p.name!r}: each pass needs a name of its own (not {OWN_PASS!r}, the "
                           "model's own pass)")
        names.append(p.name)
        if p.reference not in REFERENCES:
            raise d._error(f"pass {p.name}: reference must be one of {', '.join(REFERENCES)}, got "
                           f"{p.reference!r}")
        index = p.machine_index
        if isinstance(index, bool) or not isinstance(index, int) or index < 1:
            raise d._error(f"pass {p.name}: machine_index must be an integer >= 1 (0 is the model's own "
                           f"machine), got {index!r}")
        for what, option, kind in (("nomatch_option", p.nomatch_option, "bool"),
                                   ("watchdog_option", p.watchdog_option, "int")):
            if option is not None and (option not in options or options[option].kind != kind):
                raise d._error(f"pass {p.name}: {what} {option!r} is not a {kind} option of the model")
        _check_watchdog_runs(d, f"pass {p.name}: watchdog_runs", p.watchdog_runs)
        stray = [o for o in _sequence(d, f"pass {p.name}: not_inherited", p.not_inherited, "option names")
                 if o not in options]
        if stray:
            raise d._error(f"pass {p.name}: not_inherited names {stray[0]!r}, not an option of the model")
        _check_sets(d, p)
    indices = [p.machine_index for p in d.passes]
    if len(set(indices)) != len(indices):
        raise d._error(f"two passes on one machine (machine_index {indices}): each pass runs on its own")
    for c in d.columns:
        if c.source is Source.PASS and not c.feeds_from:
            raise d._error(f"column {c.name} reads no pass: make its kind for the pass it reads "
                           "(consistency(pass name))")
        if c.source is Source.PASS and c.feeds_from not in names:
            raise d._error(f"column {c.name} reads the results of pass {c.feeds_from!r}, which the model "
                           f"does not declare (passes: {', '.join(names) or 'none'})")
