"""The front end's likelihood tables: the host's quantized tables, clamped.

The host computes one word per |difference| of feature sums (``QuantizedTables``): for
|delta| past some point every word equals the last one (the likelihood has decayed to p0, or
p_nm0). The hardware table stops there and its address is clamped to the last entry, so a
look-up gives exactly the host's word for every |delta| an 8-bit image can produce, with a
table about five times smaller (1,165 words instead of 6,376 for m with the paper's
parameters). The tables come from the host's own code at elaboration: one definition serves both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesmachine.columns import FEATURE_COLUMNS, Census
from bayesmachine.models import ModelParams

__all__ = ["FrontEndTables", "clamp_table", "frontend_tables"]


def clamp_table(table: np.ndarray) -> np.ndarray:
    """The shortest prefix of ``table`` whose last word repeats to the end of ``table``."""
    t = np.asarray(table)
    if t.ndim != 1 or len(t) == 0:
        raise ValueError("a likelihood table is a non-empty 1-D array")
    differs = np.flatnonzero(t != t[-1])
    end = int(differs[-1]) + 2 if len(differs) else 1
    return t[:end].copy()


@dataclass(frozen=True)
class FrontEndTables:
    """Clamped word tables: ``m``, ``gh``, ``gv`` indexed by |delta|, ``nomatch`` by |gv20|;
    ``census`` (census model) by the Hamming distance."""

    m: np.ndarray
    gh: np.ndarray
    gv: np.ndarray
    nomatch: np.ndarray
    census: np.ndarray | None = None

    def feature(self, index: int) -> np.ndarray:
        return (self.m, self.gh, self.gv)[index]

    def lookup(self, name: str, delta: np.ndarray) -> np.ndarray:
        """Twin of a table read: the word at min(|delta|, last index)."""
        t = getattr(self, name)
        if t is None:
            raise ValueError(f"these tables have no {name} table (a census model's have one)")
        return t[np.minimum(np.abs(np.asarray(delta, np.int64)), len(t) - 1)]


def frontend_tables(model: ModelParams, word_bits: int) -> FrontEndTables:
    """The clamped tables of ``model`` quantized to ``word_bits``-bit words (host code, then clamped)."""
    feats = [clamp_table(c.table(word_bits).values) for kind in FEATURE_COLUMNS
             for c in model.columns if isinstance(c, kind)]
    census = model.column(Census)
    return FrontEndTables(*feats, clamp_table(model.nomatch.table(word_bits).values),
                          clamp_table(census.table(word_bits).values) if census is not None else None)
