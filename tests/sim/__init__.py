"""Tests of sim/: the machine model and the engines."""
