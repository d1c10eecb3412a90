"""What a run produces, shared by ``run`` (which fills it) and ``metrics`` (which reads it)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.region import OutputRegion

from .features import Planes
from .reference import Reference, reference_bands

__all__ = ["Prepared", "MachineRun", "PassRecord", "counts_dtype"]


def counts_dtype(counter_max: int) -> np.dtype:
    """The smallest unsigned dtype holding every counter value (0 .. n_max) of a machine."""
    for dtype in (np.uint8, np.uint16, np.uint32):
        if counter_max <= np.iinfo(dtype).max:
            return np.dtype(dtype)
    raise ValueError(f"counter max {counter_max} does not fit 32 bits")


@dataclass
class Prepared:
    """Everything about a pair that does not depend on the machine.

    The reference is kept as its MAP only; its posterior is recomputed band by band where
    a figure needs it (:meth:`reference_bands`), so no H x W x (Dmax+2) volume is held.
    """

    left: np.ndarray
    right: np.ndarray
    model: ModelParams
    planes: tuple[Planes, Planes]  # both images' planes the model reads (host.features.model_planes)
    reference_map: np.ndarray | None  # (Ho, Wo) int16, -1 = no match; None: prepared without it
    reference_seconds: float
    gt: np.ndarray | None = None  # ground truth cut to the output region (map coordinates)
    gt_image: np.ndarray | None = None  # ground truth in image coordinates (for SGBM)

    @property
    def region(self) -> OutputRegion:
        return OutputRegion.of_model(self.left.shape, self.model)

    @property
    def shape(self) -> tuple[int, int]:
        """Output region (rows, columns) in map pixels."""
        return self.region.shape

    def reference_bands(self, band_rows: int | None = None) -> Iterator[tuple[slice, Reference]]:
        """The float64 reference (posterior and MAP) band by band; see ``reference.reference_bands``."""
        return reference_bands(*self.planes, self.model, band_rows=band_rows)


@dataclass
class MachineRun:
    """Per-pixel machine results laid out over the output region."""

    engine: str
    machine: MachineParams
    map: np.ndarray  # (Ho, Wo) int16, -1 = no match (timeouts unless the machine answers them)
    # counts, cycles: None only from a board asked for the MAP without them (--board-fields)
    counts: np.ndarray | None  # (Ho, Wo, M), the smallest unsigned dtype holding n_max (counts_dtype)
    cycles: np.ndarray | None  # (Ho, Wo) int64
    nomatch: np.ndarray  # (Ho, Wo) bool, the no-match row won
    timeout: np.ndarray  # (Ho, Wo) bool, the watchdog stopped the run
    seconds: float  # time inside the engine's run calls
    words_seconds: float  # time building likelihood memories
    wall_cycles: int | None = None  # RTL engines: clock cycles including loading (None: model)
    # The passes run before the model's own (census-lr's "right"), by pass name, in order.
    passes: dict[str, PassRecord] = field(default_factory=dict)
    engine_figures: dict[str, object] | None = None  # what the engine says of the run (a board: its link's)

    @property
    def operator_samples_per_pixel(self) -> float | None:
        """The machines' work per output pixel: over every pass, its machine's operators (rows x operator
        columns) x B x its compute cycles summed over its pixels, divided by the output pixels (a pass of
        more pixels than the output weighs more); None for a run without cycles or pixels, and for the
        logarithmic machine, which samples nothing."""
        if self.cycles is None or not self.map.size:
            return None
        runs = [(self.machine, self.cycles), *((r.machine, r.cycles) for r in self.passes.values())]
        work = 0.0
        for m, c in runs:
            samples = m.kind.samples_per_pixel(m, float(np.sum(c, dtype=np.float64)))
            if samples is None:  # a machine that samples nothing (the logarithmic one)
                return None
            work += m.operators * samples
        return work / self.map.size


@dataclass
class PassRecord:
    """A pass run before the model's own, over its grid (``host.likelihoods.pass_grid``), on its own
    machine: its MAPs as the passes after it read them."""

    machine: MachineParams
    map: np.ndarray  # (Ho, W) int16, -1 = none (its no-match row won, or a timeout)
    cycles: np.ndarray  # (Ho, W) int64
    timeout: np.ndarray  # (Ho, W) bool
    seconds: float
    wall_cycles: int | None = None
