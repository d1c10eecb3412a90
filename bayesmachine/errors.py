"""The error of an impossible parameter, below ``params``, ``sources`` and ``columns``.

``bayesmachine.params`` validates through the source registry (``bayesmachine.sources``), and the
sources raise the same error: it lives here so that neither has to import the other to raise it.
The library's messages speak of parameters (``census_sigma``); ``parameter`` names the one at fault
so that a command line can say which of its flags gave it (``bayesmachine.cliargs``).
"""

from __future__ import annotations

__all__ = ["ParameterError"]


class ParameterError(ValueError):
    """An impossible or unsupported parameter value; ``parameter`` names it (None: no single one)."""

    def __init__(self, message: str, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter
