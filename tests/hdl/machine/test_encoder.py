# amaranth: UnusedElaboratable=no
"""MAP encoder: RTL against its twin, exhaustively for small M and randomly for M = 82."""

from __future__ import annotations

import random

import pytest
from conftest import run_sim

from bayesmachine.hdl.machine.encoder import MAPEncoder, map_encoder_twin
from bayesmachine.params import ParameterError

CONFIGS = [(False, "lowest-index"), (True, "lowest-index"), (True, "nomatch-first"), (False, "nomatch-first")]


def _check_patterns(rows: int, nomatch_row: bool, tie_break: str, patterns: list[int]) -> None:
    dut = MAPEncoder(rows=rows, nomatch_row=nomatch_row, tie_break=tie_break)

    async def bench(ctx):
        for pat in patterns:
            ctx.set(dut.over, pat)
            over = [(pat >> i) & 1 for i in range(rows)]
            want = map_encoder_twin(over, nomatch_row, tie_break)
            valid, index = ctx.get(dut.valid), ctx.get(dut.index)
            assert valid == (want is not None), f"pattern {pat:#x}"
            if want is not None:
                assert index == want, f"pattern {pat:#x}: index {index}, twin {want}"

    run_sim(dut, bench, clock=False)


# Every small encoder (a no-match row needs 2 rows: that case is a parameter error, tested apart).
@pytest.mark.parametrize(("rows", "nomatch_row", "tie_break"),
                         [(r, n, t) for r in range(1, 11) for n, t in CONFIGS if r >= 2 or not n])
def test_encoder_exhaustive_small(rows: int, nomatch_row: bool, tie_break: str) -> None:
    _check_patterns(rows, nomatch_row, tie_break, list(range(1 << rows)))


@pytest.mark.parametrize(("nomatch_row", "tie_break"), CONFIGS)
@pytest.mark.parametrize("rows", [82, 33, 128])
def test_encoder_random_large(rows: int, nomatch_row: bool, tie_break: str) -> None:
    rnd = random.Random(rows)
    patterns = [0, 1 << (rows - 1), (1 << rows) - 1, 1 | (1 << (rows - 1))]
    for _ in range(1500):
        kind = rnd.random()
        if kind < 0.4:  # one or a few rows: the usual case in the machine
            pat = 0
            for _ in range(rnd.randint(1, 3)):
                pat |= 1 << rnd.randrange(rows)
        elif kind < 0.6:  # ties with the no-match row
            pat = (1 << (rows - 1)) | (1 << rnd.randrange(rows))
        else:
            pat = rnd.getrandbits(rows) & rnd.getrandbits(rows) & rnd.getrandbits(rows)
        patterns.append(pat)
    _check_patterns(rows, nomatch_row, tie_break, patterns)


def test_twin_tie_rules() -> None:
    over = [0, 1, 0, 1, 1]
    assert map_encoder_twin(over, True, "nomatch-first") == 4
    assert map_encoder_twin(over, True, "lowest-index") == 1
    assert map_encoder_twin(over, False, "nomatch-first") == 1  # no no-match row: lowest index
    assert map_encoder_twin([0, 0, 0], True, "nomatch-first") is None


def test_encoder_rejects_bad_parameters() -> None:
    with pytest.raises(ParameterError, match="tie_break"):
        MAPEncoder(rows=4, tie_break="random")
    with pytest.raises(ParameterError, match="rows"):
        MAPEncoder(rows=0)
    with pytest.raises(ParameterError, match="no-match"):
        MAPEncoder(rows=1, nomatch_row=True)
