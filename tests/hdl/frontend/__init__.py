"""Tests of hdl/frontend: the on-chip front end (feature pipeline, word generators, passes, StereoMachine)."""
