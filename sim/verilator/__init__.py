"""The ``verilator`` engine: the emitted Verilog, compiled with Verilator, driven by a C++ harness.

``VerilatorEngine(params).run(words)`` gives the same :class:`MachineResult` as
``MachineModel(params).run(words)``, bit for bit, at millions of simulated clock cycles per
second instead of Amaranth's hundreds: whole VGA frames through the RTL.

Modules: ``tools`` (finding Verilator, g++, make; shared with the lint test), ``codegen`` (the
harness's top module and ``design.h``, from the design's layouts), ``build`` (the build cache:
key, compile, recovery; any harness), ``engine`` (the engine, the pipe protocol and the harness
process every harness client shares). ``docs/engines.md``
describes them.
"""

from .build import HARNESS_DIR, HarnessSources, VerilatorBuild, build_design, build_harness, cache_dir
from .engine import VerilatorEngine
from .tools import VerilatorError, find_tool, find_toolchain, find_verilator, which

__all__ = [
    "HARNESS_DIR",
    "HarnessSources",
    "VerilatorBuild",
    "VerilatorEngine",
    "VerilatorError",
    "build_design",
    "build_harness",
    "cache_dir",
    "find_tool",
    "find_toolchain",
    "find_verilator",
    "which",
]
