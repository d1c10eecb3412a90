"""Tests of hdl/: the RTL, against its Python twins."""
