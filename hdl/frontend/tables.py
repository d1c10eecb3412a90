"""The front end's likelihood tables: the host's quantized column tables, clamped.

Each term (a column, the no-match rule) has one word per cost (``Term.table(word_bits)``): past some
cost every word equals the last one (the likelihood has decayed to its floor). The hardware table
stops there and its address is clamped to the last entry, so a look-up gives exactly the host's word
for every cost an 8-bit image can produce, with a table about five times smaller (1,165 words instead
of 6,376 for m with the paper's parameters). The tables come from the columns' own code at
elaboration: one definition serves both. The machine's integrator chooses the form (:class:`LoadForm`):
W-bit words for the stochastic machine, energy codes (``Column.codes``) for the logarithmic one.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from bayesmachine.columns import Fused, SemiGlobal, Term
from bayesmachine.columns.energy import INFINITE_CODE, log_codes
from bayesmachine.integrators import integrator_kind
from bayesmachine.models import ModelParams
from bayesmachine.params import DEFAULT_INTEGRATOR, MachineParams

__all__ = ["FrontEndTables", "LoadForm", "clamp_table", "frontend_tables", "padded_table", "term_tables"]


@dataclass(frozen=True)
class LoadForm:
    """What a machine loads for a factor: its ``word_bits``-bit word (``integrator`` "stochastic") or its
    energy code (``"log"``: ``log_codes`` of the float64 factor, what ``Column.codes`` gives the host's
    log machine)."""

    integrator: str = DEFAULT_INTEGRATOR
    word_bits: int = 10

    @classmethod
    def of(cls, params: MachineParams) -> LoadForm:
        return cls(params.integrator, params.word_bits)

    @property
    def log(self) -> bool:
        """Whether the machine loads energy codes (``IntegratorKind.loads``), not words."""
        return integrator_kind(self.integrator).loads == "codes"

    @property
    def table_bits(self) -> int | None:
        """The ``Term.table`` a value comes from: float64 factors (None, coded) or W-bit words."""
        return None if self.log else self.word_bits

    @property
    def one(self) -> int:
        """A factor 1.0: the word 2^W, the code 0."""
        return 0 if self.log else 1 << self.word_bits

    @property
    def zero(self) -> int:
        """A factor 0 (a lane without a match pixel, a no-match row that cannot win): the word 0, the
        infinite code."""
        return INFINITE_CODE if self.log else 0

    def values(self, values: np.ndarray | float) -> np.ndarray:
        """Values of a ``Term.table(self.table_bits)`` in this form."""
        return log_codes(values) if self.log else np.asarray(values)

    def value(self, value: float | int) -> int:
        return int(self.values(value))

    def table(self, term: Term) -> np.ndarray:
        """``term``'s values by cost in this form."""
        return self.values(term.table(self.table_bits).values)


def clamp_table(table: np.ndarray) -> np.ndarray:
    """The shortest prefix of ``table`` whose last word repeats to the end of ``table``."""
    t = np.asarray(table)
    if t.ndim != 1 or len(t) == 0:
        raise ValueError("a likelihood table is a non-empty 1-D array")
    differs = np.flatnonzero(t != t[-1])
    end = int(differs[-1]) + 2 if len(differs) else 1
    return t[:end].copy()


def padded_table(table: np.ndarray, depth: int) -> np.ndarray:
    """A clamped ``table`` (:func:`clamp_table`) padded to ``depth`` entries with its last word: the same
    word at every address clamped to any entry from its last on (the hardware's, ``lookup.table_depth``)."""
    t = np.asarray(table)
    if depth < len(t):
        raise ValueError(f"a table of {len(t)} words cannot be padded to {depth}")
    return np.concatenate([t, np.full(depth - len(t), t[-1], dtype=t.dtype)])


class FrontEndTables(Mapping[str, np.ndarray]):
    """Clamped word tables by term name (a column's ``name``: ``m``, ``gh``, ``gv``, ``census``, ...; the
    no-match rule's ``nomatch``), each indexed by its cost."""

    def __init__(self, tables: Mapping[str, np.ndarray]) -> None:
        self._tables = {name: np.asarray(t) for name, t in tables.items()}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._tables:
            raise KeyError(f"these tables have no {name} table (they have {', '.join(self._tables)})")
        return self._tables[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._tables)

    def __len__(self) -> int:
        return len(self._tables)

    def lookup(self, name: str, cost: np.ndarray) -> np.ndarray:
        """Twin of a table read: the word at min(|cost|, last index)."""
        if name not in self._tables:
            raise ValueError(f"these tables have no {name} table (they have {', '.join(self._tables)})")
        t = self._tables[name]
        return t[np.minimum(np.abs(np.asarray(cost, np.int64)), len(t) - 1)]


def term_tables(term: Term, rule: Term, form: LoadForm) -> dict[str, np.ndarray]:
    """A term's clamped tables by name: its values in ``form`` (``{name: ...}``); a fused column's
    members' energy codes (``{member}_energy``), its pass's no-match rule's (``nomatch_energy``) and the
    way back from a sum above the pixel's least (``fused_exp``: the exp table X to words, ending at its
    first 0, the clamp; to codes (``Fused.codes``) the sum itself up to ``INFINITE_CODE - 1``); a semi-global
    column its member's (``fused_exp`` then the way back from its tempered value T)."""
    if isinstance(term, SemiGlobal):  # its member's tables: the sums, then the way back from T
        return term_tables(term.member, rule, form)
    if isinstance(term, Fused):
        out = {f"{m.name}_energy": clamp_table(e.values) for m, e in zip(term.members, term.energies(),
                                                                         strict=True)}
        back = np.arange(INFINITE_CODE, dtype=np.uint16) if form.log else term.exp_table(form.word_bits)
        return out | {"nomatch_energy": clamp_table(term.rule_energy(rule).values), "fused_exp": back}
    return {term.name: clamp_table(form.table(term))}


def frontend_tables(model: ModelParams, word_bits: int,
                    integrator: str = DEFAULT_INTEGRATOR) -> FrontEndTables:
    """The clamped tables of ``model``'s own pass's columns and its no-match rule in the form of an
    ``integrator`` machine of ``word_bits``-bit words (host code, then clamped; :func:`term_tables`)."""
    form = LoadForm(integrator, word_bits)
    out: dict[str, np.ndarray] = {}
    for t in (*model.columns, model.nomatch):
        out.update(term_tables(t, model.nomatch, form))
    return FrontEndTables(out)
