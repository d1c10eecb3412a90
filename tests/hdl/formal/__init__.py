"""Tests of hdl/formal: the formal proofs (SymbiYosys)."""
