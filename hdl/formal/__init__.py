"""Formal proofs of the machine's control logic (SymbiYosys and Yices, from PyPI): formal-only wrappers
with Amaranth ``Assert``/``Assume``/``Cover`` around the shipped blocks (``counter``, ``encoder``,
``machine``; ``control``: the machine against a reference run; ``miter``: two machines, one stalled;
``frontend``: the word generator, the front end and the FIFO of ``StereoMachine``), known bugs to show
the properties bite (``mutants``) and the runner (``runner``). Nothing here is part of the shipped
RTL. See ``docs/formal.md``."""
