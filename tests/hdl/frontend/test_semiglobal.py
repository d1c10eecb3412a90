# amaranth: UnusedElaboratable=no
"""The semi-global column on chip (``hdl.frontend.lanes.semiglobal``): ``StereoMachine`` of census-sg and
census-sgm against the model run as the host runs the passes (``conftest.passes_model``: the column's
paths carried from row to row), every pass's results, random stalls on both streams, both integrators;
frames back to back (a frame's first row starts the paths afresh), one beat a pixel and several, two,
three and four paths; several machines refused by name."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_passes_equal_the_model, noisy_pair, own_options

from bayesmachine.hdl.frontend.lanes.semiglobal import upper_memory_bits
from bayesmachine.hdl.frontend.stereo import StereoMachine, check_stereo_machine, stereo_machine_params
from bayesmachine.host.images import bundled_pair
from bayesmachine.models import ModelParams
from bayesmachine.params import ParameterError

# Whole StereoMachines under Amaranth's simulator: the pysim tier (tests/conftest.py).
pytestmark = pytest.mark.pysim


def _frames(height: int, width: int, noisy: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    left, right, _ = bundled_pair()
    crop = (slice(150, 150 + height), slice(400, 400 + width))
    frames = [(np.ascontiguousarray(left[crop]), np.ascontiguousarray(right[crop]))]
    return [*frames, noisy_pair(height - 1, width, seed=1)] if noisy else frames


# name: (model, its fields, integrator, words per beat (None: the front end's), frame (height, width), a
# noisy frame after it)
CASES = {
    "sg-log": ("census-sg", {"dmax": 3}, "log", None, (9, 18), True),
    "sg-stochastic": ("census-sg", {"dmax": 3}, "stochastic", None, (9, 18), True),
    "sgm-log": ("census-sgm", {"dmax": 3}, "log", None, (9, 18), True),
    "sgm-stochastic": ("census-sgm", {"dmax": 3}, "stochastic", None, (9, 18), True),
    # No neighbour prior: no line of MAPs, the generator's row length for the semi-global lanes alone.
    "sg-no-prior": ("census-sg", {"dmax": 4, "neighbour_prior": False}, "stochastic", None, (9, 18), True),
    # One output pixel a row in the own pass (a column's path above only).
    "sgm-one-pixel-rows": ("census-sgm", {"dmax": 3, "sgm_paths": 4}, "log", None, (9, 10), True),
    # Two beats a pixel (8 rows, 6 a beat), all four paths.
    "sgm-two-beats-four-paths": ("census-sgm", {"dmax": 7, "sgm_paths": 4}, "log", None, (10, 24), False),
    # Two rows a beat, three paths, narrow path costs, the stochastic machine.
    "sgm-three-paths-narrow": ("census-sgm", {"dmax": 5, "sgm_paths": 3, "sgm_cost_bits": 7},
                               "stochastic", 6, (10, 22), False),
}


@pytest.mark.parametrize("case", list(CASES))
def test_semiglobal_stereo_machine_equals_the_model(case: str) -> None:
    name, fields, integrator, words_per_beat, shape, noisy = CASES[case]
    model = ModelParams(name=name, **fields)
    extra = {} if words_per_beat is None else {"words_per_beat": words_per_beat}
    params = stereo_machine_params(model.dmax, model=model, integrator=integrator, **extra,
                                   **own_options(integrator, counter_max=6, max_cycles=400))
    top = StereoMachine(params=params, model=model, width=shape[1], fifo_pixels=2)
    want = assert_passes_equal_the_model(top, _frames(*shape, noisy), model, params, seed=5)
    assert len(np.unique(want[model.passes[-1].name].map)) > 1


def test_several_machines_are_refused_by_name() -> None:
    """A pass's rows dealt to several machines would split its paths' rows: refused, naming machines."""
    model = ModelParams(name="census-sgm", dmax=3)
    params = stereo_machine_params(3, model=model)
    assert check_stereo_machine(params, model, 18) is None
    with pytest.raises(ParameterError, match="semiglobal column continues from the row above") as e:
        check_stereo_machine(params, model, 18, machines=2)
    assert e.value.parameter == "machines"


def test_upper_memory_bits_at_vga() -> None:
    """The upper paths' memories: one word per output column of Dmax + 1 costs and their minimum."""
    column = ModelParams(name="census-sgm", dmax=80).columns[2]
    assert upper_memory_bits(column, 640) == 640 * 82 * 8  # sgm_paths 2: the top path's
    four = ModelParams(name="census-sgm", dmax=80, sgm_paths=4).columns[2]
    assert upper_memory_bits(four, 640) == 3 * 640 * 82 * 8
