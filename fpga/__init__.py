"""The FPGA flow: ``bayesmachine synth`` (Yosys + nextpnr from PyPI wheels), the pin-saving wrapper,
device targets and the synthesis report."""
