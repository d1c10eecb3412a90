"""What every column kind's table is held to (``Column.table``, bayesmachine/columns/base.py):
values in [0, 1], nonincreasing in the cost; a kind whose likelihood grows is refused."""

import numpy as np
import pytest

from bayesmachine.columns import Census
from bayesmachine.models import ModelParams
from bayesmachine.params import ParameterError


def test_every_table_is_checked_nonincreasing_in_its_cost():
    for model in (ModelParams(name="census-lr"), ModelParams(name="census", census_window=5, prior_s=0.5)):
        for p in model.passes:
            for term in (*(f for c in p.columns for f in c.factors()), p.model.nomatch):  # fused: members
                v = term.table().values
                assert (np.diff(v) <= 0).all(), term
    class Growing(Census):  # a kind whose likelihood grows with the cost: refused when its table is built
        def likelihood(self, cost):
            return np.linspace(0.5, 1.0, np.size(cost))

    model = ModelParams(name="census")
    with pytest.raises(ParameterError, match="^census_sigma = 6.0 gives likelihoods that grow with the cost"):
        Growing(values=model.parameters, dmax=model.dmax).table()


def test_column_kinds_are_the_package_s_kinds_each_with_a_lane_builder() -> None:
    """``COLUMN_KINDS`` lists every column kind the package exports (a class that names its operator
    column), and each kind a model of the package's builds has a lane builder on chip."""
    import bayesmachine.columns as columns
    from bayesmachine.columns import COLUMN_KINDS, Column
    from bayesmachine.hdl.frontend.lanes import lanes_for

    exported = {k for k in vars(columns).values()
                if isinstance(k, type) and issubclass(k, Column) and "name" in vars(k)}
    assert exported == set(COLUMN_KINDS)
    built = [c for model in (ModelParams(name="paper", gradient_magnitude=True, dmax=4),
                             ModelParams(name="census-lr", dmax=4),
                             ModelParams(name="census-lr", dmax=4, fuse_columns=False),
                             ModelParams(name="census-sgm", dmax=4))
             for p in model.passes for c in p.columns]
    assert {k for k in COLUMN_KINDS for c in built if isinstance(c, k)} == set(COLUMN_KINDS)
    for c in built:
        lanes_for(c)
