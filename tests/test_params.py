"""The machine's parameters (bayesmachine/params.py): the K machines' seeds (``nth_machine``)."""

from __future__ import annotations

import pytest
from conftest import small_params

from bayesmachine.params import ParameterError


def test_nth_machine() -> None:
    from bayesmachine.params import nth_machine

    params = small_params(seed=7)
    assert nth_machine(params, 0) == params
    seeds = {nth_machine(params, i).seed for i in range(50)}
    assert len(seeds) == 50
    with pytest.raises(ParameterError, match="index"):
        nth_machine(params, -1)
