"""Switching activity: every register bit's toggles in a Verilator run, a technology-free proxy for
dynamic energy (docs/integrators.md, "Switching activity").

A harness built with :data:`ACTIVITY_FLAGS` (Verilator's toggle coverage, ``harness/common.h``)
writes the toggles of every signal bit to the file its environment variable ``BM_ACTIVITY`` names:
the StereoMachine's harness those of each frame, the machine's harness (fed words) those since it
started. An engine given ``activity=DIR`` (:func:`activity_env`) writes ``DIR/<build>.dat`` beside
``DIR/<build>.v``, a copy of its design's Verilog, one pair per harness (a pass fed words runs a harness
of its own); :func:`directory_activity` sums them. :func:`read_toggles` reads one file,
:func:`register_names` finds which signals are registers in the design's Verilog (the left-hand sides
of its clocked assignments, memories excluded), and :func:`activity` sums the registers' toggles by
block (:data:`BLOCKS`). Wires are left out: a net shared by several modules' ports would be counted
once per port, and a register's toggles are what the flip-flops switch.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["ACTIVITY_FLAGS", "BLOCKS", "Activity", "activity", "activity_env", "block_of",
           "directory_activity", "read_toggles", "register_names"]

# Verilator's toggle coverage on every signal, however wide (by default it skips those over 256 bits)
# and whatever its name (by default it skips names starting with "_", as Yosys names a memory's read
# register).
ACTIVITY_FLAGS = ("--coverage-toggle", "--coverage-max-width", "65536", "--coverage-underscore")

# Where a register belongs, the first rule that matches: (block, module name pattern, register name
# pattern), matched in full against the Verilog module (``bayesmachine.machine.source``) and the
# register's name (_ANY: any module, the machine's or the top of a harness fed words). The machine's
# operators, counters and encoder registers live in its own module, told apart by their names
# (hdl/machine: ``word_r_c``/``shadow_r_c`` the likelihood-memory words and ``load_q``/``write_q`` the
# load path into them, ``bit_r_c`` the operators' outputs, ``count_r`` the
# overflow counters, ``over_group_g`` and ``search*`` the MAP encoder's, ``next_number_rep*`` and
# ``restart_number_rep*`` the sources' copies on the stochastic bus, ``source_rep<k>`` the copies of a
# shared source; the log machine's ``code{i}`` its loaded codes, ``issue_sums`` its row adders' sums
# waiting at the issue point, ``feedback{r}`` and ``distance{r}`` its feedback column's).
_ANY = r"bayesmachine(\..*)?"
BLOCKS: tuple[tuple[str, str, str], ...] = (
    # The classifier top's own (hdl/classifier.py, the top module): its likelihood memories' read
    # registers (Yosys's ``_<n>_``) and the prior's row; the per-class sums and the entries formed.
    ("tables", r"bayesmachine", r"prior|_\d+_"),
    ("sums", r"bayesmachine", r"sums|entries"),
    ("front end", r"bayesmachine\.(frontend|fifo)(\..*)?", r".*"),
    ("sources", r"bayesmachine(\.\w+)*\.(source|source_rep\d+|column_scales)(\..*)?", r".*"),
    ("feedback prior", r"bayesmachine(\.\w+)*\.feedback_prior(\..*)?", r".*"),
    ("encoder", r"bayesmachine(\.\w+)*\.encoder(\..*)?", r".*"),
    ("adders", r"bayesmachine(\.\w+)*\.(adders|row_adders)(\..*)?", r".*"),
    ("adders", _ANY, r"issue_sums"),
    ("argmin", r"bayesmachine(\.\w+)*\.(argmin|argmin_tree)(\..*)?", r".*"),
    ("weights", r"bayesmachine(\.\w+)*\.(weights|weight_stage)(\..*)?", r".*"),
    ("sources", _ANY, r"(next|restart)_number_rep.*"),
    ("likelihood memory", _ANY, r"(word|shadow)_\d+_\d+|load_q|write_q|code\d+"),
    ("operators", _ANY, r"bit_\d+_\d+"),
    ("counters", _ANY, r"count_\d+"),
    ("encoder", _ANY, r"over_group_\d+|search.*|over\$\d+"),
    ("feedback prior", _ANY, r"feedback\d+|distance\d+"),
)
OTHER = "control"  # every other register: the machines' and the top's sequencing


def block_of(module: str, register: str) -> str:
    """The block (:data:`BLOCKS`) of ``register`` in the Verilog module ``module``."""
    for block, mod, reg in BLOCKS:
        if re.fullmatch(mod, module) and re.fullmatch(reg, register):
            return block
    return OTHER


_ESCAPE = re.compile(r"__0([0-9a-fA-F]{2})")


def _unmangle(name: str) -> str:
    """Verilator's name of a signal back to the Verilog's (``beats___05Fpayload`` -> ``beats__payload``,
    ``__024`` -> ``$``, ``__02e`` -> ``.``)."""
    return _ESCAPE.sub(lambda m: chr(int(m[1], 16)), name)


def read_toggles(path: str | os.PathLike[str]) -> dict[tuple[str, str], int]:
    """``(module, signal)`` -> toggles (every bit, both directions, summed over the instances of the
    module) from a coverage file of Verilator's toggle coverage."""
    counts: dict[tuple[str, str], int] = {}
    with open(path, encoding="latin-1") as f:
        for line in f:
            if not line.startswith("C '"):
                continue
            body, _, count = line[3:].rstrip("\n").rpartition("' ")
            fields = dict(kv.split("\x02", 1) for kv in body.split("\x01") if "\x02" in kv)
            page = fields.get("page", "")
            if not page.startswith("v_toggle/"):
                continue
            module = page[len("v_toggle/"):]
            signal = _unmangle(re.sub(r"(\[\d+\])*:.*$", "", fields["o"]))
            key = (module, signal)
            counts[key] = counts.get(key, 0) + int(count)
    return counts


_MODULE = re.compile(r"^module\s+\\?(\S+)\s*\(", re.M)
_IDENT = r"(\\\S+\s|[A-Za-z_][\w$]*)"
_MEMORY = re.compile(rf"^\s*reg\s+(\[[^\]]*\]\s*)?{_IDENT}\s*\[", re.M)
_CLOCKED = re.compile(rf"^\s*{_IDENT}\s*(\[[^\]]*\]\s*)?<=", re.M)


def register_names(verilog: str) -> dict[str, set[str]]:
    """Verilog module -> the names of its registers: every left-hand side of a nonblocking assignment
    (Yosys writes one for each flip-flop), memories excluded."""
    starts = [(m.start(), m[1]) for m in _MODULE.finditer(verilog)] + [(len(verilog), "")]
    out: dict[str, set[str]] = {}
    for (start, module), (end, _) in zip(starts, starts[1:], strict=False):
        text = verilog[start:end]
        memories = {_name(m[2]) for m in _MEMORY.finditer(text)}
        out[module] = {n for m in _CLOCKED.finditer(text) if (n := _name(m[1])) not in memories}
    return out


def _name(ident: str) -> str:
    return ident.strip().removeprefix("\\")


@dataclass
class Activity:
    """Register toggles of one frame: ``toggles`` and ``registers`` (signals) per block, the output
    pixels they are divided by, and what was left out (``wire_toggles``: every other signal's)."""

    pixels: int
    toggles: dict[str, int] = field(default_factory=dict)
    registers: dict[str, int] = field(default_factory=dict)
    wire_toggles: int = 0

    @property
    def total(self) -> int:
        return sum(self.toggles.values())

    def per_pixel(self) -> dict[str, float]:
        """Toggles per output pixel, by block and ``"total"``."""
        return {**{b: t / self.pixels for b, t in self.toggles.items()}, "total": self.total / self.pixels}


def activity(coverage: str | os.PathLike[str], verilog: str | os.PathLike[str], pixels: int,
             blocks: Iterable[str] = ()) -> Activity:
    """The registers' toggles of a frame of ``pixels`` output pixels by block, from the harness's
    coverage file and the design's Verilog (its text or a path); ``blocks``: blocks listed even when
    no register falls in them."""
    if pixels <= 0:
        raise ValueError(f"pixels must be > 0, got {pixels}")
    text = Path(verilog).read_text() if isinstance(verilog, os.PathLike) else verilog
    regs = register_names(text)
    out = Activity(pixels, dict.fromkeys(blocks, 0), dict.fromkeys(blocks, 0))
    for (module, signal), n in read_toggles(coverage).items():
        if signal in regs.get(module, ()):
            block = block_of(module, signal)
            out.toggles[block] = out.toggles.get(block, 0) + n
            out.registers[block] = out.registers.get(block, 0) + 1
        else:
            out.wire_toggles += n
    return out


def activity_env(directory: str | os.PathLike[str] | None, build: Any) -> dict[str, str] | None:
    """The environment of a harness of ``build`` (a ``VerilatorBuild``) counting into ``directory``:
    ``BM_ACTIVITY`` = ``directory/<build>.dat``, its design's Verilog copied to ``directory/<build>.v``;
    None without a directory."""
    if directory is None:
        return None
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    name = Path(build.directory).name
    shutil.copyfile(Path(build.directory) / "bayesmachine.v", d / f"{name}.v")
    return {"BM_ACTIVITY": str((d / f"{name}.dat").resolve())}


def directory_activity(directory: str | os.PathLike[str], pixels: int,
                       blocks: Iterable[str] = ()) -> Activity:
    """Every harness's activity in ``directory`` (:func:`activity_env`) summed, over ``pixels``."""
    total = Activity(pixels, dict.fromkeys(blocks, 0), dict.fromkeys(blocks, 0))
    runs = sorted(Path(directory).glob("*.dat"))
    if not runs:
        raise ValueError(f"no activity file in {directory}: was the engine given activity={directory}?")
    for dat in runs:
        one = activity(dat, dat.with_suffix(".v"), pixels, blocks)
        for b, n in one.toggles.items():
            total.toggles[b] = total.toggles.get(b, 0) + n
            total.registers[b] = total.registers.get(b, 0) + one.registers[b]
        total.wire_toggles += one.wire_toggles
    return total
