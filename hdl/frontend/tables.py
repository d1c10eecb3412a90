"""The front end's likelihood tables: the host's quantized column tables, clamped.

Each term (a column, the no-match rule) has one word per cost (``Term.table(word_bits)``): past some
cost every word equals the last one (the likelihood has decayed to its floor). The hardware table
stops there and its address is clamped to the last entry, so a look-up gives exactly the host's word
for every cost an 8-bit image can produce, with a table about five times smaller (1,165 words instead
of 6,376 for m with the paper's parameters). The tables come from the columns' own code at
elaboration: one definition serves both.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

import numpy as np

from bayesmachine.columns import Fused, Term
from bayesmachine.models import ModelParams

__all__ = ["FrontEndTables", "clamp_table", "frontend_tables", "term_tables"]


def clamp_table(table: np.ndarray) -> np.ndarray:
    """The shortest prefix of ``table`` whose last word repeats to the end of ``table``."""
    t = np.asarray(table)
    if t.ndim != 1 or len(t) == 0:
        raise ValueError("a likelihood table is a non-empty 1-D array")
    differs = np.flatnonzero(t != t[-1])
    end = int(differs[-1]) + 2 if len(differs) else 1
    return t[:end].copy()


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


def term_tables(term: Term, rule: Term, word_bits: int) -> dict[str, np.ndarray]:
    """A term's clamped tables by name: its ``word_bits``-bit words (``{name: ...}``); a fused column's
    members' energy codes (``{member}_energy``), its pass's no-match rule's (``nomatch_energy``) and its
    exp table (``fused_exp``, X: ends at its first 0, the clamp)."""
    if isinstance(term, Fused):
        out = {f"{m.name}_energy": clamp_table(e.values) for m, e in zip(term.members, term.energies(),
                                                                         strict=True)}
        return out | {"nomatch_energy": clamp_table(term.rule_energy(rule).values),
                      "fused_exp": term.exp_table(word_bits)}
    return {term.name: clamp_table(term.table(word_bits).values)}


def frontend_tables(model: ModelParams, word_bits: int) -> FrontEndTables:
    """The clamped tables of ``model``'s own pass's columns and its no-match rule, quantized to
    ``word_bits``-bit words (host code, then clamped; :func:`term_tables`)."""
    out: dict[str, np.ndarray] = {}
    for t in (*model.columns, model.nomatch):
        out.update(term_tables(t, model.nomatch, word_bits))
    return FrontEndTables(out)
