"""The energy form of the tables (bayesmachine.columns.energy): codes of -ln L in 1/16-nat steps and
the exp table back to words."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayesmachine.columns import ENERGY_STEP, EnergyTable, energy_codes, exp_table
from bayesmachine.models import ModelParams


def test_codes_at_known_points() -> None:
    # -ln(0.02) = 3.912 nats = 62.59 codes -> 63; -ln(0.5) = 0.693 -> 11.09 -> 11; 1 -> 0.
    assert ENERGY_STEP == 1 / 16
    assert energy_codes(np.array([1.0, 0.5, 0.02, 0.01])).tolist() == [0, 11, 63, 74]
    # Half up: exp(-2.5 / 16) is exactly 2.5 codes away from 1 (up to float rounding of the exp).
    assert energy_codes(math.exp(-2.5 * ENERGY_STEP * (1 + 1e-12))).item() == 3
    assert energy_codes(math.exp(-2.4 * ENERGY_STEP)).item() == 2


def test_codes_saturate_zero_included() -> None:
    assert energy_codes(np.array([0.0, 1e-300, math.exp(-300 / 16)])).tolist() == [255, 255, 255]
    assert energy_codes(0.0, max_bits=6).item() == 63


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_codes_refuse_what_is_not_a_likelihood(bad: float) -> None:
    with pytest.raises(ValueError, match="likelihoods must be in"):
        energy_codes(np.array([0.5, bad]))


def test_exp_table_is_round_two_to_the_b_exp() -> None:
    x = exp_table(10)
    assert x[:6].tolist() == [1024, 962, 904, 849, 797, 749]
    assert x.size == 123 and x[-1] == 0 and x[-2] == 1
    assert (np.diff(x.astype(int)) <= 0).all()
    assert exp_table(8).size == 101 and exp_table(8)[0] == 256


def test_census_lr_energy_tables() -> None:
    """Every table of census-lr's two passes: nondecreasing codes, widths of 6 or 7 bits, the no-match
    entries (census h_nm 0.614 -> 8; lr's 0.01 -> 74; the prior's 0.1 -> 37)."""
    model = ModelParams(name="census-lr", fuse_columns=False)  # every table, one column each
    seen = {}
    for p in model.passes:
        for term in (*p.columns, p.model.nomatch):
            e = term.energy()
            assert isinstance(e, EnergyTable) and e.step == ENERGY_STEP
            assert (np.diff(e.values.astype(int)) >= 0).all()
            assert e.values.max() < (1 << e.bits) and max(e.nomatch, default=0) < (1 << e.bits)
            seen[(p.name, term.name)] = (e.bits, int(e.values.max()), e.nomatch)
    assert seen[("left", "census")] == (6, 63, (8,))
    assert seen[("left", "lr")] == (7, 37, (74,))
    assert seen[("left", "nomatch")] == (7, 74, ())
    assert seen[("left", "left-prior")] == (6, 48, (37,))
    assert seen[("right", "left-prior")] == (6, 48, (7,))


def test_log_codes_reserve_the_all_ones_code_for_zero() -> None:
    from bayesmachine.columns.energy import INFINITE_CODE, LOG_CODE_BITS, log_codes

    assert (LOG_CODE_BITS, INFINITE_CODE) == (9, 511)
    # 1.0 -> 0; exp(-1) -> 16 codes; 1e-9 saturates at 255 (finite); only 0 is the infinite code.
    got = log_codes(np.array([1.0, np.exp(-1.0), 1e-9, 0.0]))
    assert got.tolist() == [0, 16, 255, 511]
    with pytest.raises(ValueError, match="likelihoods"):
        log_codes(np.array([1.5]))
