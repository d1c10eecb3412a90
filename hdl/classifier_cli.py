"""``emit --top classifier``'s options and the classifier top built from them (no Amaranth here: the
command line registers them without importing the RTL; :mod:`.classifier` is the top)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .classifier import ClassifierTop

__all__ = ["add_emit_options", "build_from_args", "machine_options"]

# emit --top classifier: the top's size options (the tables are loaded, so one design serves any task of
# its size) and the machine options it passes on (classify.machine.MACHINE_FIELDS).
_SIZE_OPTIONS = (("classes", "--classes", 2, 4096, "rows of the machine"),
                 ("features", "--features", 1, 4096, "likelihood memories"),
                 ("bins", "--bins", 1, 256, "rows of each memory"))


def add_emit_options(parser: object) -> None:
    """``emit``'s options of ``--top classifier`` (None unless given: refused with another top)."""
    from bayesmachine.argtypes import int_in_range

    g = parser.add_argument_group("classifier (--top classifier; docs/classifier.md)")  # type: ignore[attr-defined]
    for dest, flag, lo, hi, what in _SIZE_OPTIONS:
        g.add_argument(flag, dest=f"classifier_{dest}", type=int_in_range(lo, hi), default=None,
                       metavar="N", help=f"--top classifier: the {what} ({lo} .. {hi})")


def machine_options(args: object) -> dict[str, object]:
    """The machine options given in ``args`` that the classifier top takes
    (``classify.machine.MACHINE_FIELDS``); its layout's (columns, prior, beats ...) refused."""
    from bayesmachine.classify.machine import MACHINE_FIELDS
    from bayesmachine.cliargs import MACHINE_OPTIONS

    layout = [o.flag for f, o in MACHINE_OPTIONS.items() if f not in MACHINE_FIELDS and getattr(args, f, None)
              is not None]
    if layout:
        raise ValueError(f"{', '.join(layout)}: the classifier top decides its machine's layout (one fused "
                         "column, no prior column, its load beats)")
    return {f: getattr(args, f) for f in MACHINE_FIELDS if getattr(args, f, None) is not None}


def build_from_args(args: object) -> ClassifierTop | None:
    """The classifier top of ``emit``'s arguments (``--top classifier``), or None for another top (its
    size options refused there)."""
    from bayesmachine.classify.machine import classifier_params

    from .classifier import ClassifierTop

    sizes = {dest: getattr(args, f"classifier_{dest}") for dest, *_ in _SIZE_OPTIONS}
    if args.top != "classifier":
        given = [flag for dest, flag, *_ in _SIZE_OPTIONS if sizes[dest] is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: only with --top classifier (got --top {args.top})")
        return None
    machine = machine_options(args)
    missing = [flag for dest, flag, *_ in _SIZE_OPTIONS if sizes[dest] is None]
    if missing:
        raise ValueError(f"--top classifier needs {', '.join(missing)}: the size of the task it serves")
    params = classifier_params(classes=sizes["classes"], features=sizes["features"], fuse=1, machine=machine)
    return ClassifierTop(params=params, features=sizes["features"], bins=sizes["bins"])

