"""Host subcommands of ``bayesmachine``: reference, run, sweep, classify, one module each.

``bayesmachine/cli.py`` calls :func:`register`; every ValueError or OSError raised here
(bad input, impossible parameters, file-system problems) ends as one error line there.
Machine options come from the shared helper :mod:`bayesmachine.cliargs` (the host's plumbing of
them, the inputs and the outputs: :mod:`.options`); outputs are written through
:mod:`bayesmachine.outputs` (complete or absent, the report last).
"""

from __future__ import annotations

import argparse

from ..sweep import SWEEP_OUTPUTS
from . import classify, reference, run, sweep
from .run import RUN_OUTPUTS

__all__ = ["register", "RUN_OUTPUTS", "SWEEP_OUTPUTS"]


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the host subcommands to the ``bayesmachine`` parser."""
    reference.register(subparsers)
    run.register(subparsers)
    sweep.register(subparsers)
    classify.register(subparsers)
