"""The random sources of the machine: one registry, pure Python (no Amaranth).

A source kind is a name in :data:`bayesmachine.params.RNG_KINDS` and an entry of
:data:`SOURCE_KINDS`. On-chip kinds generate their numbers inside the design (an RTL generator
and its twin in the model); off-chip kinds take them on the machine's ``entropy`` port, one
W-bit number per operator per compute cycle, and name the seeded device model
(a :class:`NumberSource`) that drives that port in simulation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bayesmachine.params import RNG_KINDS, MachineParams

__all__ = ["SOURCE_KINDS", "NumberSource", "SourceKind", "source_kind"]


class NumberSource(Protocol):
    """A stream of random numbers for the ``entropy`` port."""

    operators: int

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` compute cycles' numbers: (count, operators) uint16 in [0, 2**W).

        Stateful: successive calls continue the stream. A finite source returns fewer rows
        when it runs out (0 rows: exhausted)."""
        ...


@dataclass(frozen=True)
class SourceKind:
    name: str
    on_chip: bool  # numbers made inside the design; otherwise they arrive on the ``entropy`` port
    description: str  # one line, for --help and docs
    # Off-chip kinds: the seeded device model that drives the entropy port when a run gets no
    # numbers (None: the caller must pass them).
    numbers: Callable[[MachineParams], NumberSource] | None = None


def _smtj_numbers(params: MachineParams) -> NumberSource:
    from .smtj import SMTJSource  # numba: imported only when an SMTJ machine runs

    return SMTJSource(params)


SOURCE_KINDS: dict[str, SourceKind] = {
    kind.name: kind
    for kind in (
        SourceKind("lfsr", True, "one leap-forward LFSR per operator, inside the design"),
        SourceKind("external", False, "W-bit numbers per operator on the 'entropy' port, from the caller"),
        SourceKind(
            "smtj",
            False,
            "superparamagnetic tunnel junctions (telegraph-noise device model) on the 'entropy' port",
            _smtj_numbers,
        ),
    )
}
assert tuple(SOURCE_KINDS) == RNG_KINDS, "every rng kind has one registry entry"


def source_kind(params: MachineParams) -> SourceKind:
    """The registry entry of ``params.rng``."""
    return SOURCE_KINDS[params.rng]
