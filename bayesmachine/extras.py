"""Optional dependencies, imported on first use.

The RTL alone (``emit``, ``synth``, ``board``, the machine's engines and testbenches) installs without
the host's image and cluster libraries (``pip install bayesmachine``); images, datasets, sweeps and
plots need ``pip install 'bayesmachine[host]'``. A module that uses one names it once
(``cv2 = optional("cv2", "OpenCV")``) and uses it as the module itself; the first use without it
installed is one error naming the extra (:class:`MissingExtra`, a ``RuntimeError``: the CLI's one line).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
from collections.abc import Callable
from types import ModuleType
from typing import Any

__all__ = ["HOST_EXTRA", "HOST_MODULES", "MissingExtra", "needs_host", "optional", "require"]

HOST_EXTRA = "host"
# What the host's commands (run, reference, sweep) import, by module: checked before any work.
HOST_MODULES = {"cv2": "OpenCV", "skimage": "scikit-image", "matplotlib": "Matplotlib",
                "distributed": "Dask's distributed"}


class MissingExtra(RuntimeError):
    """An optional dependency a command needs is not installed."""


def require(name: str, what: str, extra: str = HOST_EXTRA) -> ModuleType:
    """The module ``name``, or :class:`MissingExtra` saying which extra installs ``what``."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise MissingExtra(f"this needs {what} (module {name!r}), which is not installed: "
                           f"pip install 'bayesmachine[{extra}]'") from exc


class _Optional:
    """Stands for a module until its first attribute is read (then imports it, see :func:`require`)."""

    def __init__(self, name: str, what: str, extra: str) -> None:
        self._spec = (name, what, extra)
        self._module: ModuleType | None = None

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):
            raise AttributeError(attr)
        if self._module is None:
            self._module = require(*self._spec)
        return getattr(self._module, attr)


def optional(name: str, what: str, extra: str = HOST_EXTRA) -> Any:
    """A stand-in for module ``name`` that imports it on first use (``what`` names it in the error)."""
    return _Optional(name, what, extra)


def needs_host(command: Callable[..., Any]) -> Callable[..., Any]:
    """``command`` after checking, without importing them, that the host extra's modules are installed."""

    @functools.wraps(command)
    def checked(*args: Any, **kwargs: Any) -> Any:
        missing = [what for name, what in HOST_MODULES.items() if importlib.util.find_spec(name) is None]
        if missing:
            raise MissingExtra(f"this command needs {', '.join(missing)}, not installed: "
                               f"pip install 'bayesmachine[{HOST_EXTRA}]'")
        return command(*args, **kwargs)

    return checked
