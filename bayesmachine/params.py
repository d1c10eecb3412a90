"""The one parameter object shared by the RTL, the NumPy machine model and the host.

Every width in the design derives from these numbers; every consumer validates
nothing on its own but takes a :class:`MachineParams`, which checks everything up
front: a wrong type raises TypeError, an impossible value :class:`ParameterError` naming the
offending parameter (its ``parameter``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass

from bayesmachine.checks import as_bool, as_int, as_real, type_name
from bayesmachine.errors import ParameterError
from bayesmachine.integrators import INTEGRATOR_KINDS, KIND_FIELDS, IntegratorKind, integrator_kind
from bayesmachine.integrators.stochastic import (
    DEFAULT_COUNTER_MAX,
    DEFAULT_LFSR_BITS,
    DEFAULT_MAX_CYCLES,
    DEFAULT_RNG,
    DEFAULT_SEED,
    STOCHASTIC_FIELDS,
)
from bayesmachine.sources import SMTJ_SHARES, SOURCE_KINDS, SourceKind, check_source, source_kind

__all__ = [
    "MachineParams",
    "ParameterError",
    "RNG_KINDS",
    "PRIORS",
    "TIE_BREAKS",
    "SMTJ_SHARES",
    "DEFAULT_DMAX",
    "MAX_DMAX",
    "DEFAULT_COLUMNS",
    "DEFAULT_WORD_BITS",
    "DEFAULT_COUNTER_MAX",
    "DEFAULT_RNG",
    "DEFAULT_LFSR_BITS",
    "DEFAULT_SEED",
    "DEFAULT_MAX_CYCLES",
    "DEFAULT_PRIOR",
    "DEFAULT_TIE_BREAK",
    "INTEGRATORS",
    "DEFAULT_INTEGRATOR",
    "STOCHASTIC_FIELDS",
    "SMTJ_DEFAULTS",
    "DEFAULT_WORDS_PER_BEAT",
    "SAMPLES_PER_CLOCK",
    "STEREO_ROWS_PER_BEAT",
    "TIMEOUT_ANSWERS",
    "nth_machine",
    "stereo_words_per_beat",
]

# The random source kinds: the names of the one registry, bayesmachine.sources.SOURCE_KINDS.
RNG_KINDS = tuple(SOURCE_KINDS)
PRIORS = ("uniform", "loaded", "neighbour")
TIE_BREAKS = ("nomatch-first", "lowest-index")
# How a pixel's evidence is integrated: the names of the one registry, bayesmachine.integrators (the
# paper's stochastic machine; the logarithmic one, docs/integrators.md).
INTEGRATORS = tuple(INTEGRATOR_KINDS)
DEFAULT_INTEGRATOR = "stochastic"
# Random samples each operator compares per clock (B): powers of two, so that a Sobol block of 2^W
# points is whole clocks and a clock's points are its first point XOR constants.
SAMPLES_PER_CLOCK = (1, 2, 4, 8, 16)
# What a run stopped by the watchdog answers: "none" (map 0: no answer, read as no match) or "leading"
# (the row with the largest count, by the tie rule).
TIMEOUT_ANSWERS = ("none", "leading")

# Default word width: 10 bits of comparator resolution. The paper's smallest
# probability is p_nm0 = 0.01; at 8 bits it quantizes to 3/256 = 0.0117 (+17 %),
# at 10 bits to 10/1024 = 0.0098 (-2.3 %), and p0 = 0.02 to 20/1024 (-2.3 %).
DEFAULT_WORD_BITS = 10
DEFAULT_WORDS_PER_BEAT = 16
# The on-chip front end (hdl.frontend) writes 6 rows' words per load beat: see stereo_words_per_beat.
STEREO_ROWS_PER_BEAT = 6
# The paper's machine: Dmax 80 (82 rows), three data terms, counter max 16.
DEFAULT_DMAX = 80
MAX_DMAX = 4094  # Dmax + 2 rows at most 4096
DEFAULT_COLUMNS = 3
DEFAULT_PRIOR = "uniform"
DEFAULT_TIE_BREAK = "nomatch-first"
# rng = "smtj"'s device parameters when not given: smtj_dwell, smtj_spread, smtj_share.
SMTJ_DEFAULTS = (1.0, 0.0, "operator")


# Prior columns in the operator matrix per prior kind, and how many of them are loaded.
_PRIOR_COLUMNS = {"uniform": 0, "loaded": 1, "neighbour": 2}
_LOADED_PRIOR_COLUMNS = {"uniform": 0, "loaded": 1, "neighbour": 1}


def _check_int(name: str, value: object, lo: int, hi: int | None = None) -> int:
    """``value`` as an int (NumPy integers too: :func:`~bayesmachine.checks.as_int`) in [lo, hi]."""
    v = as_int(name, value)
    if v < lo or (hi is not None and v > hi):
        bound = f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"
        raise ParameterError(f"{name} must be {bound}, got {v}", name)
    return v


def _check_choice(name: str, value: object, choices: tuple[str, ...]) -> None:
    if not isinstance(value, str):
        raise TypeError(f"{name} must be one of {choices}, not {type_name(value)}")
    if value not in choices:
        raise ParameterError(f"{name} must be one of {choices}, got {value!r}", name)


@dataclass(frozen=True, kw_only=True)
class MachineParams:
    """Parameters of one stochastic Bayesian machine, keyword-only.

    Integer fields take what Python's ``operator.index`` takes (NumPy integer scalars too), yes/no
    fields a bool or a NumPy bool, and hold plain Python values.

    rows
        M, the number of rows of the operator matrix (hypotheses of the searched
        variable). For disparity, ``Dmax + 2``: rows 0..Dmax and the no-match row.
    columns
        N, the number of data-term operator columns (3 for disparity).
    word_bits
        W, the comparator resolution (1..15). A likelihood memory word holds an integer
        q in [0, 2**W] (so it is W+1 bits wide: 1.0 is exact) and encodes p = q / 2**W.
    counter_max
        n_max. A row's overflow counter overflows on the (n_max+1)-th 1.
    rng
        The random source (``bayesmachine.sources.SOURCE_KINDS``; default ``"sobol"``). ``"lfsr"``: one
        maximal-length leap-forward LFSR per operator, inside the design.
        ``"lfsr-shared"``: one LFSR per operator column, shared by all rows. ``"sobol"``:
        one randomized Sobol generator per operator column, shared by all rows.
        ``"external"``: the W-bit random numbers come in on a port (e.g. a TRNG outside the
        module). ``"smtj"``: the same port, driven by the SMTJ device model
        (``bayesmachine.sources.smtj``): W unbiased superparamagnetic tunnel junctions per
        operator (or per column), read once per compute cycle.
    lfsr_bits
        L, the length of each LFSR (period 2**L - 1).
    seed
        The machine seed; every LFSR polynomial and start state derive from it.
    max_cycles
        Watchdog: a pixel whose run reaches this many cycles without an overflow
        stops and is flagged as a timeout.
    prior
        ``"uniform"``: column 0 of the stochastic bus is always-on 1s.
        ``"loaded"``: an extra operator column 0 holds a loaded prior word per row.
        ``"neighbour"``: two extra operator columns. Column 0 is the *feedback prior*, formed by the
        machine itself at each pixel's start from its own previous result through
        ``feedback_words`` (the raster-order left neighbour's factor); column 1 is a loaded prior
        word per row (e.g. the above neighbour's factor, which the host or the front end forms
        from the results of the previous line). Each pixel comes with a ``line_start`` flag: its
        feedback prior is flat (every word 1.0) when it starts a line, when the previous result was
        no match or a timeout, and for the first pixel after reset.
    nomatch_row
        The last row is the "no match" hypothesis: the result's no-match flag is
        set when it wins, and ``tie_break`` can favour it.
    tie_break
        When several rows overflow in the same cycle: ``"nomatch-first"`` (the
        no-match row wins any tie it is part of, otherwise the lowest index) or
        ``"lowest-index"``.
    words_per_beat
        Likelihood-memory words carried per beat of the load stream.
    smtj_dwell
        ``rng = "smtj"`` only: tau, the mean dwell time of each SMTJ state, in clock cycles
        (the geometric mean of the two states' mean dwells; see ``docs/smtj.md``).
    smtj_spread
        ``rng = "smtj"`` only: per-device variability, the log-sd of the lognormal factor that
        scatters each device's two mean dwell times (0: identical devices; 0.05: about 5 %).
    smtj_share
        ``rng = "smtj"`` only: ``"operator"`` (W devices per operator) or ``"column"`` (W
        devices per operator column, their number shared by all rows).
    samples_per_clock
        B, one of ``SAMPLES_PER_CLOCK``: each operator compares its word with the next B random
        numbers of its source per clock, each counter adds up to B, and a run stops at the sample
        of its first overflow (or at sample ``max_cycles``, the watchdog, which counts samples). The
        results are B = 1's; the ``cycles`` field counts clocks, ceil(samples / B). The random
        source decides whether it has B numbers per clock (``bayesmachine.sources``: ``sobol`` and
        ``external``).
    timeout_answer
        What a run stopped by the watchdog answers (still flagged ``timeout``): ``"none"`` (map 0,
        read as no match) or ``"leading"`` (the row with the largest count, the tie rule among equal
        counts; the no-match row's answer is no match).
    integrator
        One of ``INTEGRATORS``: ``"stochastic"`` (the paper's machine, the default) or ``"log"``: the
        logarithmic integrator (``docs/integrators.md``): every row's energy codes
        (``bayesmachine.columns.energy.log_codes``) summed, the MAP the row of the lowest sum by
        ``tie_break``, each row's weight ``exp_table(word_bits)`` at its sum's distance from the least
        (the readout where the stochastic machine has its counts, up to :attr:`readout_max`); what is
        loaded are codes, not words, and the feedback table (``feedback_words``,
        ``feedback_nomatch_word``) holds the left prior's codes. The random source, the counter max and
        the watchdog have no part in it.
    normalize
        Per-pixel column normalization: while a pixel's words are loaded the machine keeps each loaded
        column's largest word m (0 .. 2^W); the column's operators compare their words w with
        ``(r * m) >> W`` instead of the random number r (``word_bits`` W), so w fires when
        w * 2^W > r * m: exactly the run on the real words w * 2^W / m (each column rescaled so its
        largest word is 2^W; a column of zeros, m = 0, never fires, as without it). The posterior is
        unchanged, the runs shorter. A neighbour prior's feedback column is formed, not loaded: not
        scaled.

    The ``smtj_*`` fields belong to ``rng = "smtj"`` (None: the defaults 1.0, 0.0, "operator"); another
    kind refuses them and leaves them None, out of its ``to_dict`` (and fingerprint); the ``feedback_*``
    fields belong to the neighbour prior the same way.
    """

    rows: int
    columns: int = DEFAULT_COLUMNS
    word_bits: int = DEFAULT_WORD_BITS
    counter_max: int | None = None
    rng: str | None = None
    lfsr_bits: int | None = None
    seed: int | None = None
    max_cycles: int | None = None
    prior: str = DEFAULT_PRIOR
    nomatch_row: bool = False
    tie_break: str = DEFAULT_TIE_BREAK
    words_per_beat: int = DEFAULT_WORDS_PER_BEAT
    smtj_dwell: float | None = None
    smtj_spread: float | None = None
    smtj_share: str | None = None
    feedback_words: tuple[int, ...] = ()
    feedback_nomatch_word: int | None = None
    samples_per_clock: int | None = None
    timeout_answer: str | None = None
    normalize: bool | None = None
    integrator: str = DEFAULT_INTEGRATOR

    def _int(self, name: str, lo: int, hi: int | None = None) -> None:
        object.__setattr__(self, name, _check_int(name, getattr(self, name), lo, hi))

    def _bool(self, name: str) -> None:
        object.__setattr__(self, name, as_bool(name, getattr(self, name)))

    def __post_init__(self) -> None:
        self._int("rows", 1, 4096)
        self._int("columns", 1, 64)
        # <= 15: every word, up to 2**15 = 1.0, fits the 16-bit words of the host and the engines.
        self._int("word_bits", 1, 15)
        _check_choice("integrator", self.integrator, INTEGRATORS)
        kind = self.kind
        self._kind_fields(kind)
        if kind.draws_numbers:
            self._check_counters()
        _check_choice("prior", self.prior, PRIORS)
        self._check_feedback()
        self._bool("nomatch_row")
        if self.nomatch_row and self.rows < 2:
            raise ParameterError("rows: a machine with a no-match row needs at least 2 rows", "rows")
        _check_choice("tie_break", self.tie_break, TIE_BREAKS)
        self._int("words_per_beat", 1)
        if self.words_per_beat > self.words_per_pixel:
            raise ParameterError(
                f"words_per_beat ({self.words_per_beat}) exceeds the words per pixel "
                f"({self.words_per_pixel})",
                "words_per_beat")
        if kind.draws_numbers:
            self._check_samples()
        kind.check(self)

    def _kind_fields(self, kind: IntegratorKind) -> None:
        """Refuse the fields of another integrator (a ParameterError naming the first given), and fill the
        kind's own with its defaults."""
        given = [f for f in KIND_FIELDS if f not in kind.fields and getattr(self, f) is not None]
        if given:
            owners = [k.name for k in INTEGRATOR_KINDS.values() if given[0] in k.fields]
            raise ParameterError(f"{', '.join(given)}: the {' or '.join(owners)} integrator's, not read with "
                                 f"integrator {self.integrator!r}: leave {'them' if given[1:] else 'it'} out",
                                 given[0])
        for name, default in kind.defaults.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, default)

    def _check_counters(self) -> None:
        """The counters, the random source's kind, the LFSRs and the watchdog of a machine that draws
        random numbers."""
        self._int("counter_max", 1, (1 << 24) - 1)
        if not isinstance(self.rng, str):
            raise TypeError(f"rng must be a random source's name (str), not {type_name(self.rng)}")
        source_kind(self.rng)  # a known kind; what the kind needs is checked last (check_source)
        self._int("lfsr_bits", 3, 63)
        if self.lfsr_bits < self.word_bits + 2:
            raise ParameterError(
                f"lfsr_bits ({self.lfsr_bits}) must be at least word_bits + 2 "
                f"({self.word_bits + 2}): each LFSR delivers word_bits fresh bits per cycle", "lfsr_bits")
        self._int("seed", 0, (1 << 64) - 1)
        self._int("max_cycles", 1, (1 << 32) - 1)
        if self.max_cycles <= self.counter_max:
            raise ParameterError(
                f"max_cycles ({self.max_cycles}) must exceed counter_max ({self.counter_max}): "
                f"no counter can overflow in fewer than counter_max + 1 cycles", "max_cycles")

    def _check_samples(self) -> None:
        """The SMTJ devices, the samples per clock, the timeout's answer and the normalization of a machine
        that draws random numbers; last, what only its random source knows."""
        self._check_smtj()
        self._int("samples_per_clock", 1)
        if self.samples_per_clock not in SAMPLES_PER_CLOCK:
            raise ParameterError(f"samples_per_clock must be one of {SAMPLES_PER_CLOCK}, "
                                 f"got {self.samples_per_clock}", "samples_per_clock")
        if self.max_cycles <= self.samples_per_clock:
            raise ParameterError(f"max_cycles ({self.max_cycles}) must exceed samples_per_clock "
                                 f"({self.samples_per_clock}): a run has at least two clocks", "max_cycles")
        _check_choice("timeout_answer", self.timeout_answer, TIMEOUT_ANSWERS)
        self._bool("normalize")
        # Last, what only the random source knows (the Sobol table's size, the LFSR polynomials):
        # the one place it is checked, so every holder of a MachineParams can build its source.
        check_source(self)

    def _check_smtj(self) -> None:
        fields = ("smtj_dwell", "smtj_spread", "smtj_share")
        if self.rng != "smtj":
            given = [f for f in fields if getattr(self, f) is not None]
            if given:
                raise ParameterError(f"{', '.join(given)}: device parameters of rng 'smtj', not of "
                                     f"{self.rng!r}", given[0])
            return
        for name, default in zip(fields, SMTJ_DEFAULTS, strict=True):
            if getattr(self, name) is None:
                object.__setattr__(self, name, default)
        for name in ("smtj_dwell", "smtj_spread"):
            # A float: 20 and 20.0 are one machine, one fingerprint.
            object.__setattr__(self, name, as_real(name, getattr(self, name)))
        if not 0 < self.smtj_dwell <= 1e12:  # type: ignore[operator]
            raise ParameterError(f"smtj_dwell (clock cycles) must be in (0, 1e12], got {self.smtj_dwell}",
                                 "smtj_dwell")
        if not 0 <= self.smtj_spread <= 1:  # type: ignore[operator]
            raise ParameterError(f"smtj_spread (log-sd) must be in [0, 1], got {self.smtj_spread}",
                                 "smtj_spread")
        _check_choice("smtj_share", self.smtj_share, SMTJ_SHARES)

    def _check_feedback(self) -> None:
        words = self.feedback_words
        if isinstance(words, list):
            words = tuple(words)
            object.__setattr__(self, "feedback_words", words)  # a list and a tuple: one machine
        if not isinstance(words, tuple):
            raise TypeError(f"feedback_words must be a tuple of words, not {words!r}")
        if self.prior != "neighbour":
            if words or self.feedback_nomatch_word is not None:
                raise ParameterError("feedback_words and feedback_nomatch_word belong to prior = "
                                     f"'neighbour', not {self.prior!r}", "feedback_words")
            return
        if not 1 <= len(words) <= self.rows:
            raise ParameterError(f"prior = 'neighbour' needs 1 to rows ({self.rows}) feedback_words, "
                                 f"got {len(words)}", "feedback_words")
        one = self.load_max
        object.__setattr__(self, "feedback_words",
                           tuple(_check_int(f"feedback_words[{i}]", w, 0, one) for i, w in enumerate(words)))
        if self.nomatch_row:
            if self.feedback_nomatch_word is None:
                raise ParameterError("prior = 'neighbour' with a no-match row needs feedback_nomatch_word",
                                     "feedback_nomatch_word")
            self._int("feedback_nomatch_word", 0, self.load_max)
        elif self.feedback_nomatch_word is not None:
            raise ParameterError("feedback_nomatch_word needs a no-match row (nomatch_row=True)",
                                 "feedback_nomatch_word")

    @classmethod
    def for_disparity(cls, dmax: int = DEFAULT_DMAX, **kwargs: object) -> MachineParams:
        """The disparity machine of the paper: M = Dmax + 2 rows, the last one no-match."""
        dmax = _check_int("dmax", dmax, 0, MAX_DMAX)
        kwargs.setdefault("columns", DEFAULT_COLUMNS)
        if "words_per_beat" not in kwargs:
            # Small machines get a load stream no wider than one pixel's words.
            prior = kwargs.get("prior")
            columns = _check_int("columns", kwargs["columns"], 1, 64) + (
                _LOADED_PRIOR_COLUMNS.get(prior, 0) if isinstance(prior, str) else 0)
            kwargs["words_per_beat"] = min(DEFAULT_WORDS_PER_BEAT, (dmax + 2) * columns)
        return cls(rows=dmax + 2, nomatch_row=True, **kwargs)  # type: ignore[arg-type]

    # Derived quantities: every width in the RTL, the model and the host comes from here.
    @property
    def operator_columns(self) -> int:
        """Operator columns in the matrix: the data terms, plus the prior columns (one loaded prior
        column; the feedback and the loaded prior column of a neighbour prior)."""
        return self.columns + _PRIOR_COLUMNS[self.prior]

    @property
    def feedback_columns(self) -> int:
        """Operator columns the machine forms itself (1: column 0 of a neighbour prior), not loaded."""
        return 1 if self.prior == "neighbour" else 0

    @property
    def loaded_columns(self) -> int:
        """Operator columns whose words are loaded: all but the feedback column."""
        return self.operator_columns - self.feedback_columns

    @property
    def operators(self) -> int:
        return self.rows * self.operator_columns

    @property
    def words_per_pixel(self) -> int:
        """Words loaded per pixel: every row's loaded columns."""
        return self.rows * self.loaded_columns

    @property
    def beats_per_pixel(self) -> int:
        return -(-self.words_per_pixel // self.words_per_beat)

    @property
    def word_one(self) -> int:
        """The memory word that encodes probability 1.0 (2**W)."""
        return 1 << self.word_bits

    @property
    def kind(self) -> IntegratorKind:
        """The integrator's kind (``bayesmachine.integrators``): what it loads and reads out, its fields,
        its machine, engines and cycle formulas."""
        return integrator_kind(self.integrator)

    @property
    def source(self) -> SourceKind | None:
        """The random source's kind (``bayesmachine.sources``); None for a machine that draws no random
        numbers."""
        return source_kind(self.rng) if self.kind.draws_numbers else None

    @property
    def takes_numbers(self) -> bool:
        """Whether random numbers come in from outside (an off-chip source, on the ``entropy`` port)."""
        source = self.source
        return source is not None and not source.on_chip

    @property
    def load_max(self) -> int:
        """The largest value a loaded entry takes: the word 2^W (stochastic) or the infinite energy code
        (log: ``bayesmachine.columns.energy.INFINITE_CODE``)."""
        return self.kind.load_max(self)

    @property
    def readout_max(self) -> int:
        """The largest value of a row in the distribution read out: the counter max (stochastic), the
        weight of the MAP's row, 2^W (log)."""
        return self.kind.readout_max(self)

    @property
    def memory_word_width(self) -> int:
        """Stored likelihood-memory word width, W + 1 bits (0 ... 2**W)."""
        return self.word_bits + 1

    @property
    def counter_width(self) -> int:
        return self.counter_max.bit_length()

    @property
    def cycle_width(self) -> int:
        """The ``cycles`` field's width: it counts clocks, at most :attr:`max_clocks`."""
        return self.max_clocks.bit_length()

    @property
    def map_width(self) -> int:
        return max(1, (self.rows - 1).bit_length())

    @property
    def max_clocks(self) -> int:
        """The largest ``cycles`` of a result, in clocks: the watchdog's, ceil(max_cycles /
        samples_per_clock) (stochastic), or the loop's clocks (log)."""
        return self.kind.max_clocks(self)

    @property
    def nomatch_index(self) -> int | None:
        return self.rows - 1 if self.nomatch_row else None

    def to_dict(self, complete: bool = False) -> dict[str, object]:
        """The fields this machine uses (the ``smtj_*`` ones with rng ``smtj``, the ``feedback_*`` ones with
        the neighbour prior). Without ``complete``, ``samples_per_clock``, ``timeout_answer``, ``normalize``
        and ``integrator`` are left out at the values every machine had before they existed (1, 'none', off,
        'stochastic'),
        so that fingerprints stay; ``complete``: every resolved value, what a report records (a census
        model's machine with normalize off says so, rather than reading as the model's default, on)."""
        d = asdict(self)
        for name in KIND_FIELDS:  # another integrator's fields: None, and nothing to this machine
            if name not in self.kind.fields:
                del d[name]
        if self.rng != "smtj":  # device parameters mean nothing to the other sources
            for name in ("smtj_dwell", "smtj_spread", "smtj_share"):
                d.pop(name, None)
        if self.prior != "neighbour":  # nor the feedback table to the other priors
            del d["feedback_words"], d["feedback_nomatch_word"]
        else:
            d["feedback_words"] = list(self.feedback_words)
        if complete:
            return d
        # Fields at the value every machine had before them: left out, so fingerprints stay.
        for name, before in (("samples_per_clock", 1), ("timeout_answer", "none"), ("normalize", False),
                             ("integrator", DEFAULT_INTEGRATOR)):
            if name in d and d[name] == before:
                del d[name]
        return d

    def fingerprint(self) -> str:
        """A short stable hash of the parameters (build caches key on it)."""
        blob = json.dumps(self.to_dict(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


def nth_machine(params: MachineParams, index: int) -> MachineParams:
    """The parameters of machine ``index`` of K machines side by side (``hdl.machines.ParallelMachines``,
    the StereoMachine's ``machines``, census-lr's right pass).

    Machine 0 is ``params`` itself; machine i is the kind's (``IntegratorKind.nth_machine``): a
    stochastic machine i has seed ``(seed + i * 0x9E3779B97F4A7C15) mod 2**64``, so every machine draws
    its own LFSR polynomials and start states; a log machine has no seed, every machine is ``params``.
    """
    index = _check_int("index", index, 0)
    return params.kind.nth_machine(params, index) if index else params


def stereo_words_per_beat(params: MachineParams) -> int:
    """The on-chip front end's default lane count (``hdl.frontend``, ``--top stereo``, ``--feed
    pixels``): the words of :data:`STEREO_ROWS_PER_BEAT` rows per beat, a multiple of the loaded
    columns since the front end writes one feature per lane (18 words: 14 beats per pixel at Dmax 80,
    below the 17 cycles of the shortest run at counter max 16; 30 for the census model's neighbour
    machine, whose feedback column is formed on chip, not loaded)."""
    return min(STEREO_ROWS_PER_BEAT, params.rows) * params.loaded_columns
