"""Tests of fpga/: the synthesis flow and the pin wrapper."""
