"""Disparity models as data: a list of evidence columns, a no-match rule and the passes they need.

A model definition (:class:`~bayesmachine.modeldef.ModelDef`) names its column kinds in operator order
(:mod:`bayesmachine.columns`), its no-match rule, the switches (yes/no options) that leave columns out,
and the passes run before its own (:class:`~bayesmachine.modeldef.PassDef`: another model with another
reference image, whose results feed a column). :func:`register_model` makes a definition, from the package
or from a user's own file, a model of the library and of every command. :class:`ModelParams` is one model
with its parameter values: flat keywords, each owned by one of its column kinds (the command line's
options are the same declarations). The three models of the package:

* ``paper``: the paper's columns m, gH, gV; no-match row [P_nm(gV), 1, 1]; a uniform prior.
* ``census``: + a census column (its no-match entry L_c(h_nm)) and the raster-order neighbour prior (a
  left column formed by the machine from its own previous result, an above column loaded from the
  previous map row's results); ``neighbour_prior=False`` leaves the prior's two columns out.
* ``census-lr``: census + a left-right consistency column fed by the MAPs of a right pass (the census
  model with the right image as reference, its own machine: seed of machine 1), the no-match factor of
  its prior 0.1 by default.

The census models' machines normalize their columns per pixel, stop a run after
:data:`CENSUS_WATCHDOG_RUNS` runs (census-lr's right pass after :data:`RIGHT_WATCHDOG_RUNS`) and answer
a timeout with the leading row; the paper's machine does none of these.

The machine a model's pass needs (:func:`disparity_machine`) follows from its columns: leading
FEEDBACK and ABOVE columns are the machine's prior columns ("neighbour": feedback then loaded;
"loaded": one loaded), the rest its data columns (:func:`~bayesmachine.modeldef.machine_layout`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from bayesmachine.checks import as_int, type_name
from bayesmachine.columns import (
    GRADIENT_MAGNITUDE,
    NEIGHBOUR_PRIOR,
    PATHS,
    AbovePrior,
    Census,
    Column,
    GradH,
    GradMag,
    GradV,
    LeftPrior,
    Mean,
    NoMatchFloor,
    Option,
    Plane,
    Source,
    Term,
    consistency,
    fused,
    semiglobal,
)
from bayesmachine.columns.base import check_int, check_switch
from bayesmachine.integrators import integrator_kind
from bayesmachine.modeldef import MAX_WATCHDOG, OWN_PASS, ModelDef, PassDef, machine_layout
from bayesmachine.params import (
    DEFAULT_DMAX,
    DEFAULT_INTEGRATOR,
    MAX_DMAX,
    STEREO_ROWS_PER_BEAT,
    MachineParams,
    ParameterError,
    nth_machine,
)

__all__ = [
    "ModelDef",
    "PassDef",
    "Pass",
    "ModelParams",
    "MODELS",
    "OWN_PASS",
    "model_names",
    "register_model",
    "DEFAULT_MODEL",
    "BOARD_MODEL",
    "CENSUS_WATCHDOG_RUNS",
    "RIGHT_WATCHDOG_RUNS",
    "RIGHT_PASS",
    "RIGHT_PASS_OPTIONS",
    "CENSUS_TIMEOUT_ANSWER",
    "all_options",
    "machine_layout",
    "disparity_machine",
    "pass_machine",
    "check_disparity_machine",
    "neighbour_words_per_beat",
]

# The one default model, of the library (ModelParams()) and of every command when none is named, on the
# host, in simulation and in emit / synth: census-sgm, the most accurate on the measurements
# (docs/models.md, "Which model by default").
DEFAULT_MODEL = "census-sgm"
# The board's default (board build, board simulate, run --engine board): census-lr, whose StereoMachine
# meets the ULX3S-85F's 45 MHz clock, which census-sgm's does not (docs/board.md; its log one at camera rate
# does not fit the 85F: docs/architecture.md, "The semi-global column on chip").
BOARD_MODEL = "census-lr"
# The census models' watchdog, in runs of n_max + 1 cycles: max_cycles = CENSUS_WATCHDOG_RUNS *
# (counter_max + 1) (255 at counter max 16). With normalized columns the winning row of a clear pixel
# fires almost every cycle (its run ends near n_max + 1 cycles); a pixel still running after 15 such
# runs is ambiguous, and the leading row answers it. census-lr's right pass, whose MAPs only feed the
# consistency column (a timeout gives no information), stops after RIGHT_WATCHDOG_RUNS. Chosen from the
# curve in docs/architecture.md ("The watchdog"), measured on the bundled pair and held-out pairs.
CENSUS_WATCHDOG_RUNS = 15
RIGHT_WATCHDOG_RUNS = 8
# The census models' answer to a timeout: the leading row (the counters hold the partial posterior);
# the paper's machine keeps "none" (a timeout is no match).
CENSUS_TIMEOUT_ANSWER = "leading"
# census-lr's right pass: its name (the key of its results, the consistency column's pass) and its options.
RIGHT_PASS = "right"


def _right_watchdog(name: str, value: object, values: Mapping[str, Any]) -> None:
    if value is not None:
        check_int(name, value, 2, (1 << 32) - 1)


RIGHT_PASS_OPTIONS = (
    Option("lr_right_nomatch", "bool", True, check_switch,
           "give the right pass its model's no-match row (off: none, word 0)"),
    Option("lr_right_max_cycles", "int", None, _right_watchdog, "the right pass's watchdog in cycles: a "
           "right pixel stopped by it has no right MAP", optional=True,
           default_text="the right pass's default watchdog, given with --max-cycles"),
)


PAPER = ModelDef(
    name="paper", description="the paper's m, gH, gV columns (and with --gradient-magnitude a "
    "gradient-magnitude column)", columns=(Mean, GradH, GradV, GradMag),
    switches={GRADIENT_MAGNITUDE: (GradMag,)})
CENSUS = ModelDef(
    name="census", description="+ a census column, a no-match row calibrated for it and the raster-order "
    "neighbour prior on the machine's own results",
    columns=(LeftPrior, AbovePrior, fused(Mean, GradH, GradV, Census)),
    switches={NEIGHBOUR_PRIOR: (LeftPrior, AbovePrior)},
    watchdog_runs=CENSUS_WATCHDOG_RUNS,
    timeout_answer=CENSUS_TIMEOUT_ANSWER, normalize=True)
CENSUS_LR = ModelDef(
    name="census-lr", description="+ a left-right consistency column from a right pass",
    columns=(*CENSUS.columns, consistency(RIGHT_PASS)), switches=CENSUS.switches,
    passes=(PassDef(name=RIGHT_PASS, model="census", reference="right", machine_index=1,
                    options=RIGHT_PASS_OPTIONS, nomatch_option="lr_right_nomatch",
                    watchdog_option="lr_right_max_cycles", not_inherited=("prior_nomatch",),
                    watchdog_runs=RIGHT_WATCHDOG_RUNS),),
    defaults={"prior_nomatch": 0.1},
    requires={"neighbour_prior": (True, "both passes use it")},
    watchdog_runs=CENSUS_WATCHDOG_RUNS, timeout_answer=CENSUS_TIMEOUT_ANSWER, normalize=True)

CENSUS_SG = ModelDef(
    name="census-sg", description="census with its fused column's energies aggregated along causal scanline "
    "paths (the semi-global column; census-sgm's right pass)",
    columns=(LeftPrior, AbovePrior, semiglobal(fused(Mean, GradH, GradV, Census))),
    switches={NEIGHBOUR_PRIOR: (LeftPrior, AbovePrior)},
    watchdog_runs=CENSUS_WATCHDOG_RUNS, timeout_answer=CENSUS_TIMEOUT_ANSWER, normalize=True)
# census-sgm's right pass aggregates along the left path alone by default: its MAPs only feed the
# consistency column, and one path gives the filled map of two without the row above's block RAM
# (docs/models.md, "The semi-global model").
def _right_paths(name: str, value: object, values: Mapping[str, Any]) -> None:
    check_int(name, value, 1, len(PATHS))


RIGHT_SGM_PATHS = Option("lr_right_sgm_paths", "int", 1, _right_paths, "the right pass's semi-global paths "
                         "(--sgm-paths sets the own pass's): the first N of left, top, top-left, top-right "
                         "(1 .. 4); its temperature is 1 / N")
CENSUS_SGM = ModelDef(
    name="census-sgm", description="census-lr with the semi-global column over its fused column, both passes",
    columns=(*CENSUS_SG.columns, consistency(RIGHT_PASS)), switches=CENSUS_SG.switches,
    passes=(PassDef(name=RIGHT_PASS, model="census-sg", reference="right", machine_index=1,
                    options=(*RIGHT_PASS_OPTIONS, RIGHT_SGM_PATHS), nomatch_option="lr_right_nomatch",
                    watchdog_option="lr_right_max_cycles",
                    not_inherited=("prior_nomatch", "sgm_temperature"),
                    sets=(("sgm_paths", RIGHT_SGM_PATHS.name),), watchdog_runs=RIGHT_WATCHDOG_RUNS),),
    defaults={"prior_nomatch": 0.1},
    requires={"neighbour_prior": (True, "both passes use it")},
    watchdog_runs=CENSUS_WATCHDOG_RUNS, timeout_answer=CENSUS_TIMEOUT_ANSWER, normalize=True)

# The models by name: the ones above, then those registered by register_model.
MODELS: dict[str, ModelDef] = {}


def model_names() -> tuple[str, ...]:
    """The names of the models known now (:data:`MODELS`, registered ones included), in order."""
    return tuple(MODELS)


def register_model(definition: ModelDef) -> ModelDef:
    """Make ``definition`` a model of the library (``ModelParams(name=...)``) and of every command in this
    process (``--model NAME``, listed by ``--help``); returns it.

    Besides the checks a :class:`ModelDef` makes of itself, one error naming the model for: a name
    already taken, a pass naming an unknown model, a cycle of passes (a pass of the model itself), a pass
    of a model with passes of its own (passes do not nest: declare them all in this model), an option
    spelled like another model's option but declared apart, or defaults that do not give a model (its
    values checked, its tables built)."""
    if not isinstance(definition, ModelDef):
        raise TypeError(f"register_model takes a ModelDef, not {type(definition).__name__}")
    d = definition
    if d.name in MODELS:
        raise ValueError(f"model {d.name!r}: the name is taken (models: {', '.join(MODELS)})")
    for p in d.passes:
        if p.model == d.name:
            raise ValueError(f"model {d.name!r}: a cycle of passes: its pass {p.name!r} runs the model "
                             "itself")
        if p.model not in MODELS:
            raise ValueError(f"model {d.name!r}: pass {p.name!r} names an unknown model {p.model!r} (models: "
                             f"{', '.join(MODELS)})")
        if MODELS[p.model].passes:
            raise ValueError(f"model {d.name!r}: pass {p.name!r} runs model {p.model!r}, which runs passes "
                             "of its own: passes do not nest, declare them all in this model")
        unknown = [name for name, _ in p.sets if name not in MODELS[p.model].options]
        if unknown:
            raise ValueError(f"model {d.name!r}: pass {p.name!r} sets {unknown[0]!r}, not an option of model "
                             f"{p.model!r}")
    known = all_options()
    for name, option in d.options.items():
        if name in known and known[name][0] is not option:
            raise ValueError(f"model {d.name!r}: its option {name} is declared apart from the option of "
                             f"that name of model {known[name][1][0]}: one name, one option")
    MODELS[d.name] = d
    try:
        ModelParams(name=d.name)
    except (ValueError, TypeError) as exc:
        del MODELS[d.name]
        raise type(exc)(f"model {d.name!r}: its defaults give no model: {exc}") from None
    return d


def all_options() -> dict[str, tuple[Option, tuple[str, ...]]]:
    """Every model parameter once, with the models that have it (in :data:`MODELS` order)."""
    out: dict[str, tuple[Option, tuple[str, ...]]] = {}
    for d in MODELS.values():
        for name, option in d.options.items():
            owners = out[name][1] if name in out else ()
            out[name] = (option, (*owners, d.name))
    return out


@dataclass(frozen=True, eq=False, kw_only=True)
class Pass:
    """One pass of a model: the columns of ``model`` (the model itself for its own pass, named
    :data:`~bayesmachine.modeldef.OWN_PASS`) over the pixels of the ``reference`` image, on machine
    ``machine_index`` of a row. ``nomatch``: whether its no-match row holds ``model``'s rule (else every
    FEATURES column's entry there is 0, the row never fires); ``max_cycles``: its own watchdog, given by
    the option ``watchdog_option`` (None: ``watchdog_runs`` runs of n_max + 1 cycles, or, without those,
    the machine's)."""

    name: str
    model: ModelParams = field(repr=False)
    reference: str = "left"
    nomatch: bool = True
    machine_index: int = 0
    max_cycles: int | None = None
    watchdog_option: str | None = None
    watchdog_runs: int | None = None

    @property
    def columns(self) -> tuple[Column, ...]:
        return self.model.columns

    @property
    def terms(self) -> tuple[Term, ...]:
        """Its columns and its no-match rule."""
        return (*self.model.columns, self.model.nomatch)

    @property
    def rule_column(self) -> Column:
        """The column whose no-match row holds the pass's no-match rule: its first FEATURES column."""
        return next(c for c in self.columns if c.source is Source.FEATURES)

    @property
    def step(self) -> int:
        """Lane d's match column: x - d (the left image as reference) or x + d (the right)."""
        return -1 if self.reference == "left" else 1

    @property
    def where(self) -> str:
        """The pass, for messages."""
        return f"the {self.name} pass (model {self.model.name})"


def _check_keys(definition: ModelDef, parameters: Mapping[str, Any]) -> None:
    """TypeError for a keyword no model has; ParameterError for one of other models only."""
    options = definition.options
    for key in parameters:
        if key not in options:
            owners = [d.name for d in MODELS.values() if key in d.options]
            if not owners:
                raise TypeError(f"ModelParams: no parameter named {key!r}")
            raise ParameterError(f"{key} is not a parameter of the {definition.name} model (it is one of "
                                 f"{', '.join(owners)})", key)


def _planes(passes: tuple[Pass, ...]) -> dict[str, Plane]:
    """The planes the passes' terms read, by name; ValueError when two terms read one name of two planes."""
    out: dict[str, Plane] = {}
    readers: dict[str, str] = {}
    for p in passes:
        for term in p.terms:
            for name, plane in term.planes().items():
                if out.setdefault(name, plane) != plane:
                    raise ValueError(f"plane {name}: {p.where}'s {term.name} reads it of {plane.window}x"
                                     f"{plane.window} windows, {readers[name]} of {out[name].window}x"
                                     f"{out[name].window} (or of another filter): one name, one plane")
                readers.setdefault(name, f"{p.where}'s {term.name}")
    return out


def _rebuild(values: dict[str, Any]) -> ModelParams:
    return ModelParams(**values)


class ModelParams:
    """A disparity model with its parameter values, validated up front.

    ``ModelParams(name=DEFAULT_MODEL, dmax=DEFAULT_DMAX, **parameters)`` (keywords only): every keyword is a
    parameter
    of one of the named model's column kinds (or its no-match rule), read back as an attribute
    (``model.census_sigma``); a parameter left out or None takes its default (the model's own, or the
    kind's, resolved: ``census_sigma`` 6 for 7x7, 3 for 5x5). Wrong types raise TypeError, impossible
    values :class:`~bayesmachine.params.ParameterError` naming the parameter. Two models with the same
    values are equal; ``to_dict()`` lists every value and ``ModelParams(**to_dict())`` is the same model.

    Parameters
    ----------
    name : str
        The model, one of :data:`MODELS` (default :data:`DEFAULT_MODEL`, the command line's).
    dmax : int
        The largest disparity, 0 .. 4094 (default 80).
    **parameters
        Its column kinds' parameters (:func:`all_options`; e.g. ``sigma_m``, ``census_window``,
        ``lr_beta``); None or left out: the default.

    Attributes
    ----------
    name, dmax : str, int
        The model (one of :data:`MODELS`) and its largest disparity.
    columns : tuple of Column
        Its own pass's operator columns, in order.
    nomatch : NoMatchFloor
        Its no-match rule.
    passes : tuple of Pass
        The passes a run makes, in order: the declared ones, then its own (the output).
    planes : dict of Plane
        The planes of both images its passes read, by name (each declared by a column, or the no-match
        rule, with its filter and window).
    margin : int
        Pixels from its largest window's centre to its edge (5x5 windows: 2, a 7x7 census: 3).
    """

    __slots__ = ("_definition", "_dmax", "_given", "_values", "_columns", "_nomatch", "_passes", "_planes")

    def __init__(self, *, name: str = DEFAULT_MODEL, dmax: int = DEFAULT_DMAX, **parameters: Any) -> None:
        if not isinstance(name, str):
            raise TypeError(f"name must be a model name (str), not {type(name).__name__} {name!r}")
        if name not in MODELS:
            raise ParameterError(f"name must be one of {', '.join(MODELS)}, got {name!r}", "name")
        dmax = as_int("dmax", dmax, 0, MAX_DMAX)
        definition = MODELS[name]
        _check_keys(definition, parameters)
        values = definition.resolve(parameters)
        self._definition = definition
        self._dmax = dmax
        self._given = {k: v for k, v in parameters.items() if v is not None}
        self._values = MappingProxyType(values)
        self._columns = tuple(kind(values=values, dmax=dmax) for kind in definition.present(values))
        self._nomatch = definition.nomatch(values=values, dmax=dmax)
        passes = (*(self._declared_pass(p) for p in definition.passes), Pass(name=OWN_PASS, model=self))
        self._planes = _planes(passes)
        self._passes = passes  # the last attribute set: the model is read-only from here

    def _declared_pass(self, p: PassDef) -> Pass:
        other = MODELS[p.model].options
        keep = {k: v for k, v in self._values.items() if k in other and k not in p.not_inherited}
        keep.update({name: self._values[given] for name, given in p.sets})
        max_cycles = self._values[p.watchdog_option] if p.watchdog_option else None
        nomatch = bool(self._values[p.nomatch_option]) if p.nomatch_option else True
        return Pass(name=p.name, model=ModelParams(name=p.model, dmax=self._dmax, **keep),
                    reference=p.reference, nomatch=nomatch, machine_index=p.machine_index,
                    max_cycles=max_cycles, watchdog_option=p.watchdog_option, watchdog_runs=p.watchdog_runs)

    # What the model is.
    @property
    def name(self) -> str:
        return self._definition.name

    @property
    def dmax(self) -> int:
        return self._dmax

    @property
    def definition(self) -> ModelDef:
        return self._definition

    @property
    def columns(self) -> tuple[Column, ...]:
        return self._columns

    @property
    def nomatch(self) -> NoMatchFloor:
        return self._nomatch

    @property
    def passes(self) -> tuple[Pass, ...]:
        return self._passes

    @property
    def parameters(self) -> Mapping[str, Any]:
        """The values of its column kinds' parameters (read-only)."""
        return self._values

    @property
    def hypotheses(self) -> int:
        """Dmax + 2: disparities 0..Dmax and no match (the machine's rows M)."""
        return self._dmax + 2

    @property
    def planes(self) -> dict[str, Plane]:
        """The planes of both images every pass reads, by name, in the order its terms read them."""
        return dict(self._planes)

    @property
    def margin(self) -> int:
        """Pixels from a window's centre to its edge, for the largest window of its planes (5x5 filters: 2,
        7x7 census: 3): the output region keeps every window inside the image (``bayesmachine.region``)."""
        return max(p.margin for p in self._planes.values())

    def column(self, kind: type[Column]) -> Column | None:
        """Its own pass's column of ``kind`` (None if it has none)."""
        return next((c for c in self._columns if isinstance(c, kind)), None)

    def pass_named(self, name: str) -> Pass:
        for p in self._passes:
            if p.name == name:
                return p
        raise ValueError(f"the {self.name} model has no {name} pass")

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f"the {self._definition.name} model has no parameter {name!r}") from None

    def __setattr__(self, name: str, value: Any) -> None:
        if name.startswith("_") and not hasattr(self, "_passes"):
            object.__setattr__(self, name, value)
            return
        raise AttributeError(f"ModelParams is read-only: use model.replace({name}=...)")

    def replace(self, **changes: Any) -> ModelParams:
        """The model of the parameters given to this one, with ``changes``: the others take their defaults
        again (``census_window=5`` gives the 5x5 window's ``census_sigma``; a new ``name`` its model's
        defaults and keeps the given parameters it has)."""
        given = {"name": self.name, "dmax": self._dmax, **self._given}
        if "name" in changes and changes["name"] != self.name:
            other = MODELS[changes["name"]].options if changes["name"] in MODELS else {}
            given = {k: v for k, v in given.items() if k in ("name", "dmax") or k in other}
        return ModelParams(**{**given, **changes})

    def to_dict(self) -> dict[str, Any]:
        """``dmax``, ``name`` and every parameter's value (resolved: what ran)."""
        return {"dmax": self._dmax, "name": self.name, **self._values}

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ModelParams) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(tuple(self.to_dict().items()))

    def __repr__(self) -> str:
        return "ModelParams(" + ", ".join(f"{k}={v!r}" for k, v in self.to_dict().items()) + ")"

    def __reduce__(self) -> tuple[Any, tuple[dict[str, Any]]]:
        return _rebuild, ({"name": self.name, "dmax": self._dmax, **self._given},)


def neighbour_words_per_beat(rows: int, loaded_columns: int) -> int:
    """A neighbour-prior machine's default ``words_per_beat``: the loaded words of
    :data:`~bayesmachine.params.STEREO_ROWS_PER_BEAT` rows per load beat (the front end's rule).

    A pixel's loaded words grow by the census and above-prior columns (5 per row: 410 at Dmax 80),
    which the 16 lanes of ``for_disparity`` would load in 26 beats, longer than 47 % of the runs
    on the bundled pair at counter max 16 (no run is shorter than 17 cycles): loading would show
    (63.7 wall cycles per pixel instead of 61.4, docs/host.md). Six rows per beat
    (30 lanes) load them in 14 beats, below the shortest run, so loading stays hidden behind the
    previous pixel's run (wall cycles per pixel ``max(k + 2, beats + 1) + 1``) from counter max 12
    up; a lane count a multiple of the loaded columns keeps a row's words in one beat.
    """
    return min(STEREO_ROWS_PER_BEAT, rows) * loaded_columns


def disparity_machine(model: ModelParams, **machine_kwargs: Any) -> MachineParams:
    """The machine ``model``'s own pass needs: ``MachineParams.for_disparity(model.dmax, ...)`` with the
    data columns and the prior its columns give (:func:`machine_layout`).

    With a feedback column (the neighbour prior): ``prior="neighbour"``, ``feedback_words`` and
    ``feedback_nomatch_word`` from that column's table (:meth:`~bayesmachine.columns.LeftPrior.feedback`)
    and ``words_per_beat`` by default :func:`neighbour_words_per_beat`; with the definition's
    ``watchdog_runs``, ``max_cycles`` by default that many runs of ``counter_max`` + 1 cycles.
    ``machine_kwargs`` are the other fields (``word_bits``, ``rng``, ...); a ``columns``, ``prior`` or
    feedback table contradicting the model is a ``ParameterError`` naming it.
    """
    _check_model(model)
    prior, data = machine_layout(model.columns)
    if "columns" in machine_kwargs and machine_kwargs["columns"] != data:
        raise ParameterError(f"columns: the {model.name} model has {data} data columns, got "
                             f"columns={machine_kwargs['columns']!r}", "columns")
    kwargs = dict(machine_kwargs, columns=data)
    own_fields = integrator_kind(kwargs.get("integrator", DEFAULT_INTEGRATOR)).fields
    given = kwargs.get("prior")
    if prior == "neighbour":
        if given is not None and given != "neighbour":
            raise ParameterError(
                f"prior: the {model.name} model's neighbour prior needs the machine's prior 'neighbour' "
                f"(its own feedback column and a loaded above column), not {given!r}; leave prior out, or "
                "turn neighbour_prior off", "prior")
        # The other fields first, validated as usual (their errors name them), for the word width; not
        # the words per beat, which count the loaded above column this probe does not have.
        own = ("prior", "feedback_words", "feedback_nomatch_word", "words_per_beat")
        rest = {k: v for k, v in kwargs.items() if k not in own}
        if (rest.get("max_cycles") is None and model.definition.watchdog_runs is not None
                and "max_cycles" in own_fields):
            rest["max_cycles"] = MAX_WATCHDOG  # the model's watchdog comes below
        probe = MachineParams.for_disparity(model.dmax, **rest)
        word_bits = probe.word_bits
        left = model.column(LeftPrior)
        assert left is not None
        feedback, nm = left.feedback_of(probe)
        for name, want in (("feedback_words", feedback), ("feedback_nomatch_word", nm)):
            got = kwargs.get(name)
            if got is not None and (tuple(got) if name == "feedback_words" else got) != want:
                raise ParameterError(f"{name}: the model's {word_bits}-bit prior table gives {want}, "
                                     f"got {got!r}", name)
        kwargs.update(prior="neighbour", feedback_words=feedback, feedback_nomatch_word=nm)
        kwargs.setdefault("words_per_beat", neighbour_words_per_beat(model.hypotheses, data + 1))
    elif given == "neighbour":
        raise ParameterError(f"prior: 'neighbour' is the neighbour prior's machine; {_described(model)} has "
                             "no feedback column", "prior")
    # The model's machine defaults, where the machine's integrator reads the field.
    for name in ("timeout_answer", "normalize"):
        if name in own_fields and kwargs.get(name) is None:
            kwargs[name] = getattr(model.definition, name)
    runs = model.definition.watchdog_runs
    if runs is not None and "max_cycles" in own_fields and kwargs.get("max_cycles") is None:
        # The counter max (checked, its default if not given) under the largest watchdog, not the
        # machine's default one, which a counter max the model's watchdog covers may exceed.
        kwargs["max_cycles"] = MAX_WATCHDOG
        counter_max = MachineParams.for_disparity(model.dmax, **kwargs).counter_max
        kwargs["max_cycles"] = _watchdog(f"the {model.name} model's", runs, counter_max)
    machine = MachineParams.for_disparity(model.dmax, **kwargs)
    check_disparity_machine(model, machine)
    return machine


def _watchdog(whose: str, runs: int, counter_max: int) -> int:
    """``runs`` runs of ``counter_max`` + 1 cycles; ParameterError naming counter_max when a machine's
    watchdog cannot count that many (a definition's runs fit at the default counter max only)."""
    cycles = runs * (counter_max + 1)
    if cycles > MAX_WATCHDOG:
        raise ParameterError(f"counter_max {counter_max}: {whose} watchdog, {runs} runs of counter max + 1 "
                             f"cycles, is {cycles} cycles, more than a machine counts ({MAX_WATCHDOG}): "
                             "give a smaller counter_max or a max_cycles", "counter_max")
    return cycles


def _check_model(model: object) -> None:
    if not isinstance(model, ModelParams):
        raise TypeError(f"model must be a ModelParams (e.g. ModelParams(name='census')), not "
                        f"{type_name(model)}")


def _described(model: ModelParams) -> str:
    """"the census model with neighbour_prior off": the model and the switches, on by default, that left
    columns out."""
    options = model.definition.options
    switched = [option.name for option in model.definition.switches
                if not model.parameters[option.name] and options[option.name].default]
    return f"the {model.name} model" + (f" with {', '.join(switched)} off" if switched else "")


def pass_machine(model: ModelParams, machine: MachineParams, name: str) -> MachineParams:
    """The machine of ``model``'s declared pass ``name`` when its own pass runs on ``machine``.

    The pass's model's machine (:func:`disparity_machine`) with ``machine``'s integrator, word width,
    counter max, random source, watchdog (the pass's own if its option or its ``watchdog_runs`` gives one:
    a pixel stopped by it has no result) and tie rule, and the seed of machine ``machine_index`` of a row
    (:func:`~bayesmachine.params.nth_machine`): a machine beside the left one, its own random numbers.
    """
    _check_model(model)
    p = model.pass_named(name)
    if p.model is model:
        raise ValueError(f"{name} is the {model.name} model's own pass: its machine is "
                         "disparity_machine(model)")
    check_disparity_machine(model, machine)
    keep = ("word_bits", "counter_max", "rng", "lfsr_bits", "seed", "max_cycles", "tie_break",
            "samples_per_clock", "timeout_answer", "normalize", "integrator")
    kwargs: dict[str, Any] = {k: getattr(machine, k) for k in keep}
    if "max_cycles" in machine.kind.fields:  # the pass's own watchdog, where the machine has one
        if p.max_cycles is not None:
            kwargs["max_cycles"] = p.max_cycles
        elif p.watchdog_runs is not None:
            kwargs["max_cycles"] = _watchdog(f"the {name} pass's", p.watchdog_runs, machine.counter_max)
    if machine.rng == "smtj":
        kwargs.update(smtj_dwell=machine.smtj_dwell, smtj_spread=machine.smtj_spread,
                      smtj_share=machine.smtj_share)
    try:
        return nth_machine(disparity_machine(p.model, **kwargs), p.machine_index)
    except ParameterError as exc:
        own = p.max_cycles is not None or p.watchdog_runs is not None
        if exc.parameter != "max_cycles" or not own or p.watchdog_option is None:
            raise
        # The pass's own watchdog is at fault, which its option changes (not the machine's max_cycles).
        how = "" if p.max_cycles is not None else f": by default {p.watchdog_runs} runs of counter max + 1"
        raise ParameterError(f"the {name} pass's watchdog ({kwargs['max_cycles']} cycles{how}) is too short "
                             f"({exc}); give a longer {p.watchdog_option}", p.watchdog_option) from None


def check_disparity_machine(model: ModelParams, machine: MachineParams) -> int:
    """``ParameterError`` naming the parameter unless ``machine`` can run ``model``'s own pass.

    Returns the operator column of the first data column: 1 with a loaded prior (column 0), 2 with
    the neighbour prior (feedback column 0, loaded above column 1), else 0.
    """
    _check_model(model)
    if not isinstance(machine, MachineParams):
        raise TypeError(f"machine must be a MachineParams, not {type_name(machine)}")
    data_prior, data = machine_layout(model.columns)
    if machine.rows != model.hypotheses or not machine.nomatch_row:
        raise ParameterError(
            f"rows: the machine has {machine.rows} rows (no-match row: {machine.nomatch_row}); the model's "
            f"dmax {model.dmax} needs {model.hypotheses} = dmax + 2 with a no-match row: "
            f"use MachineParams.for_disparity({model.dmax}, columns={data})", "rows")
    if machine.columns != data:
        raise ParameterError(f"columns: the {model.name} model has {data} data columns, the machine has "
                             f"columns={machine.columns}", "columns")
    if data_prior == "neighbour" and machine.prior != "neighbour":
        raise ParameterError(
            f"neighbour_prior needs the machine's neighbour prior (prior='neighbour': its feedback column "
            f"and a loaded above column), not prior={machine.prior!r}: build the machine with "
            "disparity_machine(model), or turn the neighbour prior off", "neighbour_prior")
    if data_prior != "neighbour" and machine.prior == "neighbour":
        raise ParameterError(f"prior: the machine has a neighbour prior (prior='neighbour') but "
                             f"{_described(model)} has none", "prior")
    for term in (model.nomatch, *model.columns):
        term.check_machine(machine)
    for p in model.passes[:-1]:  # a declared pass's watchdog runs beside this machine
        if p.max_cycles is not None and p.max_cycles <= machine.counter_max:
            raise ParameterError(f"{p.watchdog_option} = {p.max_cycles} must exceed the counter max "
                                 f"({machine.counter_max}): no counter can overflow in fewer than counter "
                                 "max + 1 cycles", p.watchdog_option)
    return machine.operator_columns - machine.columns



for _definition in (PAPER, CENSUS, CENSUS_LR, CENSUS_SG, CENSUS_SGM):
    register_model(_definition)
