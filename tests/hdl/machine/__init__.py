"""Tests of hdl/machine: the Bayesian machine's blocks and the whole machine."""
