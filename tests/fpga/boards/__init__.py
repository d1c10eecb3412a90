"""Tests of fpga/boards: the board's RTL, its twin and the host link."""
