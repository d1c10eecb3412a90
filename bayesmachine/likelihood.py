"""The disparity model's likelihoods (paper eq. 2 and 4) and their quantization to memory words.

Pure computation (NumPy only), shared by the host, which builds likelihood memories per
pixel, and the on-chip front end, which needs the same tables at elaboration.

The likelihood of a feature f at disparity d is ``p0 + (1-p0) exp(-C / (2 sigma_f^2))`` with
``C = (f_l(x,y) - f_r(x-d,y))^2``. The features are kept as integer sums (``f = s / k``,
k in :data:`SCALES`), so C is ``delta^2 / k^2`` with ``delta`` an integer difference of sums
and the likelihood depends only on |delta|: one lookup table per feature, indexed by
|delta|, gives exactly the value the formula gives (same float operations on the same
operands). The no-match probability ``p_nm0 + (1-p_nm0) exp(-gV_l^2 / (2 sigma_nm^2))`` is a
table indexed by |gv20|.

Two models (``ModelParams.name``):

* ``"paper"``: the paper's columns m, gH, gV and its no-match row [P_nm(gV), 1, 1], a
  uniform prior. Bit for bit what the project computed before the census model existed.
* ``"census"``: the paper's three columns, a census column, a calibrated no-match row and a
  raster-order neighbour prior (issue 17). The census column's likelihood is
  ``L_c(h) = census_p0 + (1-census_p0) exp(-h^2 / (2 census_sigma^2))`` of the Hamming
  distance h between the left and right census codes (a table indexed by h = 0..bits, the
  same formula with scale 1). The no-match row is [P_nm(gV), 1, 1, L_c(h_nm)]: the census
  table read at the constant address h_nm. The neighbour prior of pixel (y, x) is
  ``pi(d) = prod_n f(|d - d_n|)`` over its left (y, x-1) and upper (y-1, x) neighbours'
  MAPs d_n, ``f(k) = eps + (1-eps) exp(-k^2 / (2 s^2))`` (a table indexed by k = 0..Dmax),
  a factor 1 for a neighbour called no match or outside the output region; the no-match
  row's prior is ``prior_nomatch`` per matched neighbour. On the machine
  (:func:`disparity_machine`: ``prior="neighbour"``) each neighbour's factor is a column of
  its own, so the AND gates multiply the two factor words exactly (no rounded combined word):
  the left factor is the machine's feedback column, formed from its own previous result
  through ``feedback_words`` (the quantized table clamped where it stops changing), the above
  factor a loaded column (:func:`neighbour_words` of the previous map row's results).
* ``"census-lr"``: the census model and a left-right consistency column (issue 22). A right pass
  (:attr:`ModelParams.right_model`: the census model with the right image as reference, lane d
  pairing right map column x_r with left map column x_r + d, raster order, its own left/above
  neighbour prior, and the census model's no-match row, ``lr_right_nomatch``; without it, the
  issue's right pass, that row's words are 0, so it never fires) gives the right MAPs d_R; the
  left pass multiplies in one more column: row d of left map column x gets 1 when
  ``|d_R(x - d) - d| <= lr_tolerance`` and ``lr_beta`` otherwise; a lane whose right pixel x - d has
  no right MAP (the right pass's no match or its watchdog) is *neutral* (``lr_neutral``): factor 1,
  no information either way (without ``lr_neutral``, the issue's rule: beta); x - d outside the
  right pass's columns gets beta. The no-match row gets ``lr_gamma`` when any lane is consistent
  (a neutral lane does not count), 1 when none is (0 with ``lr_nomatch=False``: no no-match row at
  all), and its prior factor per matched neighbour is ``prior_nomatch`` (0.1 by default for this
  model). Its machine's watchdog is by default :data:`LR_WATCHDOG_RUNS` runs of n_max + 1 cycles
  (:func:`disparity_machine`): a pixel whose winning row fires too rarely stops as no match. The
  right no-match row, the neutral lanes and the watchdog cut the model's cycles per pixel by more than
  an order of magnitude within the issue's accuracy target (docs/host.md, "census-lr's cycles").
  :func:`lr_consistent`, :func:`lr_unknown` and :func:`consistency_column` (both through
  :func:`lr_column`) are the one definition the host, the references and the machine runs read. The
  right pass covers right map columns ``x_first - Dmax .. x_last`` (every column an output
  pixel consults); its lane d is loaded with word 0 (it never fires) where the left pixel
  x_r + d lies right of ``x_last``, the last output column (:func:`right_lanes_valid`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from numbers import Real

import numpy as np

from bayesmachine.params import DEFAULT_DMAX, STEREO_ROWS_PER_BEAT, MachineParams, ParameterError, nth_machine

__all__ = [
    "MODELS",
    "LR_WATCHDOG_RUNS",
    "DEFAULT_MODEL",
    "HARDWARE_MODEL",
    "CENSUS_WINDOWS",
    "FEATURES",
    "SCALES",
    "MAX_ABS",
    "ModelParams",
    "LikelihoodTables",
    "likelihood_tables",
    "likelihood_formula",
    "quantize",
    "QuantizedTables",
    "check_disparity_machine",
    "disparity_machine",
    "neighbour_words_per_beat",
    "neighbour_words",
    "lr_consistent",
    "lr_unknown",
    "lr_column",
    "right_lanes_valid",
    "consistency_column",
    "right_machine",
]

MODELS = ("paper", "census", "census-lr")
# The model a command that computes disparities on the host or in simulation runs when --model is
# not given (run, reference, sweep): census-lr, the best on the measurements (README, Models), which
# the host, every engine and the simulated StereoMachine compute.
# ModelParams() itself stays the paper's model (its figures stay reproducible with --model paper).
DEFAULT_MODEL = "census-lr"
# The default of what builds or drives an FPGA design (emit, synth, board, run --engine board,
# run --machines K > 1): census-lr's StereoMachine does not place on the ECP5-85F (89 % of its
# flip-flops, docs/fpga.md) and K machines cannot share its right pass; census is the best model
# that does. cliargs.default_model is the one rule choosing between the two.
HARDWARE_MODEL = "census"
# Census windows the model takes: 7x7 (48 bits, codes fit a uint64) or the cheaper 5x5 (24 bits).
CENSUS_WINDOWS = (5, 7)
# Default census sigma per window (issue 17: 6 for 7x7, 3 for 5x5).
CENSUS_SIGMA = {7: 6.0, 5: 3.0}

FEATURES = ("m", "gh", "gv")
# Integer scale of each stored feature: f = sum / scale (5x5 mean: 25; gradients: 2 x 2 x 5 = 20).
SCALES = {"m": 25, "gh": 20, "gv": 20}
# Largest |sum| each feature can reach for 8-bit input (sizes the lookup tables).
MAX_ABS = {"m": 25 * 255, "gh": 10 * 255, "gv": 10 * 255}

# The command-line spelling of each model parameter, for error messages.
OPTION_NAMES = {
    "dmax": "--dmax",
    "p0": "--p0",
    "sigma_m": "--sigma-m/--sigma",
    "sigma_gh": "--sigma-gh/--sigma",
    "sigma_gv": "--sigma-gv/--sigma",
    "p_nm0": "--p-nm0",
    "sigma_nm": "--sigma-nm",
    "name": "--model",
    "census_window": "--census-window",
    "census_p0": "--census-p0",
    "census_sigma": "--census-sigma",
    "census_nomatch_h": "--census-nomatch-h",
    "neighbour_prior": "--neighbour-prior",
    "prior_eps": "--prior-eps",
    "prior_s": "--prior-s",
    "prior_nomatch": "--prior-nomatch",
    "lr_beta": "--lr-beta",
    "lr_gamma": "--lr-gamma",
    "lr_tolerance": "--lr-tolerance",
    "lr_nomatch": "--lr-nomatch/--no-lr-nomatch",
    "lr_right_nomatch": "--lr-right-nomatch/--no-lr-right-nomatch",
    "lr_right_max_cycles": "--lr-right-max-cycles",
    "lr_neutral": "--lr-neutral/--no-lr-neutral",
}
# The census model's own fields: left out of a paper model's to_dict(), so its reports and the
# Verilator design keys (sim/stereo_engine.py hashes model.to_dict()) stay what they were.
CENSUS_FIELDS = ("name", "census_window", "census_p0", "census_sigma", "census_nomatch_h",
                 "neighbour_prior", "prior_eps", "prior_s", "prior_nomatch")
# The left-right model's own fields: left out of the other models' to_dict() (same reason).
LR_FIELDS = ("lr_beta", "lr_gamma", "lr_tolerance", "lr_nomatch", "lr_right_nomatch", "lr_right_max_cycles",
             "lr_neutral")
# The census-lr model's default no-match prior factor per matched neighbour (issue 22).
LR_PRIOR_NOMATCH = 0.1
# The census-lr machine's default watchdog, in runs of n_max + 1 cycles: max_cycles =
# LR_WATCHDOG_RUNS * (counter_max + 1) (1088 at counter max 16). A run lasts about (n_max + 1) / p_win
# cycles, so a pixel stops as a timeout (no match) when its winning row fires less than about once in
# 64 cycles: every hypothesis explains the pixel badly. It cuts the long tail of the left pass's runs
# (docs/host.md, "census-lr's cycles"); a given max_cycles (--max-cycles) wins.
LR_WATCHDOG_RUNS = 64


def _error(name: str, text: str) -> ParameterError:
    return ParameterError(f"{OPTION_NAMES[name]}: {name} {text}")


def _check_sigma(name: str, v: object) -> None:
    if isinstance(v, bool) or not isinstance(v, Real) or not (math.isfinite(v) and v > 0):
        raise _error(name, f"must be a finite number > 0, got {v!r}")
    two_s2 = 2.0 * float(v) * float(v)
    if not (math.isfinite(two_s2) and two_s2 > 0.0):
        raise _error(
            name, f"= {v!r}: 2 sigma^2 = {two_s2!r} is not a finite positive float64 "
            "(use a sigma between about 1e-150 and 1e150)"
        )


def _check_probability(name: str, v: object) -> None:
    if isinstance(v, bool) or not isinstance(v, Real) or not 0.0 <= float(v) <= 1.0:
        raise _error(name, f"must be a probability in [0, 1], got {v!r}")


@dataclass(frozen=True)
class ModelParams:
    """The Bayesian disparity model (paper table 1 defaults; ``name="census"``: issue 17), validated up front.

    Each check is what the computation needs: probabilities in [0, 1] (p_nm0 > 0, the
    floor that keeps every posterior defined) and sigmas whose ``2 sigma^2`` is a finite
    positive float64 (a sigma of 1e-300 would square to 0 and give NaN likelihoods).

    The census fields are validated for every model but used by ``"census"`` only; ``None``
    means "the default for this window": ``census_sigma`` 6 (7x7) or 3 (5x5), ``census_nomatch_h``
    bits / 8 (0 gives L_c(0) = 1: a no-match row left uncalibrated), ``prior_nomatch`` the
    prior's value at one s, ``f(s) = eps + (1-eps) exp(-1/2)`` (0.626 by default). The resolved
    values are the properties ``sigma_c``, ``h_nm`` and ``prior_nm``.
    """

    dmax: int = DEFAULT_DMAX
    p0: float = 0.02
    sigma_m: float = 10.0
    sigma_gh: float = 10.0
    sigma_gv: float = 10.0
    p_nm0: float = 0.01
    sigma_nm: float = 8.0
    name: str = "paper"
    census_window: int = 7
    census_p0: float = 0.02
    census_sigma: float | None = None
    census_nomatch_h: int | None = None
    neighbour_prior: bool = True
    prior_eps: float = 0.05
    prior_s: float = 4.0
    prior_nomatch: float | None = None
    lr_beta: float = 0.1
    lr_gamma: float = 0.01
    lr_tolerance: int = 1
    lr_nomatch: bool = True
    lr_right_nomatch: bool = True
    lr_right_max_cycles: int | None = None
    lr_neutral: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.dmax, bool) or not isinstance(self.dmax, int) or not 0 <= self.dmax <= 4094:
            raise _error("dmax", f"must be an integer in [0, 4094], got {self.dmax!r}")
        for name in ("p0", "p_nm0"):
            _check_probability(name, getattr(self, name))
        if not self.p_nm0 > 0:
            # The floor of the no-match hypothesis keeps every pixel's posterior defined: without
            # it, a pixel whose likelihoods all underflow to 0 would have 0/0.
            raise _error("p_nm0", "must be > 0: it keeps every pixel's posterior defined")
        for name in ("sigma_m", "sigma_gh", "sigma_gv", "sigma_nm"):
            _check_sigma(name, getattr(self, name))
        if self.name not in MODELS:
            raise _error("name", f"must be one of {', '.join(MODELS)}, got {self.name!r}")
        w = self.census_window
        if isinstance(w, bool) or not isinstance(w, int) or w not in CENSUS_WINDOWS:
            raise _error("census_window", f"must be 5 or 7 (a 5x5 or 7x7 census window), got {w!r}")
        _check_probability("census_p0", self.census_p0)
        if self.census_sigma is not None:
            _check_sigma("census_sigma", self.census_sigma)
        h, bits = self.census_nomatch_h, self.census_bits
        if h is not None and (isinstance(h, bool) or not isinstance(h, int) or not 0 <= h <= bits):
            raise _error("census_nomatch_h", f"must be an integer Hamming distance in [0, {bits}] "
                         f"(the {w}x{w} census has {bits} bits), got {h!r}")
        if not isinstance(self.neighbour_prior, bool):
            raise _error("neighbour_prior", f"must be True or False, got {self.neighbour_prior!r}")
        _check_probability("prior_eps", self.prior_eps)
        _check_sigma("prior_s", self.prior_s)
        if self.prior_nomatch is not None:
            _check_probability("prior_nomatch", self.prior_nomatch)
            if not self.prior_nomatch > 0:
                # With both neighbours matched and every disparity's likelihood ~0, a no-match prior
                # of 0 would leave the pixel 0/0.
                raise _error("prior_nomatch", "must be > 0: it keeps every pixel's posterior defined")
        for name in ("lr_beta", "lr_gamma"):
            _check_probability(name, getattr(self, name))
            if not getattr(self, name) > 0:
                # beta 0 with no consistent lane (and no no-match row) would leave a pixel 0/0.
                raise _error(name, "must be > 0: it keeps every pixel's posterior defined")
        t = self.lr_tolerance
        if isinstance(t, bool) or not isinstance(t, int) or not 0 <= t <= 4094:
            raise _error("lr_tolerance", f"must be an integer disparity distance in [0, 4094], got {t!r}")
        for name in ("lr_nomatch", "lr_right_nomatch", "lr_neutral"):
            if not isinstance(getattr(self, name), bool):
                raise _error(name, f"must be True or False, got {getattr(self, name)!r}")
        c = self.lr_right_max_cycles
        if c is not None and (isinstance(c, bool) or not isinstance(c, int) or not 2 <= c <= (1 << 32) - 1):
            raise _error("lr_right_max_cycles", f"must be an integer number of cycles in [2, 2^32 - 1] "
                         f"(or None: the left machine's watchdog), got {c!r}")
        if self.lr and not self.neighbour_prior:
            # The right pass and the left pass are the census model with its prior (issue 22).
            raise _error("neighbour_prior", "must be on for --model census-lr (both passes use it)")

    @property
    def hypotheses(self) -> int:
        """Dmax + 2: disparities 0..Dmax and no match (the machine's rows M)."""
        return self.dmax + 2

    @property
    def census(self) -> bool:
        """Whether the model has a census column (census and census-lr)."""
        return self.name in ("census", "census-lr")

    @property
    def lr(self) -> bool:
        """Whether the model has the left-right consistency column (census-lr)."""
        return self.name == "census-lr"

    @property
    def right_model(self) -> ModelParams:
        """The right pass's model: this census-lr model as a census model (its columns, its prior,
        the census model's own no-match prior factor)."""
        if not self.lr:
            raise ValueError(f"the {self.name} model has no right pass")
        return replace(self, name="census", prior_nomatch=None)

    @property
    def has_prior(self) -> bool:
        """Whether the model has the raster-order neighbour prior (census model only)."""
        return self.census and self.neighbour_prior

    @property
    def columns(self) -> int:
        """Data columns of the machine (the prior column aside): 3 (paper), 4 (+ census), 5 (+ left-right)."""
        return 5 if self.lr else 4 if self.census else 3

    @property
    def census_bits(self) -> int:
        """Bits of a census code: the window's neighbours (48 for 7x7, 24 for 5x5)."""
        return self.census_window * self.census_window - 1

    @property
    def margin(self) -> int:
        """Pixels from a window's centre to its edge, for the model's largest window (5x5 filters: 2,
        7x7 census: 3): the output region keeps every window inside the image (``bayesmachine.region``)."""
        return max(2, self.census_window // 2) if self.census else 2

    @property
    def sigma_c(self) -> float:
        """The census sigma in use (``census_sigma`` or the window's default)."""
        return float(self.census_sigma) if self.census_sigma is not None else CENSUS_SIGMA[self.census_window]

    @property
    def h_nm(self) -> int:
        """The no-match row's Hamming distance in use (``census_nomatch_h`` or bits / 8)."""
        return self.census_nomatch_h if self.census_nomatch_h is not None else self.census_bits // 8

    @property
    def prior_nm(self) -> float:
        """The no-match row's prior factor per matched neighbour in use (default: f(s))."""
        if self.prior_nomatch is not None:
            return float(self.prior_nomatch)
        if self.lr:
            return LR_PRIOR_NOMATCH
        return float(likelihood_formula(np.int64(1), 1, self.prior_eps, 1.0))

    def sigma(self, feature: str) -> float:
        return float(getattr(self, f"sigma_{feature}"))

    def to_dict(self) -> dict[str, object]:
        """The fields; a paper model's without the census ones (its reports and cache keys unchanged).

        A census model's dict holds the resolved ``census_sigma``, ``census_nomatch_h`` and
        ``prior_nomatch`` (what ran), so ``ModelParams(**to_dict())`` is the same model.
        """
        out = asdict(self)
        if not self.lr:
            out = {k: v for k, v in out.items() if k not in LR_FIELDS}
        if not self.census:
            return {k: v for k, v in out.items() if k not in CENSUS_FIELDS}
        out.update(census_sigma=self.sigma_c, census_nomatch_h=self.h_nm, prior_nomatch=self.prior_nm)
        return out


def likelihood_formula(delta: np.ndarray, scale: int, p0: float, sigma: float) -> np.ndarray:
    """Eq. 2 from integer differences of sums: C = delta^2 / scale^2, exact in float64.

    Both the lookup tables and the plain oracle go through this one function, so the
    two give bit-identical likelihoods.
    """
    d = np.asarray(delta, dtype=np.int64)
    cost = (d * d) / float(scale * scale)
    return p0 + (1.0 - p0) * np.exp(-cost / (2.0 * sigma * sigma))


@dataclass(frozen=True)
class LikelihoodTables:
    """float64 tables indexed by |delta| (features) and |gv20| (no match).

    Census model only (None otherwise): ``census`` indexed by the Hamming distance h = 0..bits,
    ``census_nomatch`` = L_c(h_nm) (the no-match row's census entry); with the neighbour prior,
    ``prior`` indexed by |d - d_n| = 0..Dmax and ``prior_nomatch`` (the no-match row's factor
    per matched neighbour).
    """

    m: np.ndarray
    gh: np.ndarray
    gv: np.ndarray
    nomatch: np.ndarray
    census: np.ndarray | None = None
    census_nomatch: float | None = None
    prior: np.ndarray | None = None
    prior_nomatch: float | None = None
    lr_beta: float | None = None
    lr_gamma: float | None = None


def likelihood_tables(model: ModelParams) -> LikelihoodTables:
    """The per-feature lookup tables replacing exp in the fast paths; every value in [0, 1]."""
    tabs = {}
    for f in FEATURES:
        # |f_l - f_r| over 8-bit images is at most twice the largest |sum| of a signed
        # feature (gradients) or the largest sum (the mean, which is never negative).
        n = MAX_ABS[f] + 1 if f == "m" else 2 * MAX_ABS[f] + 1
        tabs[f] = likelihood_formula(np.arange(n), SCALES[f], model.p0, model.sigma(f))
    nm = likelihood_formula(np.arange(MAX_ABS["gv"] + 1), SCALES["gv"], model.p_nm0, model.sigma_nm)
    census = census_nm = prior = prior_nm = None
    checks = [("sigma_m", tabs["m"]), ("sigma_gh", tabs["gh"]), ("sigma_gv", tabs["gv"]), ("sigma_nm", nm)]
    if model.census:
        census = likelihood_formula(np.arange(model.census_bits + 1), 1, model.census_p0, model.sigma_c)
        census_nm = float(census[model.h_nm])
        checks.append(("census_sigma", census))
        if model.neighbour_prior:
            prior = likelihood_formula(np.arange(model.dmax + 1), 1, model.prior_eps, model.prior_s)
            prior_nm = model.prior_nm
            checks.append(("prior_s", prior))
    for name, tab in checks:
        if not ((tab >= 0.0) & (tab <= 1.0)).all():  # NaN fails both comparisons
            raise _error(name, f"= {getattr(model, name)!r} gives likelihoods outside [0, 1]")
    lr_beta = float(model.lr_beta) if model.lr else None
    lr_gamma = float(model.lr_gamma) if model.lr else None
    return LikelihoodTables(tabs["m"], tabs["gh"], tabs["gv"], nm, census, census_nm, prior, prior_nm,
                            lr_beta, lr_gamma)


def quantize(p: np.ndarray | float, word_bits: int) -> np.ndarray:
    """Probability -> likelihood-memory word: q = round(p * 2^W), round half up, in [0, 2^W].

    ``p * 2^W`` is exact in float64 (a power-of-two scaling) and so is its fractional part,
    so "half up" is decided exactly (``floor(x + 0.5)`` would not be: 0.5 - 2^-54 + 0.5 rounds
    to 1.0). 0 maps to 0 and 1 to 2^W. Values outside [0, 1]
    or NaN are errors (they mean a bug upstream, not something to clip silently).
    """
    if not 1 <= word_bits <= 15:
        raise ValueError(f"word_bits must be in [1, 15] (words up to 2^15 fit uint16), got {word_bits}")
    arr = np.asarray(p, dtype=np.float64)
    bad = ~((arr >= 0.0) & (arr <= 1.0))  # NaN compares false, so it lands here too
    if bad.any():
        first = arr[bad].flat[0]
        raise ValueError(f"probabilities must be in [0, 1] to quantize, got {first!r} ({int(bad.sum())} bad)")
    one = 1 << word_bits
    scaled = arr * one
    q = np.floor(scaled)
    q += (scaled - q) >= 0.5
    return np.clip(q, 0, one).astype(np.uint16)


class QuantizedTables:
    """The likelihood tables quantized once to the machine's word (the fast word path).

    Census model: ``census`` (by h) and ``census_nomatch`` = ``census[h_nm]``; with the
    neighbour prior, ``prior`` (by |d - d_n|), ``prior_nomatch`` and ``prior_last``, the
    first |d - d_n| from which the quantized prior no longer changes (a table clamped there
    gives the same words).
    """

    def __init__(self, tables: LikelihoodTables, word_bits: int) -> None:
        self.word_bits = word_bits
        self.m = quantize(tables.m, word_bits)
        self.gh = quantize(tables.gh, word_bits)
        self.gv = quantize(tables.gv, word_bits)
        self.nomatch = quantize(tables.nomatch, word_bits)
        self.one = 1 << word_bits
        self.census = self.census_nomatch = self.prior = self.prior_nomatch = self.prior_last = None
        if tables.census is not None:
            self.census = quantize(tables.census, word_bits)
            self.census_nomatch = int(quantize(tables.census_nomatch, word_bits))
        if tables.prior is not None:
            self.prior = quantize(tables.prior, word_bits)
            self.prior_nomatch = int(quantize(tables.prior_nomatch, word_bits))
            changes = np.flatnonzero(self.prior[1:] != self.prior[:-1])
            self.prior_last = int(changes[-1]) + 1 if changes.size else 0
        self.lr_beta = self.lr_gamma = None
        if tables.lr_beta is not None and tables.lr_gamma is not None:
            self.lr_beta = int(quantize(tables.lr_beta, word_bits))
            self.lr_gamma = int(quantize(tables.lr_gamma, word_bits))


def neighbour_words(qtables: QuantizedTables, dmax: int, hat: np.ndarray) -> np.ndarray:
    """One neighbour's prior factor words (P, Dmax+2) of P pixels from that neighbour's MAPs ``hat``.

    ``hat`` (P,): the neighbour's disparity, -1 for no match, a timeout or outside the output region
    (factor 1.0: every word 2^W). Row d gets ``prior[|d - hat|]``, the no-match row
    ``prior_nomatch``. A neighbour-prior machine's loaded column 0 is the above neighbour's
    factor; its feedback column is the same rule for the left neighbour, formed on chip.
    """
    if qtables.prior is None:
        raise ValueError("these tables have no neighbour prior (a census model with neighbour_prior has one)")
    hat = np.asarray(hat)
    if hat.ndim != 1 or hat.dtype.kind not in "iu":
        raise ValueError(f"neighbour MAPs must be a 1-D integer array, got {hat.dtype} {hat.shape}")
    if hat.size and hat.max() > dmax:
        raise ValueError(f"neighbour MAPs must be -1 (none) or disparities 0..{dmax}, got {int(hat.max())}")
    f = np.full((hat.shape[0], dmax + 2), qtables.one, dtype=np.uint16)
    matched = hat >= 0
    d = np.arange(dmax + 1)
    f[matched, : dmax + 1] = qtables.prior[np.abs(d[None, :] - hat[matched, None].astype(np.int64))]
    f[matched, dmax + 1] = qtables.prior_nomatch
    return f


def right_lanes_valid(right_columns: np.ndarray, dmax: int, last: int) -> np.ndarray:
    """(Wr, Dmax+1) bool: lane d of right map column x_r pairs it with left map column x_r + d, which
    must not lie right of ``last``, the last output column (a lane past it is loaded with word 0)."""
    xr = np.asarray(right_columns, dtype=np.int64)
    return (xr[:, None] + np.arange(dmax + 1)[None, :]) <= last


def lr_consistent(right_map: np.ndarray, right_first: int, columns: np.ndarray, dmax: int,
                  tolerance: int) -> np.ndarray:
    """The left-right test: (..., Wo, Dmax+1) bool, lane d of left map column ``columns[i]`` consistent.

    ``right_map`` (..., Wr): the right pass's MAPs of right map columns ``right_first ..``, -1 for none
    (no MAP, a timeout). Lane d is consistent when ``|d_R(x - d) - d| <= tolerance``; a column
    x - d outside ``right_map``'s columns or without a MAP is not.
    """
    hat = np.asarray(right_map)
    if hat.dtype.kind not in "iu":
        raise ValueError(f"right MAPs must be integers (-1: none), got {hat.dtype}")
    cols = np.asarray(columns, dtype=np.int64)
    d = np.arange(dmax + 1)
    j = cols[:, None] - d[None, :] - int(right_first)  # (Wo, Dmax+1) index into right_map
    inside = (j >= 0) & (j < hat.shape[-1])
    got = hat[..., np.clip(j, 0, max(0, hat.shape[-1] - 1))].astype(np.int64)
    return inside & (got >= 0) & (np.abs(got - d) <= tolerance)


def lr_unknown(right_map: np.ndarray, right_first: int, columns: np.ndarray, dmax: int) -> np.ndarray:
    """(..., Wo, Dmax+1) bool: lane d of left map column ``columns[i]`` reads a right pixel x - d inside
    ``right_map``'s columns that has no right MAP (-1: the right pass's no match or a timeout).

    With ``lr_neutral`` such a lane is neutral in :func:`consistency_column` (factor 1); a lane whose
    x - d lies outside the right columns is not unknown (it stays inconsistent, beta).
    """
    hat = np.asarray(right_map)
    if hat.dtype.kind not in "iu":
        raise ValueError(f"right MAPs must be integers (-1: none), got {hat.dtype}")
    cols = np.asarray(columns, dtype=np.int64)
    j = cols[:, None] - np.arange(dmax + 1)[None, :] - int(right_first)
    inside = (j >= 0) & (j < hat.shape[-1])
    return inside & (hat[..., np.clip(j, 0, max(0, hat.shape[-1] - 1))].astype(np.int64) < 0)


def consistency_column(consistent: np.ndarray, model: ModelParams, one: float | int, beta: float | int,
                       gamma: float | int, unknown: np.ndarray | None = None) -> np.ndarray:
    """The consistency column (..., Dmax+2) of :func:`lr_consistent`'s test (..., Dmax+1).

    Row d: ``one`` when consistent, ``beta`` otherwise; with ``model.lr_neutral`` also ``one`` where
    ``unknown`` (:func:`lr_unknown`: the lane's right pixel has no right MAP; required then). The
    no-match row: ``gamma`` when any lane is consistent (an unknown lane does not count), ``one`` when
    none is, 0 without a no-match row (``lr_nomatch=False``). In floats (1.0, beta, gamma: the
    reference) or in words (2^W and the quantized beta, gamma: the machine's loaded column); the
    dtype follows ``one`` (float64, or uint16 for words).
    """
    c = np.asarray(consistent, dtype=bool)
    dtype = np.float64 if isinstance(one, float) else np.uint16
    out = np.empty((*c.shape[:-1], c.shape[-1] + 1), dtype=dtype)
    if model.lr_neutral:
        if unknown is None or np.shape(unknown) != c.shape:
            got = None if unknown is None else np.shape(unknown)
            raise ValueError(f"--lr-neutral: the consistency column needs the unknown lanes (lr_unknown), "
                             f"shape {c.shape}, got {got}")
        out[..., :-1] = np.where(c | np.asarray(unknown, dtype=bool), one, beta)
    else:
        out[..., :-1] = np.where(c, one, beta)
    if model.lr_nomatch:
        out[..., -1] = np.where(c.any(axis=-1), gamma, one)
    else:
        out[..., -1] = 0
    return out


def lr_column(right_map: np.ndarray, right_first: int, columns: np.ndarray, model: ModelParams,
              one: float | int, beta: float | int, gamma: float | int) -> np.ndarray:
    """The consistency column (..., Wo, Dmax+2) of left map columns ``columns`` from the right MAPs
    ``right_map`` (..., Wr) of right map columns ``right_first ..``: :func:`lr_consistent` (and
    :func:`lr_unknown` with ``lr_neutral``) then :func:`consistency_column`, as every caller needs."""
    consistent = lr_consistent(right_map, right_first, columns, model.dmax, model.lr_tolerance)
    unknown = lr_unknown(right_map, right_first, columns, model.dmax) if model.lr_neutral else None
    return consistency_column(consistent, model, one, beta, gamma, unknown)


def neighbour_words_per_beat(rows: int, loaded_columns: int) -> int:
    """A neighbour-prior machine's default ``words_per_beat``: the loaded words of
    :data:`~bayesmachine.params.STEREO_ROWS_PER_BEAT` rows per load beat (the front end's rule).

    A pixel's loaded words grow by the census and above-prior columns (5 per row: 410 at Dmax 80),
    which the 16 lanes of ``for_disparity`` would load in 26 beats, longer than 47 % of the runs
    on the bundled pair at counter max 16 (no run is shorter than 17 cycles): loading would show
    (63.7 wall cycles per pixel instead of 61.4, docs/host.md). Six rows per beat
    (30 lanes) load them in 14 beats, below the shortest run, so loading stays hidden behind the
    previous pixel's run (wall cycles per pixel ``max(k + 2, beats + 1) + 1``) from counter max 12
    up; a lane count a multiple of the loaded columns keeps a row's words in one beat.
    """
    return min(STEREO_ROWS_PER_BEAT, rows) * loaded_columns


def disparity_machine(model: ModelParams, **machine_kwargs: object) -> MachineParams:
    """The machine ``model`` needs: ``MachineParams.for_disparity(model.dmax, columns=model.columns, ...)``.

    With the neighbour prior (``model.has_prior``): ``prior="neighbour"``, ``feedback_words`` the
    quantized prior table clamped where it stops changing (``QuantizedTables.prior[:prior_last + 1]``),
    ``feedback_nomatch_word`` the quantized no-match factor, and ``words_per_beat`` by default
    :func:`neighbour_words_per_beat`. For census-lr ``max_cycles`` is by default
    :data:`LR_WATCHDOG_RUNS` x (``counter_max`` + 1), the watchdog that ends its long runs as no
    match (the right pass takes it too unless ``lr_right_max_cycles``). ``machine_kwargs`` are the
    other fields (``word_bits``, ``rng``, ...); a ``columns``, ``prior`` or feedback table
    contradicting the model is a ``ParameterError``.
    """
    if "columns" in machine_kwargs and machine_kwargs["columns"] != model.columns:
        raise ParameterError(f"columns: the {model.name} model has {model.columns} data columns, got "
                             f"columns={machine_kwargs['columns']!r}")
    kwargs = dict(machine_kwargs, columns=model.columns)
    prior = kwargs.get("prior")
    if model.has_prior:
        if prior is not None and prior != "neighbour":
            raise ParameterError(
                f"prior: the {model.name} model's neighbour prior needs the machine's prior 'neighbour' "
                f"(its own feedback column and a loaded above column), not {prior!r}; leave --prior out, "
                "or turn the neighbour prior off (--no-neighbour-prior)")
        # The other fields first, validated as usual (their errors name them), for the word width.
        own = ("prior", "feedback_words", "feedback_nomatch_word")
        rest = {k: v for k, v in kwargs.items() if k not in own}
        word_bits = MachineParams.for_disparity(model.dmax, **rest).word_bits  # type: ignore[arg-type]
        feedback, nm = feedback_table(model, word_bits)
        for name, want in (("feedback_words", feedback), ("feedback_nomatch_word", nm)):
            got = kwargs.get(name)
            if got is not None and (tuple(got) if name == "feedback_words" else got) != want:  # type: ignore[arg-type]
                raise ParameterError(f"{name}: the model's {word_bits}-bit prior table gives {want}, "
                                     f"got {got!r}")
        kwargs.update(prior="neighbour", feedback_words=feedback, feedback_nomatch_word=nm)
        kwargs.setdefault("words_per_beat", neighbour_words_per_beat(model.hypotheses, model.columns + 1))
    elif prior == "neighbour":
        raise ParameterError(f"prior: 'neighbour' is the census model's neighbour prior; the {model.name} "
                             "model" + (" without it" if model.census else "") + " has no feedback table")
    if model.lr and "max_cycles" not in kwargs:
        counter_max = MachineParams.for_disparity(model.dmax, **kwargs).counter_max  # type: ignore[arg-type]
        kwargs["max_cycles"] = LR_WATCHDOG_RUNS * (counter_max + 1)
    machine = MachineParams.for_disparity(model.dmax, **kwargs)  # type: ignore[arg-type]
    check_disparity_machine(model, machine)
    return machine


def right_machine(model: ModelParams, machine: MachineParams) -> MachineParams:
    """The right pass's machine of a census-lr model whose left pass runs on ``machine``.

    The census model's machine (:func:`disparity_machine` of :attr:`ModelParams.right_model`: 4 data
    columns and its neighbour prior) with ``machine``'s word width, counter max, random source,
    watchdog (``model.lr_right_max_cycles`` if given: a right pixel stopped by it has no right MAP)
    and tie rule, and the seed of lane 1 of a row of machines
    (:func:`~bayesmachine.params.nth_machine`): a second machine beside the left one, with its own
    random numbers.
    """
    if not model.lr:
        raise ValueError(f"the {model.name} model has no right pass")
    check_disparity_machine(model, machine)
    keep = ("word_bits", "counter_max", "rng", "lfsr_bits", "seed", "max_cycles", "tie_break")
    kwargs = {k: getattr(machine, k) for k in keep}
    if model.lr_right_max_cycles is not None:
        kwargs["max_cycles"] = model.lr_right_max_cycles
    if machine.rng == "smtj":
        kwargs.update(smtj_dwell=machine.smtj_dwell, smtj_spread=machine.smtj_spread,
                      smtj_share=machine.smtj_share)
    return nth_machine(disparity_machine(model.right_model, **kwargs), 1)


def feedback_table(model: ModelParams, word_bits: int) -> tuple[tuple[int, ...], int]:
    """The neighbour prior's feedback table on ``word_bits``-bit words: (``feedback_words``,
    ``feedback_nomatch_word``) = (quantized prior clamped at ``prior_last``, quantized no-match factor)."""
    if not model.has_prior:
        raise ValueError(f"the {model.name} model has no neighbour prior")
    q = QuantizedTables(likelihood_tables(model), word_bits)
    assert q.prior is not None and q.prior_last is not None and q.prior_nomatch is not None
    return tuple(int(v) for v in q.prior[: q.prior_last + 1]), int(q.prior_nomatch)


def check_disparity_machine(model: ModelParams, machine: MachineParams) -> int:
    """``ParameterError`` naming the parameter unless ``machine`` can run ``model``'s disparity pixels.

    Returns the operator column of the first data column: 1 with a loaded prior (column 0), 2 with
    the neighbour prior (feedback column 0, loaded above column 1), else 0. The neighbour prior needs
    the machine :func:`disparity_machine` builds (its feedback table is the model's); a neighbour
    machine with a model without the prior is refused too.
    """
    if machine.rows != model.hypotheses or not machine.nomatch_row:
        raise ParameterError(
            f"rows: the machine has {machine.rows} rows (no-match row: {machine.nomatch_row}); the model's "
            f"dmax {model.dmax} needs {model.hypotheses} = dmax + 2 with a no-match row: "
            f"use MachineParams.for_disparity({model.dmax}, columns={model.columns})"
        )
    if machine.columns != model.columns:
        raise ParameterError(
            f"columns: the {model.name} model has {model.columns} data terms, the machine has "
            f"columns={machine.columns}")
    w = machine.word_bits
    if quantize(model.p_nm0, w) == 0:
        # Then an occluded pixel (every row ~0) could only stop at the watchdog, max_cycles later.
        raise ParameterError(
            f"p_nm0: {model.p_nm0} quantizes to 0 with {w}-bit words, so a pixel with no match could "
            f"not stop before the watchdog; raise --word-bits or --p-nm0 (p_nm0 >= 2^-{w + 1})"
        )
    if model.census:
        l_nm = likelihood_formula(np.int64(model.h_nm), 1, model.census_p0, model.sigma_c)
        if quantize(l_nm, w) == 0:
            raise _error("census_nomatch_h", f"= {model.h_nm}: the no-match row's census likelihood "
                         f"{float(l_nm):.3g} quantizes to 0 with {w}-bit words (no match could never win)")
    if model.lr:
        c = model.lr_right_max_cycles
        if c is not None and c <= machine.counter_max:
            raise _error("lr_right_max_cycles", f"= {c} must exceed the counter max ({machine.counter_max}): "
                         "no counter can overflow in fewer than counter max + 1 cycles")
        for name in ("lr_beta", "lr_gamma"):
            if int(quantize(getattr(model, name), w)) == 0:
                raise _error(name, f"= {getattr(model, name):.3g} quantizes to 0 with {w}-bit words "
                             "(raise it or --word-bits)")
    if model.has_prior:
        if machine.prior != "neighbour":
            raise _error("neighbour_prior", f"needs the machine's neighbour prior (prior='neighbour': its "
                         f"feedback column and a loaded above column), not prior={machine.prior!r}: build "
                         "the machine with disparity_machine(model), or turn the neighbour prior off")
        if int(quantize(model.prior_nm, w)) == 0:
            raise _error("prior_nomatch", f"= {model.prior_nm:.3g} quantizes to 0 with {w}-bit words "
                         "(the no-match row could never win next to a matched neighbour)")
        feedback, nm = feedback_table(model, w)
        if machine.feedback_words != feedback or machine.feedback_nomatch_word != nm:
            raise _error("neighbour_prior", f"the machine's feedback table {machine.feedback_words} / "
                         f"{machine.feedback_nomatch_word} is not the model's {w}-bit prior table "
                         f"{feedback} / {nm}: build the machine with disparity_machine(model)")
    elif machine.prior == "neighbour":
        raise ParameterError(
            f"prior: the machine has a neighbour prior (prior='neighbour') but the {model.name} model "
            + ("has it turned off" if model.census else "has none (the census model has one)"))
    return machine.operator_columns - machine.columns
