"""The stochastic operators: comparators against random numbers, ANDed along each row's bus.

Operator (r, c) turns its likelihood-memory word q (a probability q / 2**W) into a
stochastic bitstream by comparing a W-bit random number with q each cycle (``number < q``
is 1 with probability exactly q / 2**W for uniform numbers; q = 0 is never 1 and q = 2**W
always is), and multiplies it into the stochastic bus signal of its row by an AND gate.
:func:`operator_rows` builds the whole M x N matrix: the machine builds it from the same two
functions on its registers (``matrix.py``), and :class:`OperatorMatrix`, the component
``tests/hdl/machine/test_operator.py`` holds to :func:`operator_matrix_twin`, wraps that same function.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from amaranth.hdl import Array, Cat, Const, Module, Value, ValueCastable, unsigned
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.params import ParameterError

__all__ = [
    "OperatorMatrix",
    "bus_rows",
    "operator_bits",
    "operator_matrix_twin",
    "operator_rows",
    "sample_bits",
    "sample_bits_twin",
    "sample_low",
    "scaled_numbers",
    "scaled_numbers_twin",
    "stochastic_operator",
    "stochastic_operator_twin",
]


def stochastic_operator(bus_in: Value | ValueCastable | int, number: Value, word: Value) -> Value:
    """One operator's output bit: ``bus_in & (number < word)``.

    ``number`` is W bits, ``word`` W + 1 bits, so the comparator covers p = 0 and p = 1 exactly.
    """
    # Amaranth compares unsigned values of different widths by zero-extension: exact.
    return Value.cast(bus_in) & (number < word)


def stochastic_operator_twin(bus_in: int, number: int, word: int) -> int:
    """Python twin of :func:`stochastic_operator`."""
    return int(bool(bus_in) and number < word)


def _check_sources(rows: int, columns: int, sources: Sequence[int]) -> tuple[int, ...]:
    sources = tuple(int(s) for s in sources)
    if len(sources) != rows * columns:
        raise ParameterError(f"sources must name one random number per operator ({rows * columns}), "
                             f"got {len(sources)}")
    if min(sources) < 0:
        raise ParameterError("sources must be indices of the random numbers (>= 0)")
    return sources


class OperatorMatrix(wiring.Component):
    """:func:`operator_rows` as a component: the stochastic bus of every row of the matrix.

    Parameters
    ----------
    rows, columns : int
        M and N, the matrix's rows and (operator) columns.
    word_bits : int
        W, the bits of a random number (likelihood-memory words have W + 1).
    sources : sequence of int
        Per operator, the number it reads: ``o`` for one number per operator, ``o % N`` for
        numbers shared by a column's rows.

    Attributes
    ----------
    words : ``In(unsigned(W + 1)).array(M * N)``
        The likelihood-memory words, operator order ``o = r * N + c``.
    numbers : ``In(unsigned(W)).array(max(sources) + 1)``
        The random source's numbers.
    row : ``Out(M)``
        ``row[r] = AND_c (numbers[sources[o]] < words[o])``, a uniform prior being the always-on
        1 the bus starts from.
    """

    def __init__(self, *, rows: int, columns: int, word_bits: int, sources: Sequence[int]) -> None:
        rows, columns, word_bits = (as_int(name, v, 1) for name, v in (("rows", rows), ("columns", columns),
                                                                         ("word_bits", word_bits)))
        if isinstance(sources, (str, bytes)) or not isinstance(sources, Sequence):
            raise TypeError(f"sources must be a sequence of integers, not {type(sources).__name__}")
        self._rows, self._columns, self._word_bits = rows, columns, word_bits
        self._sources = _check_sources(rows, columns, sources)
        super().__init__({
            "words": In(unsigned(word_bits + 1)).array(rows * columns),
            "numbers": In(unsigned(word_bits)).array(max(self._sources) + 1),
            "row": Out(rows),
        })

    @property
    def rows(self) -> int:
        return self._rows

    @property
    def columns(self) -> int:
        return self._columns

    @property
    def word_bits(self) -> int:
        return self._word_bits

    @property
    def sources(self) -> tuple[int, ...]:
        return self._sources

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.d.comb += self.row.eq(operator_rows(self.numbers, self.words, self._rows, self._columns,
                                              self._sources))
        return m


def operator_bits(numbers: Sequence[Value], words: Sequence[Value], sources: Sequence[int]) -> list[Value]:
    """Every operator's comparator bit ``numbers[sources[o]] < words[o]``, in operator order."""
    return [stochastic_operator(1, numbers[s], word) for s, word in zip(sources, words, strict=True)]


def _top_bits(points: Sequence[int], w: int) -> int:
    """The top bits the ``points`` (W-bit constants) use: every point is 0 below them."""
    return max((w - ((p & -p).bit_length() - 1) for p in points if p), default=0)


def sample_low(number: Value, word: Value, points: Sequence[int]) -> Value:
    """The comparator of the low bits the ``points`` leave alone, which :func:`sample_bits` shares
    between them (0 when the points leave none)."""
    w = len(number)
    m = _top_bits(points, w)
    return number[: w - m] < word[: w - m] if w > m else Const(0, 1)


def sample_bits(number: Value, word: Value, points: Sequence[int], low: Value | None = None) -> Value:
    """``Cat((number ^ points[i]) < word for i)`` for a W-bit number and a (W+1)-bit word, from one
    comparator of the low bits the points leave alone and one small compare of the top bits per point.

    A clock's Sobol numbers are its first XOR the points 0 ... B - 1 (their Gray-code bits), which
    use the top log2(B) bits only (``sources.sobol.sample_points``); a block's first two clocks' use
    log2(B) + 1 (the machine without a bubble compares both in a swap). So B operator bits cost one
    (W - log2 B)-bit comparator and B compares of log2(B) + 1 bits. ``low``: :func:`sample_low`'s
    comparator as a net of the caller's (Amaranth builds a value again wherever it is read)."""
    w = len(number)
    m = _top_bits(points, w)
    if m == 0:
        return Cat(*(number < word for _ in points))
    low = sample_low(number, word, points) if low is None else low
    high = word[w - m:]  # the word's top bits: up to 2^m (a word is at most 2^W)
    top = number[w - m:]
    out = []
    for p in points:
        t = top ^ (p >> (w - m))
        out.append((t < high) | ((t == high) & low))
    return Cat(*out)


def sample_bits_twin(number: int, word: int, points: Sequence[int]) -> list[int]:
    """Python twin of :func:`sample_bits`."""
    return [int((number ^ p) < word) for p in points]


def scaled_numbers(number: Value, scale: Value, points: Sequence[int],
                   net: Callable[[str, Value], Value] | None = None) -> list[Value]:
    """``[((number ^ p) * scale) >> W for p in points]`` for a W-bit number and a scale up to 2^W (a
    normalized column's numbers: docs/architecture.md), from one product of the low bits the points
    leave alone and one adder per value of the top bits they use.

    With t such top bits, (number ^ p) * scale = k * scale * 2^(W - t) + low * scale, k the top bits
    XOR p's: the value is (k * scale + (low * scale >> (W - t))) >> t. A clock's B Sobol points (or a
    block's first 2B) take every k below 2^t once, so the 2^t sums are formed once (the multiples
    k * scale by shifts and one adder each) and each point picks its own by the number's top bits.
    ``net(name, value)``: the value as a net of the caller's module, for values read in several
    places (Amaranth builds an expression again wherever it is read)."""
    net = net or (lambda name, value: value)
    w = len(number)
    t = _top_bits(points, w)
    product = net("product", number[: w - t] * scale)
    if t == 0:
        return [product[w: 2 * w] for _ in points]
    part = product[w - t:]
    multiples: list[Value] = [Const(0, 1), scale]
    for k in range(2, 1 << t):
        value = Cat(Const(0, 1), multiples[k // 2]) if k % 2 == 0 else multiples[k - 1] + scale
        multiples.append(net(f"multiple{k}", value))
    sums = Array(net(f"sum{k}", (x + part)[t: t + w]) for k, x in enumerate(multiples))
    top = number[w - t:]
    return [sums[top ^ (p >> (w - t))] for p in points]


def scaled_numbers_twin(number: int, scale: int, points: Sequence[int], w: int) -> list[int]:
    """Python twin of :func:`scaled_numbers`."""
    return [((number ^ p) * scale) >> w for p in points]


def bus_rows(bits: Sequence[Value], rows: int, columns: int, samples: int = 1) -> Value:
    """The stochastic bus from the comparator bits: row r's ``samples`` bits (from bit ``r * samples``)
    are the AND of row r's operator bits (``samples`` bits each, sample i at bit i)."""
    out = []
    for r in range(rows):
        # uniform prior: always-on 1s (a loaded prior is operator column 0)
        bus: Value = Const((1 << samples) - 1, samples)
        for c in range(columns):
            bus = bus & bits[r * columns + c]
        out.append(bus)
    return Cat(*out)


def operator_rows(numbers: Sequence[Value], words: Sequence[Value], rows: int, columns: int,
                  sources: Sequence[int]) -> Value:
    """The matrix's logic: the M row bits of the stochastic bus (bit r = row r).

    ``bus_rows(operator_bits(...))``. The machine builds its matrix from these two functions on
    its own likelihood-memory registers and source outputs (a submodule's port copies of every word
    and number would slow Amaranth's simulator; with an on-chip source it registers the comparator
    bits between them, ``matrix.py``), and :class:`OperatorMatrix` wraps this function for
    ``tests/hdl/machine/test_operator.py``.
    """
    return bus_rows(operator_bits(numbers, words, sources), rows, columns)


def operator_matrix_twin(words: Sequence[int], numbers: Sequence[int], rows: int, columns: int,
                         sources: Sequence[int]) -> list[int]:
    """Python twin of :class:`OperatorMatrix`: the row bits of one cycle."""
    out = []
    for r in range(rows):
        bus = 1
        for c in range(columns):
            o = r * columns + c
            bus = stochastic_operator_twin(bus, numbers[sources[o]], words[o])
        out.append(bus)
    return out
