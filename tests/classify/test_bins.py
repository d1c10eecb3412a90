"""bayesmachine.classify.bins: quantile edges, repeated edges dropped, values on an edge go up."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.classify.bins import QuantileBins
from bayesmachine.errors import ParameterError


def test_quartiles_of_one_to_eight() -> None:
    x = np.arange(1.0, 9.0)[:, None]
    b = QuantileBins.fit(x, 4)
    # np.quantile (linear): 2.75, 4.5, 6.25, moved to the nearest midpoints 2.5, 4.5, 6.5
    np.testing.assert_allclose(b.edges[0], [2.5, 4.5, 6.5])
    assert b.counts.tolist() == [4]
    assert b.transform(x)[:, 0].tolist() == [0, 0, 1, 1, 2, 2, 3, 3]
    # beyond the training range: the end bins; on an edge: the bin above it
    assert b.transform(np.array([[-100.0], [4.5], [1e9]]))[:, 0].tolist() == [0, 2, 3]


def test_few_distinct_values_give_fewer_bins() -> None:
    # 90 % zeros; 95 % ones; a constant feature: every quantile is 0 (1), the edge the midpoint 0.5
    x = np.array([[0.0, 0.0, 5.0]] * 5 + [[0.0, 1.0, 5.0]] * 85 + [[1.0, 1.0, 5.0]] * 10)
    b = QuantileBins.fit(x, 8)
    assert b.counts.tolist() == [2, 2, 1]
    np.testing.assert_allclose(b.edges[0], [0.5])
    assert b.transform(np.array([[0.0, 0.0, 5.0], [1.0, 1.0, 7.0]])).tolist() == [[0, 0, 0], [1, 1, 0]]


def test_one_bin() -> None:
    b = QuantileBins.fit(np.array([[1.0], [2.0]]), 1)
    assert b.counts.tolist() == [1] and b.transform(np.array([[3.0]])).tolist() == [[0]]


@pytest.mark.parametrize("bad", [0, 257])
def test_bins_out_of_range(bad: int) -> None:
    with pytest.raises(ParameterError, match="bins"):
        QuantileBins.fit(np.zeros((3, 1)), bad)


def test_bad_inputs() -> None:
    with pytest.raises(TypeError, match="bins"):
        QuantileBins.fit(np.zeros((3, 1)), 2.5)
    with pytest.raises(ValueError, match="NaN"):
        QuantileBins.fit(np.array([[np.nan]]), 4)
    with pytest.raises(ValueError, match="2-D"):
        QuantileBins.fit(np.zeros(3), 4)
    with pytest.raises(ValueError, match="features"):
        QuantileBins.fit(np.zeros((3, 2)), 4).transform(np.zeros((3, 1)))
