"""The error of an impossible machine parameter, below both ``params`` and ``sources``.

``bayesmachine.params`` validates through the source registry (``bayesmachine.sources``), and the
sources raise the same error: it lives here so that neither has to import the other to raise it.
"""

from __future__ import annotations

__all__ = ["ParameterError"]


class ParameterError(ValueError):
    """An impossible or unsupported machine parameter."""
