"""The word generator's table look-ups, the pieces its pipeline (:class:`~.wordpipe.WordPipeline`) builds
them from: a table's depth in hardware (padded to a power of two, so that the clamp of its address is an
OR of high bits) and the clamped absolute value of a lane's cost that addresses it; and a complete
multiplexer over a list (:func:`pick`).
"""

from __future__ import annotations

from amaranth.hdl import Mux, Value

__all__ = ["BLOCK_TABLE_DEPTH", "COST_BITS", "TABLE_READ_PORTS", "clamped_magnitude", "pick", "table_depth"]

# Tables deeper than this go to block RAM (a DP16KD holds 1024 words of up to 18 bits, or 2048 of 9);
# shallower ones (a census distance's, the prior's) stay logic.
BLOCK_TABLE_DEPTH = 128
# Read ports per copy of a table: a block RAM's two. A lookup of more lane rows reads more copies (Yosys's
# memory mapping searches its port assignments per memory: dozens of ports on one exhaust its memory).
TABLE_READ_PORTS = 2
# The widest cost a lane's table address takes (a difference of two 13-bit feature sums).
COST_BITS = 14
# A block RAM's (DP16KD's) shapes, (depth, width): a table takes the fewest blocks of any one of them.
BLOCK_SHAPES = ((16384, 1), (8192, 2), (4096, 4), (2048, 9), (1024, 18))


def _blocks(depth: int, width: int) -> int:
    """The block RAMs a table of ``depth`` words of ``width`` bits takes."""
    return min(-(-depth // d) * -(-width // w) for d, w in BLOCK_SHAPES)


def table_depth(entries: int, width: int) -> int:
    """The hardware depth of a table of ``entries`` words of ``width`` bits: the next power of two (the
    table padded with its last word, so the clamp of its address is an OR of high bits:
    :func:`clamped_magnitude`) unless that takes more block RAMs (a table in logic is padded while it
    stays in logic)."""
    padded = 1 << max(0, entries - 1).bit_length()
    if entries <= BLOCK_TABLE_DEPTH:
        return padded if padded <= BLOCK_TABLE_DEPTH else entries
    return padded if _blocks(padded, width) <= _blocks(entries, width) else entries


def clamped_magnitude(x: Value, last: int) -> Value:
    """min(|x|, ``last``), as ``range(last + 1)``. When ``last`` + 1 is a power of two 2^k the clamp is
    an OR of x's high bits into its k low ones (x <= -2^k for a negative x: not all of its high bits
    set, or none of its low ones), and the absolute value negates only the k low bits; otherwise
    |x| >= ``last`` is two compares on x itself, beside the absolute value."""
    x = Value.cast(x)
    signed_, width = x.shape().signed, x.shape().width
    k = max(1, last.bit_length())
    if (2 ** (width - 1) if signed_ else 2 ** width - 1) <= last:  # never past the last entry
        return abs(x) if signed_ else x
    if (1 << k) != last + 1:
        far = (x >= last) | (x <= -last) if signed_ else x >= last
        return Mux(far, last, abs(x) if signed_ else x)
    low = x[:k]
    if not signed_:
        return low | x[k:].any().replicate(k)
    sign, high = x[-1], x[k:-1]
    far = Mux(sign, ~high.all() | ~low.any(), high.any())
    return Mux(sign, (-low)[:k], low) | far.replicate(k)


def pick(values: list[Value], index: Value) -> Value:
    """``values[index]``, by a chain of multiplexers (``index`` < ``len(values)``; a complete choice where an
    indexed ``Array`` of a length not a power of two would be an incomplete case)."""
    out = values[-1]
    for k in reversed(range(len(values) - 1)):
        out = Mux(index == k, values[k], out)
    return out
