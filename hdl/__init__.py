"""Amaranth RTL of the stochastic Bayesian machine."""
