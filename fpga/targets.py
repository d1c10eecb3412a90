"""FPGA targets of ``bayesmachine synth``: the device, how to call the tools, and its size.

Sizes are the device data sheets' counts; they give utilization from synthesis alone (the machine
estimate) and are checked against nextpnr's own counts in the report.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TARGETS", "Target", "ecp5_device_args", "get_target"]

# nextpnr-ecp5's names of the ECP5 packages Amaranth calls BG* and MG*.
_ECP5_PACKAGES = {"BG": "CABGA", "MG": "CSFBGA"}


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


@dataclass(frozen=True)
class Target:
    name: str
    family: str  # "ecp5" or "ice40"
    device: str  # human-readable part name
    nextpnr_args: tuple[str, ...]
    luts: int  # LUT4s (ECP5: 2 per slice; iCE40: 1 per logic cell)
    ffs: int
    brams: int  # DP16KD (ECP5, 18 kbit) or SB_RAM40_4K (iCE40, 4 kbit)
    dsps: int  # MULT18X18D (ECP5); iCE40 HX has none

    @property
    def yosys_synth(self) -> str:
        return f"synth_{self.family}"

    @property
    def nextpnr(self) -> str:
        return f"yowasp-nextpnr-{self.family}"


TARGETS: dict[str, Target] = {
    t.name: t
    for t in (
        Target("ecp5-85k", "ecp5", "LFE5U-85F CABGA381", ecp5_device_args("LFE5U-85F", "BG381"),
               83640, 83640, 208, 156),
        Target("ecp5-25k", "ecp5", "LFE5U-25F CABGA256", ecp5_device_args("LFE5U-25F", "BG256"),
               24288, 24288, 56, 28),
        Target("ice40-hx8k", "ice40", "iCE40-HX8K CT256", ("--hx8k", "--package", "ct256"),
               7680, 7680, 32, 0),
    )
}


def get_target(name: str) -> Target:
    try:
        return TARGETS[name]
    except KeyError:
        raise ValueError(f"unknown FPGA target {name!r}; choose one of {', '.join(TARGETS)}") from None
