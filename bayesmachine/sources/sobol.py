"""The ``sobol`` source: one randomized W-bit Sobol generator per operator column (no Amaranth).

Sobol points come from the Gray-code construction of Antonov and Saleev: point j + 1 is point j
XOR the direction number of the lowest 0 bit of j, so each generator is a W-bit register and
an XOR per cycle, and all columns share one index counter. Column c is Sobol dimension c + 1
(the first is the van der Corput sequence); the direction numbers of dimensions 2 ... 16 are
those of S. Joe and F. Y. Kuo, "Constructing Sobol sequences with better two-dimensional
projections", SIAM J. Sci. Comput. 30 (2008) 2635-2654, file ``new-joe-kuo-6.21201``
(https://web.maths.unsw.edu.au/~fkuo/sobol/), the table SciPy's ``scipy.stats.qmc.Sobol``
uses too (``tests/sources/test_sobol.py`` checks the points against it).

Exact per-cycle rule (``docs/architecture.md``, "Random source"): a pixel's compute cycles
fall in blocks of 2**W; the j-th cycle of a block (j = 0 ... 2**W - 1) gives column c the number
``x_c[j] XOR s_c`` where ``x_c[j]`` is the unrandomized Sobol point and ``s_c`` is a random
digital shift for the block: the next W-bit number of the column's leap-forward LFSR
(:func:`~bayesmachine.sources.lfsr.column_lfsr_specs`), which advances once per block, on the
block's first compute cycle. Every pixel starts a new block. The shift keeps each number
uniform (the machine stays unbiased, and identical pixels get independent results) while
keeping the net structure of every block: within a block the numbers of a column are a
permutation-like stratification of [0, 2**W), and columns 0 and 1 form a (0, m, 2)-net.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from bayesmachine.errors import ParameterError

from .lfsr import LFSRSpec, column_lfsr_specs, lfsr_step

if TYPE_CHECKING:
    from bayesmachine.params import MachineParams

__all__ = [
    "JOE_KUO",
    "MAX_DIMENSIONS",
    "SobolTwin",
    "clock_directions",
    "direction_numbers",
    "sample_points",
    "sobol_points",
]

# (s, a, m_1 ... m_s) of dimensions 2 ... 16 of new-joe-kuo-6.21201: the primitive polynomial
# x^s + a_1 x^(s-1) + ... + a_(s-1) x + 1 (a's bits, a_1 first) and the initial direction numbers.
JOE_KUO: tuple[tuple[int, int, tuple[int, ...]], ...] = (
    (1, 0, (1,)),
    (2, 1, (1, 3)),
    (3, 1, (1, 3, 1)),
    (3, 2, (1, 1, 1)),
    (4, 1, (1, 1, 3, 3)),
    (4, 4, (1, 3, 5, 13)),
    (5, 2, (1, 1, 5, 5, 17)),
    (5, 4, (1, 1, 5, 5, 5)),
    (5, 7, (1, 1, 7, 11, 19)),
    (5, 11, (1, 1, 5, 1, 1)),
    (5, 13, (1, 1, 1, 3, 11)),
    (5, 14, (1, 3, 5, 5, 31)),
    (6, 1, (1, 3, 3, 9, 7, 49)),
    (6, 13, (1, 1, 1, 15, 21, 21)),
    (6, 16, (1, 3, 1, 13, 27, 49)),
)

MAX_DIMENSIONS = 1 + len(JOE_KUO)  # van der Corput, then the table


def _m_values(dimension: int, count: int) -> list[int]:
    """m_1 ... m_count of a dimension (0-based: 0 is van der Corput, m_k = 1)."""
    if dimension == 0:
        return [1] * count
    s, a, init = JOE_KUO[dimension - 1]
    m = list(init[:count])
    for k in range(s, count):  # Bratley-Fox recurrence (0-based k: m[k] from m[k-s] ... m[k-1])
        v = m[k - s] ^ (m[k - s] << s)
        for i in range(1, s):
            if (a >> (s - 1 - i)) & 1:
                v ^= m[k - i] << i
        m.append(v)
    return m


def direction_numbers(dimension: int, bits: int) -> tuple[int, ...]:
    """V_0 ... V_(bits-1) of a dimension as ``bits``-bit integers: V_k = m_(k+1) * 2**(bits-1-k).

    Point j + 1 = point j XOR V_(lowest 0 bit of j).
    """
    if not 0 <= dimension < MAX_DIMENSIONS:
        raise ParameterError(
            f"Sobol dimension {dimension} is outside the embedded table (0 ... {MAX_DIMENSIONS - 1})"
        )
    return tuple(m << (bits - 1 - k) for k, m in enumerate(_m_values(dimension, bits)))


def _lowest_zero_bit(j: int) -> int:
    return ((~j) & (j + 1)).bit_length() - 1


def sobol_points(dimension: int, bits: int, count: int | None = None) -> list[int]:
    """The first ``count`` (default 2**bits) unrandomized points of a dimension, Gray-code order."""
    count = (1 << bits) if count is None else count
    if not 0 <= count <= (1 << bits):
        raise ValueError(f"a {bits}-bit Sobol block has {1 << bits} points, asked for {count}")
    v = direction_numbers(dimension, bits)
    x, out = 0, []
    for j in range(count):
        out.append(x)
        if j + 1 < (1 << bits):
            x ^= v[_lowest_zero_bit(j)]
    return out


def sample_points(dimension: int, bits: int, samples: int) -> tuple[int, ...]:
    """The constants a clock's B = ``samples`` points differ from its first one by: point j + i is
    point j XOR ``sample_points[i]`` (the unrandomized point i) whenever j is a multiple of B.

    The Gray code of j + i is that of j XOR that of i (j's low log2(B) bits are 0), and a point is
    the XOR of the direction numbers of its index's Gray-code bits. Point i < B has its bits in the
    top log2(B) bits only, so the B numbers of a clock share their low W - log2(B) bits.
    """
    return tuple(sobol_points(dimension, bits, samples))


def clock_directions(dimension: int, bits: int, samples: int) -> tuple[int, ...]:
    """The per-clock direction numbers of a generator that gives B = ``samples`` points per clock: a
    clock's first point is the previous clock's XOR ``clock_directions[lowest 0 bit of the clock's
    index in its block - 1]`` (the index counting clocks, W - log2(B) bits).

    Point B(i + 1) = point B(i + 1) - 1 XOR V_(lowest 0 bit of B(i + 1) - 1) = point Bi XOR point
    B - 1 XOR V_(log2(B) + lowest 0 bit of i): so D_k = point(B - 1) XOR V_(log2(B) + k). For B = 1,
    D_k = V_k.
    """
    b = samples.bit_length() - 1
    v = direction_numbers(dimension, bits)
    last = sobol_points(dimension, bits, samples)[-1]
    return tuple(last ^ v[b + k] for k in range(bits - b))


class SobolTwin:
    """Per-cycle Python twin of ``hdl.sources.SobolGenerators`` (all operator columns).

    State: the shared block index ``i`` (counting clocks: W - log2(B) bits, B = samples_per_clock),
    ``fresh`` (the next compute cycle starts a block), per column the register ``y`` and the shift
    LFSR. Each cycle, :attr:`numbers` are column c's ``lfsr number if fresh else y`` (the clock's
    first point), :attr:`sample_numbers` the clock's B numbers (the first XOR
    :func:`sample_points`); :meth:`clock` applies one clock edge.
    """

    def __init__(self, params: MachineParams) -> None:
        # A sobol MachineParams has checked its columns against the table (check_params); for
        # any other rng, direction_numbers refuses a column beyond it.
        self.bits = params.word_bits
        self.samples = params.samples_per_clock
        self.columns = params.operator_columns
        self.clocks = (1 << self.bits) // self.samples  # clocks per block
        self.specs: list[LFSRSpec] = column_lfsr_specs(params)
        self.directions = [clock_directions(c, self.bits, self.samples) for c in range(self.columns)]
        self.points = [sample_points(c, self.bits, self.samples) for c in range(self.columns)]
        self.reset()

    def reset(self) -> None:
        self.index = 0
        self.fresh = True
        self.y = [0] * self.columns
        self.lfsr = [s.init for s in self.specs]

    @property
    def numbers(self) -> list[int]:
        if self.fresh:
            return [lfsr_step(s, spec)[0] for s, spec in zip(self.lfsr, self.specs, strict=True)]
        return list(self.y)

    @property
    def sample_numbers(self) -> list[list[int]]:
        """This clock's numbers, sample by sample: ``[sample][column]``."""
        first = self.numbers
        return [[n ^ pts[i] for n, pts in zip(first, self.points, strict=True)] for i in range(self.samples)]

    def clock(self, enable: bool, restart: bool) -> None:
        """One clock edge: ``enable`` = a compute cycle, ``restart`` = a pixel's run starts."""
        if not enable:
            if restart:
                self.index, self.fresh = 0, True
            return
        nums = self.numbers
        if self.fresh:  # the block's shift is consumed: the LFSRs advance, even on a restart
            self.lfsr = [lfsr_step(s, spec)[1] for s, spec in zip(self.lfsr, self.specs, strict=True)]
        last = self.index == self.clocks - 1
        # y after the block's last cycle is never read (a block starts with the shift): keep it.
        k = _lowest_zero_bit(self.index)
        self.y = [n ^ (0 if last else d[k]) for n, d in zip(nums, self.directions, strict=True)]
        if restart or last:
            self.index, self.fresh = 0, True
        else:
            self.index, self.fresh = self.index + 1, False


def check_params(params: MachineParams) -> None:
    """A ``sobol`` machine needs a Sobol dimension per operator column: the one check of it (run by
    ``MachineParams`` through the source registry, ``bayesmachine.sources``)."""
    if params.operator_columns > MAX_DIMENSIONS:
        raise ParameterError(
            f"rng = 'sobol' supports at most {MAX_DIMENSIONS} operator columns (Sobol dimensions "
            f"embedded), this machine has {params.operator_columns}"
        )
    if 2 * params.samples_per_clock > 1 << params.word_bits:
        raise ParameterError(
            f"samples_per_clock {params.samples_per_clock}: rng = 'sobol' needs a block of 2^W = "
            f"{1 << params.word_bits} points to span at least two clocks (samples_per_clock <= 2^(W-1))"
        )
