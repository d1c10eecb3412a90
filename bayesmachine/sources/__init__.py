"""Random sources of the machine's operators: one registry, pure Python (no Amaranth).

A source kind is a name in :data:`bayesmachine.params.RNG_KINDS` and an entry of
:data:`SOURCE_KINDS`. On-chip kinds generate their numbers inside the design (an RTL
generator and its twin in the model); off-chip kinds receive them on the machine's
``entropy`` port, one W-bit number per operator per compute cycle, from a
:class:`NumberSource` (the caller's array, or the kind's seeded device model).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from bayesmachine.params import MachineParams

__all__ = ["SOURCE_KINDS", "NumberSource", "SourceKind"]


class NumberSource(Protocol):
    """A stream of random numbers for the ``entropy`` port."""

    operators: int

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` compute cycles' numbers, shape (count, operators), uint16 in [0, 2**W).

        Stateful: successive calls continue the stream. A finite source returns fewer rows when
        it runs out (0 rows: exhausted).
        """
        ...


@dataclass(frozen=True)
class SourceKind:
    name: str
    on_chip: bool  # True: generated inside the design; False: numbers arrive on the `entropy` port
    description: str  # one line, for --help and docs
    # Off-chip kinds only: the seeded device model engines use when run() gets numbers=None
    # (None: the caller must pass the numbers).
    numbers: Callable[[MachineParams], NumberSource] | None = None


SOURCE_KINDS: dict[str, SourceKind] = {
    "lfsr": SourceKind("lfsr", True, "one leap-forward LFSR per operator, inside the design"),
    "external": SourceKind("external", False,
                           "W-bit numbers per operator on the 'entropy' port, from the caller"),
}
