"""Simulation: the NumPy machine model, the engines, results, packing, synthetic data, ties."""
