"""Formal proofs of the machine's control logic (SymbiYosys and Yices, from PyPI): formal-only wrappers
with Amaranth ``Assert``/``Assume``/``Cover`` around the shipped blocks (``counter``, ``encoder``,
``machine``), known bugs to show the properties bite (``mutants``) and the runner (``runner``).
Nothing here is part of the shipped RTL. See ``docs/formal.md``."""
