"""The log integrator's rule (``bayesmachine.sim.log_model``; its parameters
``bayesmachine.integrators.log``): hand-worked pixels, a plain Python scan as an independent oracle over
random pixels, the exp table, the parameters' checks."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.columns.energy import exp_table
from bayesmachine.errors import ParameterError
from bayesmachine.integrators.log import LogParams
from bayesmachine.sim.log_model import argmin_rows, log_integrate, row_weights

TABLE = (16, 10, 6, 4, 2, 1, 1, 0)  # exp_table(4, 0.5)


def params(**kw: object) -> LogParams:
    base: dict[str, object] = dict(rows=4, codes=2, code_bits=3, weights=TABLE)
    base.update(kw)
    return LogParams(**base)  # type: ignore[arg-type]


def plain_rule(pixel: list[list[int]], p: LogParams) -> tuple[int, bool, bool, int, list[int]]:
    """The rule as written in docs/integrators.md, one pixel, plain Python: a sequential scan."""
    sums = [sum(row) for row in pixel]
    excluded = [p.infinite in row for row in pixel]
    best = None
    for r in range(p.rows):
        if excluded[r]:
            continue
        nm_tie = p.nomatch_row and p.tie_break == "nomatch-first" and r == p.rows - 1
        if best is None or sums[r] < sums[best] or (nm_tie and sums[r] == sums[best]):
            best = r
    if best is None:
        map_, s_min = (p.rows - 1 if p.nomatch_row else 0), 0
    else:
        map_, s_min = best, sums[best]
    weights = [0 if excluded[r] else p.weights[min(max(sums[r] - s_min, 0), len(p.weights) - 1)]
               for r in range(p.rows)]
    return map_, p.nomatch_row and map_ == p.rows - 1, best is None, s_min, weights


def fields(res: object, i: int) -> tuple[int, bool, bool, int, list[int]]:
    return (int(res.map[i]), bool(res.nomatch[i]), bool(res.all_excluded[i]), int(res.s_min[i]),
            [int(w) for w in res.weights[i]])


def test_exp_table() -> None:
    # The energy form's exp table (one definition) is what LogParams takes: pinned at the sizes used here.
    table = tuple(int(x) for x in exp_table(8, 1 / 16))
    assert table[:6] == (256, 240, 226, 212, 199, 187)
    assert len(table) == 101 and table[-2:] == (1, 0)
    assert tuple(int(x) for x in exp_table(4, 0.5)) == TABLE
    assert LogParams(rows=2, codes=1, code_bits=3, weights=exp_table(4, 0.5)).weights == TABLE


def test_hand_worked_pixels() -> None:
    # Sums 3, 1, 3, 1: row 1 and the no-match row tie at the least.
    pixel = np.array([[[1, 2], [0, 1], [3, 0], [1, 0]]], np.uint8)
    res = log_integrate(pixel, params())
    assert fields(res, 0) == (3, True, False, 1, [6, 16, 6, 16])
    assert int(log_integrate(pixel, params(tie_break="lowest-index")).map[0]) == 1
    assert int(log_integrate(pixel, params(nomatch_row=False)).map[0]) == 1
    # An infinite code (7) excludes its row: row 1's sum 1 does not count; rows 0 and 3 tie at 2.
    pixel = np.array([[[1, 1], [7, 0], [3, 1], [2, 0]]], np.uint8)
    res = log_integrate(pixel, params(tie_break="lowest-index"))
    assert fields(res, 0) == (0, False, False, 2, [16, 0, 6, 16])
    assert res.sums[0].tolist() == [2, 7, 4, 2] and res.excluded[0].tolist() == [False, True, False, False]
    # Every row excluded: no match (flagged), weights 0; without a no-match row, row 0.
    pixel = np.full((1, 4, 2), 7, np.uint8)
    assert fields(log_integrate(pixel, params()), 0) == (3, True, True, 0, [0, 0, 0, 0])
    assert fields(log_integrate(pixel, params(nomatch_row=False)), 0) == (0, False, True, 0, [0, 0, 0, 0])
    # A far row reads the table's last entry (0); the clamp at len(X) - 1.
    pixel = np.array([[[0, 0], [6, 6], [3, 2], [4, 0]]], np.uint8)
    assert fields(log_integrate(pixel, params()), 0) == (0, False, False, 0, [16, 0, 1, 2])


RULES = [(True, "nomatch-first"), (True, "lowest-index"), (False, "nomatch-first")]
SHAPES = [(1, 1, 2), (2, 3, 2), (5, 4, 3), (82, 4, 6)]


@pytest.mark.parametrize(("rows", "codes", "code_bits", "nomatch_row", "tie_break"),
                         [(*s, *r) for s in SHAPES for r in RULES if s[0] >= 2 or not r[0]])
def test_rule_against_a_plain_scan(rows: int, codes: int, code_bits: int, nomatch_row: bool,
                                   tie_break: str) -> None:
    p = params(rows=rows, codes=codes, code_bits=code_bits, nomatch_row=nomatch_row, tie_break=tie_break)
    rng = np.random.default_rng(rows * 7 + codes)
    # Small codes (many ties), some infinite codes, some pixels with every row excluded.
    pix = rng.integers(0, 3, size=(300, rows, codes)).astype(np.uint16)
    pix[rng.random(pix.shape) < 0.15] = p.infinite
    pix[:10] = p.infinite
    pix[10:20] = 1  # every row ties
    res = log_integrate(pix.reshape(20, 15, rows, codes), p)  # any leading shape
    flat = type(res)(**{k: v.reshape(300, *v.shape[2:]) for k, v in vars(res).items()})
    for i in range(300):
        assert fields(flat, i) == plain_rule(pix[i].tolist(), p), f"pixel {i}"


def test_parts_on_their_own() -> None:
    p = params()
    sums = np.array([[5, 3, 3, 4]])
    excl = np.array([[False, False, False, True]])
    got = argmin_rows(sums, excl, p)
    assert [int(a[0]) for a in got] == [1, 0, 0, 3]
    # A sum below s_min (never from the rule itself) reads X[0].
    assert row_weights(np.array([[1, 4, 12, 2]]), excl, np.array([3]), p).tolist() == [[16, 10, 0, 0]]


def test_bad_parameters() -> None:
    with pytest.raises(TypeError, match="rows"):
        params(rows=4.0)
    with pytest.raises(TypeError, match="rows"):
        params(rows=True)
    assert params(rows=np.int64(5)).rows == 5
    with pytest.raises(ParameterError, match="rows") as err:
        params(rows=1)  # a no-match row needs 2 rows
    assert err.value.parameter == "rows"
    with pytest.raises(ParameterError, match="code_bits"):
        params(code_bits=17)
    with pytest.raises(ParameterError, match="weights"):
        params(weights=(4, 5, 0))
    with pytest.raises(ParameterError, match="weights"):
        params(weights=(4, 2, 1))
    with pytest.raises(TypeError, match="weights"):
        params(weights=7)
    with pytest.raises(ParameterError, match="tie_break"):
        params(tie_break="random")
    with pytest.raises(TypeError, match="nomatch_row"):
        params(nomatch_row=1)
    with pytest.raises(ParameterError, match="step"):
        exp_table(8, 0.0)
    with pytest.raises(ParameterError, match="bits"):
        exp_table(0, 0.1)


def test_bad_codes() -> None:
    p = params()
    with pytest.raises(ValueError, match="shape"):
        log_integrate(np.zeros((3, 4, 3), np.uint8), p)
    with pytest.raises(ValueError, match=r"\[0, 7\]"):
        log_integrate(np.full((3, 4, 2), 8, np.uint8), p)
    with pytest.raises(TypeError, match="integer array"):
        log_integrate(np.zeros((3, 4, 2)), p)
    with pytest.raises(TypeError, match="LogParams"):
        log_integrate(np.zeros((3, 4, 2), np.uint8), "p")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="one shape"):
        argmin_rows(np.zeros((3, 4)), np.zeros((3, 3), bool), p)
    with pytest.raises(ValueError, match="one shape"):
        row_weights(np.zeros((3, 5)), np.zeros((3, 5), bool), np.zeros(3), p)
