"""Evidence columns: the unit of a disparity model (paper sec. 3: every piece of evidence is one more
operator column, and the AND gates multiply them).

Each column kind (one module each) defines in one place:

- the planes of both images it reads (a FEATURES column, and the no-match rule): each a
  :class:`~.planes.Plane`, its name, filter and window, so that the host computes exactly the planes a
  model reads and a model's margin follows from its windows;
- its options: the model parameters it owns (:class:`~.base.Option`: default, check, help; the
  command line's flag is derived from the name);
- its cost (a feature difference, a census Hamming distance, a prior distance |d - d_n|, the
  consistency test) and its float64 likelihood table indexed by that cost, checked once to lie in
  [0, 1] and be nonincreasing in the cost (:meth:`~.base.Term.table`), and the table quantized to
  W-bit words (``table(word_bits)``);
- its entry in the no-match row;
- where its words come from (:class:`~.base.Source`): both images' features, the machine's own
  previous result (feedback), the previous map row's results (a loaded above column), or another
  pass's results;
- its host words (the twin of the RTL's lane) and its reference factor: ``words(ctx)`` from a
  :class:`~.base.PassContext` (both images' planes, the row above's MAPs, other passes' MAPs by name),
  on the word table or on the float64 table;
- its checks against a machine (``check_machine``).

Kinds: :class:`~.features.Mean`, :class:`~.features.GradH`, :class:`~.features.GradV` (the paper's),
:class:`~.gradient.GradMag` (an option of the paper model),
:class:`~.census.Census`, :class:`~.prior.LeftPrior` (feedback) and :class:`~.prior.AbovePrior`
(loaded), :class:`~.consistency.Consistency` (fed by another pass: :func:`~.consistency.consistency` makes
the kind of a pass), :class:`~.fused.Fused` (FEATURES columns as one, in the energy form:
:func:`~.fused.fused` makes a kind of its members), :class:`~.semiglobal.SemiGlobal` (a fused column's
energies aggregated along causal scanline paths: :func:`~.semiglobal.semiglobal` makes a kind of its
member); and the no-match row's floor :class:`~.features.NoMatchFloor`. A model
(:mod:`bayesmachine.models`) is a list of them.
"""

from .base import Column, Option, PassContext, PlaneColumn, Source, Table, Term, likelihood_formula, quantize
from .census import CENSUS_SIGMA, CENSUS_WINDOWS, Census, census_bits, census_codes, census_offsets, hamming
from .consistency import Consistency, consistency, lr_consistent, lr_unknown, right_lanes_valid
from .energy import ENERGY_MAX_BITS, ENERGY_STEP, EnergyTable, energy_codes, exp_table
from .features import (
    FEATURE_COLUMNS,
    FEATURES,
    MAX_ABS,
    SCALES,
    FeatureColumn,
    GradH,
    GradV,
    Mean,
    NoMatchFloor,
)
from .fused import FUSE_COLUMNS, Fused, fused
from .gradient import GRADIENT_MAGNITUDE, GradMag
from .planes import Plane
from .prior import NEIGHBOUR_PRIOR, AbovePrior, LeftPrior, NeighbourPrior, neighbour_words
from .semiglobal import PATHS, SEMIGLOBAL, SemiGlobal, semiglobal

__all__ = [
    "Column", "PlaneColumn", "PassContext", "Plane", "Option", "Source", "Table", "Term",
    "likelihood_formula", "quantize",
    "FEATURES", "SCALES", "MAX_ABS", "FeatureColumn", "Mean", "GradH", "GradV", "FEATURE_COLUMNS",
    "NoMatchFloor", "GRADIENT_MAGNITUDE", "GradMag",
    "CENSUS_WINDOWS", "CENSUS_SIGMA", "Census", "census_bits", "census_codes", "census_offsets", "hamming",
    "NEIGHBOUR_PRIOR", "NeighbourPrior", "LeftPrior", "AbovePrior", "neighbour_words",
    "ENERGY_STEP", "ENERGY_MAX_BITS", "EnergyTable", "energy_codes", "exp_table",
    "FUSE_COLUMNS", "Fused", "fused",
    "PATHS", "SEMIGLOBAL", "SemiGlobal", "semiglobal",
    "Consistency", "consistency", "lr_consistent", "lr_unknown", "right_lanes_valid",
    "COLUMN_KINDS",
]

# The closed set of column kinds the package defines (each with its lane builder on chip).
COLUMN_KINDS: tuple[type[Column], ...] = (Mean, GradH, GradV, GradMag, Census, LeftPrior, AbovePrior,
                                          Consistency, Fused, SemiGlobal)
