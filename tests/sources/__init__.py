"""Tests of bayesmachine/sources and their RTL generators (hdl/sources.py, hdl/smtj.py)."""
