"""Command-line options of the random sources (``--rng`` and the SMTJ device parameters).

Shared by ``emit`` (``hdl/cli.py``) and ``run``/``sweep`` (``host/cli.py``) so the three
commands spell them alike; pure argparse.
"""

from __future__ import annotations

import argparse

from bayesmachine.params import SMTJ_SHARES

__all__ = ["add_rng_options", "rng_kwargs"]

_SMTJ_OPTIONS = ("smtj_dwell", "smtj_spread", "smtj_share")


def add_rng_options(p: argparse.ArgumentParser | argparse._ArgumentGroup, choices: tuple[str, ...]) -> None:
    """``--rng`` among ``choices`` and the SMTJ device options (``--smtj-dwell`` ...)."""
    p.add_argument("--rng", choices=choices, default="lfsr",
                   help="random source: " + ", ".join(choices) + " (default lfsr; smtj: W superparamagnetic "
                   "tunnel junctions per operator, a device model driving the 'entropy' port)")
    p.add_argument("--smtj-dwell", type=float, default=None, metavar="TAU",
                   help="--rng smtj: mean dwell time of a device state, in clock cycles (default 1)")
    p.add_argument("--smtj-spread", type=float, default=None, metavar="S",
                   help="--rng smtj: device-to-device spread, log-sd of each dwell time "
                   "(default 0; 0.05 ~ 5 %%)")
    p.add_argument("--smtj-share", choices=SMTJ_SHARES, default=None,
                   help="--rng smtj: W devices per operator, or per column shared by its rows "
                   "(default operator)")


def rng_kwargs(args: argparse.Namespace) -> dict[str, object]:
    """``MachineParams`` keyword arguments from the options; device options need ``--rng smtj``."""
    given = {name: getattr(args, name) for name in _SMTJ_OPTIONS if getattr(args, name) is not None}
    if given and args.rng != "smtj":
        flags = ", ".join("--" + name.replace("_", "-") for name in given)
        raise ValueError(f"{flags}: device options of --rng smtj (got --rng {args.rng})")
    return {"rng": args.rng, **given}
