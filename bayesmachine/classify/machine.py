"""A naive-Bayes classifier as the machine: rows = classes, one decision one "pixel" of the machine.

Two layouts of the same tables (:class:`~.tables.NaiveBayesTables`), both on the existing machine and
its word engines (``bayesmachine.sim.engines``), so the model, pysim and Verilator decide bit for bit
alike:

- **fused** (``fuse = K``, default 1): the features dealt in order into K operator columns, each a
  fused column in the energy form as the stereo fused column (``columns/fused.py``): per class the sum
  of its features' codes ``S_c = sum_j E_j[c, bin_j]`` (``energy_codes`` of the float64 tables, column 0
  with the prior's code too), the least over the classes subtracted, and back to a word through one
  table, ``X[min(S_c - S_min, len(X) - 1)]`` (``exp_table(W)``); the log integrator loads the
  differences themselves (at most ``INFINITE_CODE - 1``, as ``Fused.codes``). No loaded prior column.
- **one column per feature** (``fuse = None``, the paper's picture): a loaded prior column (the
  machine's ``prior = "loaded"``) and each feature's table, quantized as every stereo column: words
  ``quantize(P, W)`` with per-decision column normalization (``MachineParams.normalize``), or the log
  integrator's ``log_codes(P)``. At most 64 operator columns (63 features).

The readout (:class:`Decisions`): the MAP class, the counters or weights, the distribution they give
(``proba``: the readout normalized; a stochastic run's MAP row counted with its overflowing
``(counter max + 1)``-th 1, which its counter does not hold, so the MAP is always the largest), the
confidence (the MAP's share of it: the stereo confidence's mass with ``t`` = 0 and a window of 1,
``host/confidence.py``) and the cycles of each decision.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesmachine.checks import as_int, type_name
from bayesmachine.columns.energy import INFINITE_CODE, energy_codes, exp_table
from bayesmachine.errors import ParameterError
from bayesmachine.integrators import integrator_kind
from bayesmachine.params import DEFAULT_INTEGRATOR, DEFAULT_WORDS_PER_BEAT, MachineParams

from .tables import NaiveBayesTables

__all__ = ["MACHINE_FIELDS", "MAX_OPERATOR_COLUMNS", "ClassifierMachine", "Decisions", "classifier_params"]

MAX_OPERATOR_COLUMNS = 64
# The machine options a classifier passes on (MachineParams fields); the layout fields (rows, columns,
# prior, normalize, words_per_beat, nomatch_row) are the classifier's own.
MACHINE_FIELDS = ("integrator", "word_bits", "counter_max", "rng", "lfsr_bits", "seed", "max_cycles",
                  "tie_break", "samples_per_clock")


@dataclass(frozen=True, eq=False)
class Decisions:
    """The machine's decisions of n samples.

    Attributes
    ----------
    map : ndarray
        (n,) int64 the MAP class index.
    readout : ndarray
        (n, classes) the counters (stochastic) or weights (log) as read out.
    proba : ndarray
        (n, classes) float64 the distribution the readout gives (module text).
    confidence : ndarray
        (n,) float64 the MAP's share of it.
    cycles : ndarray
        (n,) int64 clocks per decision.
    timeout : ndarray
        (n,) bool a stochastic run stopped by the watchdog (answered by its leading row).
    """

    map: np.ndarray
    readout: np.ndarray
    proba: np.ndarray
    confidence: np.ndarray
    cycles: np.ndarray
    timeout: np.ndarray


def _fuse(fuse: object, features: int) -> int | None:
    if fuse is None:
        return None
    k = as_int("fuse", fuse, 1)
    if k > features:
        raise ParameterError(f"fuse ({k}) must not exceed the features ({features}): each fused column holds "
                             "at least one", "fuse")
    return k


def classifier_params(*, classes: int, features: int, fuse: int | None = 1,
                      machine: Mapping[str, Any] | None = None) -> MachineParams:
    """The machine of a classifier of ``classes`` and ``features`` in the layout ``fuse`` (K fused
    columns, or None: one per feature and a loaded prior column) from the machine options ``machine``
    (MachineParams fields of ``MACHINE_FIELDS``): what :class:`ClassifierMachine` runs and the classifier
    top (``hdl.classifier``) is built for."""
    options = dict(machine or {})
    unknown = sorted(set(options) - set(MACHINE_FIELDS))
    if unknown:
        raise ParameterError(f"{unknown[0]}: not a machine option of the classifier (its options: "
                             f"{', '.join(MACHINE_FIELDS)})", unknown[0])
    kind = integrator_kind(options.get("integrator", DEFAULT_INTEGRATOR))  # another kind's fields: refused
    classes = as_int("classes", classes, 1)
    fuse = _fuse(fuse, as_int("features", features, 1))
    if fuse is None and features + 1 > MAX_OPERATOR_COLUMNS:
        raise ParameterError(f"fuse: one column per feature needs {features + 1} operator columns (the "
                             f"features and the prior), more than the machine's {MAX_OPERATOR_COLUMNS}; "
                             "fuse them (fuse=1)", "fuse")
    layout: dict[str, Any] = ({"columns": features, "prior": "loaded"} if fuse is None
                              else {"columns": fuse, "prior": "uniform"})
    loaded = layout["columns"] + (layout["prior"] == "loaded")
    layout["words_per_beat"] = min(DEFAULT_WORDS_PER_BEAT, classes * loaded)
    # A run the watchdog stops answers its leading class; per-feature words are normalized per decision
    # (a fused column's best class is 2^W already): the fields of the kinds that read them.
    wanted = {"timeout_answer": "leading", "normalize": fuse is None}
    layout.update({f: v for f, v in wanted.items() if f in kind.fields})
    return MachineParams(rows=classes, **options, **layout)


class ClassifierMachine:
    """The machine of a classifier's tables (module text).

    Parameters
    ----------
    tables : NaiveBayesTables
    fuse : int or None
        K fused energy columns (1 .. features), or None: one operator column per feature.
    machine : Mapping
        Machine options (MachineParams fields of ``MACHINE_FIELDS``); the others are the layout's.

    Attributes
    ----------
    tables, fuse, params : the tables, K (or None) and the machine's MachineParams.
    groups : tuple of ndarray
        The features of each fused column (fused only).
    """

    def __init__(self, *, tables: NaiveBayesTables, fuse: int | None = 1,
                 machine: Mapping[str, Any] | None = None) -> None:
        if not isinstance(tables, NaiveBayesTables):
            raise TypeError(f"tables must be NaiveBayesTables, not {type_name(tables)}")
        self._tables = tables
        self._fuse = _fuse(fuse, tables.features)
        self._params = classifier_params(classes=tables.classes, features=tables.features, fuse=self._fuse,
                                         machine=machine)
        self._kind = self._params.kind
        # A stochastic run's MAP row held counter max + 1 ones, its counter only counter max.
        self._overflow = 1 if self._kind.draws_numbers else 0
        k = self._fuse
        self._groups = () if k is None else tuple(np.array_split(np.arange(tables.features), k))
        self._codes = tuple(energy_codes(t).astype(np.int64) for t in tables.likelihoods)
        self._prior_codes = energy_codes(tables.prior).astype(np.int64)

    tables = property(lambda self: self._tables)
    fuse = property(lambda self: self._fuse)
    params = property(lambda self: self._params)
    groups = property(lambda self: self._groups)

    def entries(self, bins: np.ndarray) -> np.ndarray:
        """(n, classes, loaded columns) uint16: what the machine loads for each decision of ``bins``."""
        b = np.asarray(bins, np.int64)
        if self._fuse is None:
            f = self._tables.factors(b)
            return self._kind.load(f, self._params)
        out = np.empty((b.shape[0], self._tables.classes, self._fuse), np.uint16)
        words = self._kind.loads == "words"
        x = exp_table(self._params.word_bits).astype(np.uint16)
        for k, group in enumerate(self._groups):
            s = np.zeros((b.shape[0], self._tables.classes), np.int64)
            if k == 0:
                s += self._prior_codes
            for j in group:
                s += self._codes[j][:, b[:, j]].T
            d = s - s.min(axis=1, keepdims=True)
            out[:, :, k] = x[np.minimum(d, x.size - 1)] if words else np.minimum(d, INFINITE_CODE - 1)
        return out

    def energy_decision(self, bins: np.ndarray) -> np.ndarray:
        """(n,) int64: the MAP of the summed energy codes (ties to the lowest index), what the fused
        log machine decides."""
        b = np.asarray(bins, np.int64)
        s = np.broadcast_to(self._prior_codes, (b.shape[0], self._tables.classes)).copy()
        for j, c in enumerate(self._codes):
            s += c[:, b[:, j]].T
        return np.argmin(s, axis=1)

    def run(self, bins: np.ndarray, engine: str = "model", **options: Any) -> Decisions:
        """The decisions of ``bins`` (n, features) on a fresh ``engine`` (as after reset): one of the
        integrator kind's engines (``MachineParams.kind.engines``), ``options`` its constructor's."""
        with self._kind.engine_class(engine)(self._params, **options) as e:
            r = e.run(self.entries(bins))
        return self.readout(r.map, r.counts, r.cycles, r.timeout)

    def readout(self, map_: np.ndarray, counts: np.ndarray, cycles: np.ndarray,
                timeout: np.ndarray) -> Decisions:
        """:class:`Decisions` of a machine result's fields."""
        m = np.asarray(map_, np.int64)
        t = np.asarray(timeout, bool)
        dist = np.asarray(counts, np.float64).copy()
        n = np.arange(m.size)
        dist[n[~t], m[~t]] += self._overflow
        total = dist.sum(axis=1, keepdims=True)
        proba = np.divide(dist, total, out=np.full(dist.shape, 1.0 / dist.shape[1]), where=total > 0)
        return Decisions(map=m, readout=np.asarray(counts).copy(), proba=proba, confidence=proba[n, m],
                         cycles=np.asarray(cycles, np.int64).copy(), timeout=t.copy())
