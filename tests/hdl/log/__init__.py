"""Tests of hdl/log: the logarithmic integrator and its machine."""
