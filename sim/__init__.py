"""Simulation: the NumPy machine model, the engines, testbench helpers."""
