"""The stochastic Bayesian machine, one component per concern (``BayesianMachine``, the top level).

- ``top.py``: :class:`BayesianMachine`, the likelihood memories, the load, the run's control and
  the result; it builds the parts below into one design;
- ``operator.py``: the stochastic operators and the matrix's logic (its twin, the test's component);
- ``matrix.py``: the operator matrix on the machine's registers (prefetched comparators, the
  numbers' registered copies, normalized numbers);
- ``normalize.py``: :class:`ColumnScales`, per-pixel column normalization's scales (a component);
- ``feedback.py``: :class:`FeedbackPrior`, a neighbour prior's feedback column (a component);
- ``counters.py`` and ``stop.py``: the overflow counters, and the stop decision on them;
- ``encoder.py``: :class:`MAPEncoder`, which overflowing row wins (a component);
- the timing contract (bubble, load latency, a pixel's wall cycles): ``bayesmachine.integrators.stochastic``;
- ``nets.py``: :class:`MachineNets`, the nets the builders share and a proof reads.

``docs/architecture.md`` describes the blocks, their ports and their timing.
"""

from bayesmachine.hdl.signatures import entropy_layout, load_layout, result_layout
from bayesmachine.integrators.stochastic import (
    BUBBLE_CYCLES,
    FEEDBACK_CYCLES,
    LOAD_LATENCY,
    SEARCH_CYCLES_PER_BIT,
    hides_bubble,
    pixel_wall_cycles,
    search_cycles,
)

from .encoder import MAPEncoder
from .feedback import FeedbackPrior
from .nets import GROUP_OPERATORS, SOURCE_GROUPS, MachineNets
from .normalize import ColumnScales
from .top import BayesianMachine

__all__ = [
    "BUBBLE_CYCLES", "FEEDBACK_CYCLES", "GROUP_OPERATORS", "LOAD_LATENCY", "SEARCH_CYCLES_PER_BIT",
    "SOURCE_GROUPS", "BayesianMachine", "ColumnScales", "FeedbackPrior", "MAPEncoder", "MachineNets",
    "entropy_layout", "hides_bubble", "load_layout", "pixel_wall_cycles", "result_layout", "search_cycles",
]
