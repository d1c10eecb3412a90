"""How a pixel's evidence is integrated: one registry of integrator kinds, pure Python (no Amaranth).

An integrator kind is an entry in :data:`INTEGRATOR_KINDS`, the one list of kinds
(``bayesmachine.params.INTEGRATORS`` is its names), as ``bayesmachine.sources`` is for random
sources: ``stochastic`` (the paper's machine: AND gates and overflow counters,
:mod:`~bayesmachine.integrators.stochastic`) and ``log`` (energy codes summed per row, the MAP the
lowest sum: :mod:`~bayesmachine.integrators.log`). A kind declares what its machine loads (words or
energy codes), the ``MachineParams`` fields only it reads (:attr:`IntegratorKind.fields`: None for
another kind, refused when given, absent from ``to_dict``), its readout, its RTL top and model
(named ``"module:Class"``, imported when asked for: the definitions need no Amaranth), its
engines, its cycle formulas and the lines a report gives of it. Commands, engines, the front end
and the host ask the kind (``MachineParams.kind``) and never compare an integrator's name.

``params`` imports this package; its modules import ``bayesmachine.params`` (and NumPy) inside
their functions only, as the sources' modules do.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, ClassVar

from bayesmachine.checks import type_name
from bayesmachine.errors import ParameterError
from bayesmachine.extras import MissingExtra

if TYPE_CHECKING:  # params imports this package: no import of params (or numpy) when it does
    import numpy as np

    from bayesmachine.columns.base import Column, PassContext
    from bayesmachine.params import MachineParams

__all__ = ["INTEGRATOR_KINDS", "KIND_FIELDS", "IntegratorKind", "integrator_kind", "load_named",
           "unread_fields"]


def load_named(target: str) -> type:
    """The class (or function) ``"module:Name"`` names, imported now."""
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


class IntegratorKind(ABC):
    """One kind of integrator (module text). A kind's module subclasses it and fills the class
    attributes and gives the abstract methods.

    Attributes
    ----------
    name : str
        The ``MachineParams.integrator`` that selects it.
    description : str
        One line for ``--help`` and reports.
    title : str
        Its machine's adjective in messages ("the logarithmic machine").
    named : bool
        Whether a one-line summary and a sweep point's id name the integrator where it does not vary
        (the paper's machine, the default, goes unnamed).
    loads : str
        ``"words"`` (W-bit likelihood words, 2^W the factor 1.0) or ``"codes"`` (energy codes,
        ``bayesmachine.columns.energy.log_codes``, 0 the factor 1.0).
    fields : tuple of str
        The ``MachineParams`` fields only this kind reads (None for every other kind).
    defaults : mapping
        The values those fields take when not given (a field missing here stays None until its
        own rule fills it, e.g. the ``smtj_*`` fields with ``rng = "smtj"``).
    draws_numbers : bool
        Whether the machine compares random numbers (a random source, an ``entropy`` port when
        the source is off chip).
    top, model : str
        ``"module:Class"`` of the RTL top (a ``wiring.Component`` taking ``params=``) and of the
        ``model`` engine (``sim.engines``' contract).
    engines : mapping of str to str
        Engine name to ``"module:Class"``: the engines that run this kind's machine.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    title: ClassVar[str]
    named: ClassVar[bool]
    loads: ClassVar[str]
    fields: ClassVar[tuple[str, ...]]
    defaults: ClassVar[Mapping[str, object]]
    draws_numbers: ClassVar[bool]
    top: ClassVar[str]
    model: ClassVar[str]
    engines: ClassVar[Mapping[str, str]]

    def __repr__(self) -> str:
        return f"integrator_kind({self.name!r})"

    # -- parameters ------------------------------------------------------------------------------
    def check(self, params: MachineParams) -> None:  # noqa: B027  (a kind may know nothing more)
        """What only this kind knows about a machine's parameters (ParameterError naming the field);
        ``MachineParams`` runs it once its own fields are checked."""

    @abstractmethod
    def load_max(self, params: MachineParams) -> int:
        """The largest loaded entry: the word 2^W, or the infinite energy code."""

    @abstractmethod
    def readout_max(self, params: MachineParams) -> int:
        """The largest value of a row in the distribution read out (the counter max, or the MAP's
        weight)."""

    @abstractmethod
    def flat(self, params: MachineParams) -> int:
        """The entry of a factor 1.0: the word 2^W or the code 0."""

    @abstractmethod
    def empty(self, params: MachineParams) -> int:
        """The entry of a factor 0: the word 0 or the infinite code."""

    @abstractmethod
    def max_clocks(self, params: MachineParams) -> int:
        """The largest ``cycles`` a result carries (its field's range)."""

    @abstractmethod
    def nth_machine(self, params: MachineParams, index: int) -> MachineParams:
        """Machine ``index`` of K side by side (``bayesmachine.params.nth_machine``)."""

    def table_bits(self, params: MachineParams) -> int | None:
        """The ``word_bits`` a pass context's tables are read at: W (words) or None (float64
        factors, coded on loading)."""
        return params.word_bits if self.loads == "words" else None

    # -- what is loaded ----------------------------------------------------------------------------
    @abstractmethod
    def load(self, factors: np.ndarray | float, params: MachineParams) -> np.ndarray:
        """float64 factors in [0, 1] as the machine loads them (uint16)."""

    @abstractmethod
    def entries(self, values: np.ndarray | float, params: MachineParams) -> np.ndarray:
        """Values read from tables at :meth:`table_bits` (words, or float64 factors) as loaded."""

    @abstractmethod
    def column_entries(self, column: Column, ctx: PassContext) -> np.ndarray:
        """A column's loaded entries in a pass context (``Column.words`` or ``Column.codes``)."""

    @abstractmethod
    def feedback_table(self, column: object, params: MachineParams) -> tuple[tuple[int, ...], int]:
        """A neighbour prior column's feedback table (``feedback_words``, ``feedback_nomatch_word``)
        in this kind's domain."""

    # -- the machine -------------------------------------------------------------------------------
    def machine_top(self, params: MachineParams) -> object:
        """The RTL top of ``params`` (Amaranth is imported now)."""
        return load_named(self.top)(params=params)

    def engine_class(self, name: str) -> type:
        """The class of engine ``name`` for this kind (ValueError naming the engines it has)."""
        if name not in self.engines:
            raise ValueError(f"unknown engine {name!r}: the {self.name} integrator runs on "
                             f"{', '.join(self.engines)}")
        try:
            return load_named(self.engines[name])
        except ModuleNotFoundError as exc:  # the RTL's engines need Amaranth, the model engine does not
            if exc.name is None or exc.name.split(".")[0] == "bayesmachine":
                raise
            raise MissingExtra(f"the {name} engine needs the module {exc.name!r}, which is not installed "
                               "(pip install bayesmachine installs it)") from exc

    @abstractmethod
    def pixel_wall_cycles(self, params: MachineParams, cycles: np.ndarray,
                          timeout: np.ndarray | None = None) -> np.ndarray:
        """Clock cycles per pixel in steady state (loads keep coming, results are taken at once) from
        the results' ``cycles`` (and ``timeout`` flags)."""

    def samples_per_pixel(self, params: MachineParams, cycles: float) -> float | None:
        """The random samples per operator that ``cycles`` clocks of a run compare (None: the kind
        samples nothing)."""
        return None

    # -- reports -----------------------------------------------------------------------------------
    @abstractmethod
    def summary_lines(self, params: MachineParams) -> list[str]:
        """How the machine integrates, for ``emit``'s summary."""

    @abstractmethod
    def brief(self, params: MachineParams) -> list[str]:
        """The parts of a one-line description of the machine after its rows and columns (synth's
        ``machine_summary``: ``counter max 16``, ``W 10``, ...)."""

    @abstractmethod
    def label_parts(self, values: Mapping[str, object]) -> list[str]:
        """What a one-line summary says of the machine of a report's ``values`` (``rng=...``)."""

    @abstractmethod
    def id_parts(self, params: MachineParams) -> list[str]:
        """The parts of a sweep point's id this kind's fields give (after the model's)."""


def _kinds() -> dict[str, IntegratorKind]:
    from .log import LOG
    from .stochastic import STOCHASTIC

    return {kind.name: kind for kind in (STOCHASTIC, LOG)}


INTEGRATOR_KINDS: dict[str, IntegratorKind] = _kinds()


# Every kind's own fields (None for the other kinds' machines).
KIND_FIELDS = tuple(dict.fromkeys(f for kind in INTEGRATOR_KINDS.values() for f in kind.fields))


def unread_fields(kinds: Iterable[IntegratorKind]) -> tuple[str, ...]:
    """The kinds' own fields (:data:`KIND_FIELDS`) that none of ``kinds`` reads."""
    read = {f for kind in kinds for f in kind.fields}
    return tuple(f for f in KIND_FIELDS if f not in read)


def integrator_kind(name: str) -> IntegratorKind:
    """The registry entry of an integrator; a clear error for an unknown name."""
    kind = INTEGRATOR_KINDS.get(name) if isinstance(name, str) else None
    if kind is None:
        if not isinstance(name, str):
            raise TypeError(f"integrator must be one of {tuple(INTEGRATOR_KINDS)}, not {type_name(name)}")
        raise ParameterError(f"integrator must be one of {tuple(INTEGRATOR_KINDS)}, got {name!r}",
                             "integrator")
    return kind
