"""Random sources of the stochastic operators: one registry, pure Python (no Amaranth).

A source kind is an entry in :data:`SOURCE_KINDS`, the one list of kinds
(``bayesmachine.params.RNG_KINDS`` is its names). On-chip kinds generate their numbers inside
the design: an RTL generator in ``bayesmachine.hdl.sources`` and a twin kernel in
``bayesmachine.sim.model``, both built on the definitions of this package (``lfsr``: LFSR
specs and polynomial search; ``sobol``: direction numbers and the per-cycle twin). Off-chip
kinds take one W-bit number per operator per compute cycle on the machine's ``entropy`` port;
``numbers`` builds the seeded device model that engines use when a run gets no numbers
(``external``: none, the caller passes them).

Each kind's ``check`` holds what only the source knows about a machine's parameters (the Sobol
table's size, the LFSR polynomials of a length); ``MachineParams`` runs it (:func:`check_source`)
as the last step of its validation, so a built ``MachineParams`` is a machine whose source can be
built. ``params`` imports this package; its modules never import ``bayesmachine.params`` at module
level (for type checking only): their functions take the parameter object and read its fields.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from bayesmachine.errors import ParameterError

if TYPE_CHECKING:  # params imports this package: no import of params (or numpy) when it does
    import numpy as np

    from bayesmachine.params import MachineParams

__all__ = ["SMTJ_SHARES", "SOURCE_KINDS", "NumberSource", "SourceKind", "check_source", "source_kind"]

# ``rng = "smtj"``: W devices per operator, or W per operator column shared by its rows.
SMTJ_SHARES = ("operator", "column")


class NumberSource(Protocol):
    """A stream of random numbers for the ``entropy`` port of an off-chip source."""

    operators: int

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` compute cycles' numbers: shape (count, operators), uint16, in
        [0, 2**W). Successive calls continue the stream; a finite source returns fewer rows when
        it runs out (0 rows: exhausted)."""
        ...


@dataclass(frozen=True)
class SourceKind:
    """One kind of random source (see the module docstring)."""

    name: str
    on_chip: bool
    description: str
    numbers: Callable[[MachineParams], NumberSource] | None = None
    # What only the source knows about a machine's parameters (e.g. that LFSR polynomials of
    # this length exist); raises ParameterError. MachineParams runs it (check_source) when built.
    check: Callable[[MachineParams], None] | None = None


def _one_sample(params: MachineParams, why: str) -> None:
    """A kind with one number per operator per clock refuses samples_per_clock > 1, saying why."""
    if params.samples_per_clock > 1:
        raise ParameterError(f"samples_per_clock {params.samples_per_clock}: rng = {params.rng!r} gives one "
                             f"number per operator per clock ({why}); use sobol or external")


def _check_lfsr(params: MachineParams) -> None:
    from .lfsr import check_lfsr_params

    _one_sample(params, "B numbers would be B leap-forward steps per LFSR and clock: docs/sources.md")
    check_lfsr_params(params)


def _check_sobol(params: MachineParams) -> None:
    from .lfsr import check_lfsr_params
    from .sobol import check_params

    check_params(params)
    check_lfsr_params(params)  # the random digital shifts come from column LFSRs


def _check_smtj(params: MachineParams) -> None:
    _one_sample(params, "its devices are read once per clock: docs/smtj.md")


def _smtj_numbers(params: MachineParams) -> NumberSource:
    from .smtj import SMTJSource  # numba: imported only when an SMTJ machine runs

    return SMTJSource(params)


SOURCE_KINDS: dict[str, SourceKind] = {
    kind.name: kind
    for kind in (
        SourceKind("lfsr", True, "one leap-forward LFSR per operator (L = lfsr_bits, W bits per cycle)",
                   check=_check_lfsr),
        SourceKind(
            "lfsr-shared", True,
            "one leap-forward LFSR per operator column, its number shared by every row",
            check=_check_lfsr,
        ),
        SourceKind(
            "sobol", True,
            "one Sobol generator per operator column, shared by every row; restarts each pixel, "
            "a random digital shift per block of 2^W cycles",
            check=_check_sobol,
        ),
        SourceKind(
            "external", False,
            "W-bit numbers per operator on the 'entropy' port, one set per compute cycle (caller-supplied)",
        ),
        SourceKind(
            "smtj", False,
            "superparamagnetic tunnel junctions (telegraph-noise device model) on the 'entropy' port",
            _smtj_numbers, _check_smtj,
        ),
    )
}


def source_kind(name: str) -> SourceKind:
    """The registry entry of a source kind; a clear error for an unknown name."""
    kind = SOURCE_KINDS.get(name) if isinstance(name, str) else None
    if kind is None:
        raise ParameterError(f"rng must be one of {', '.join(SOURCE_KINDS)}, got {name!r}", "rng")
    return kind


def check_source(params: MachineParams) -> None:
    """Raise ParameterError if the machine's random source cannot be built for ``params``.

    Part of ``MachineParams`` validation (its last step): callers holding a ``MachineParams`` need
    not call it again."""
    kind = source_kind(params.rng)
    if kind.check is not None:
        kind.check(params)
