"""The classifier top (``hdl.classifier.ClassifierTop``) in Amaranth's simulator: its tables loaded through
its load stream, then the observations, the results collected (what a host does); for the tests, which
hold it to its twin (``ClassifierMachine.run``), and the benchmarks' wall cycles."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from amaranth.sim import Simulator, SimulatorContext

from bayesmachine.classify.machine import ClassifierMachine
from bayesmachine.columns.energy import energy_codes
from bayesmachine.hdl.classifier import ClassifierTop, beat_layout
from bayesmachine.sim.results import MachineResult, decode_results

__all__ = ["TopRun", "load_beats", "run_beats", "run_classifier_top"]


@dataclass(frozen=True)
class TopRun:
    """The results and the clocks from the first observation taken to the last result."""

    result: MachineResult
    wall_cycles: int


def load_beats(machine: ClassifierMachine, bins: int, observed: np.ndarray) -> tuple[list[int], int]:
    """(raw load beats, how many are table rows): every memory's ``bins`` rows (rows past a feature's
    own bins 0), the prior's, then the observations."""
    t = machine.tables
    layout = beat_layout(t.classes, t.features, bins)
    beats = []
    for j, table in enumerate(t.likelihoods):
        codes = energy_codes(table)
        for b in range(bins):
            row = codes[:, b] if b < codes.shape[1] else np.zeros(t.classes, np.uint16)
            beats.append({"feature": j, "bin": b, "codes": row.tolist()})
    beats.append({"feature": t.features, "bin": 0, "codes": energy_codes(t.prior).tolist()})
    raw = [layout.const({"table": 1, "data": {"row": r}}).as_bits() for r in beats]
    raw += [layout.const({"table": 0, "data": {"bins": o.tolist()}}).as_bits() for o in np.asarray(observed)]
    return raw, len(beats)


def run_classifier_top(machine: ClassifierMachine, observed: np.ndarray, bins: int) -> TopRun:
    """``observed`` (n, features) bins through the top of ``machine`` (its fused layout, memories of
    ``bins`` rows), its tables loaded first, from reset."""
    beats, rows = load_beats(machine, bins, observed)
    top = ClassifierTop(params=machine.params, features=machine.tables.features, bins=bins)
    return run_beats(top, beats, len(beats) - rows, first=rows)


def run_beats(top: ClassifierTop, beats: list[int], decisions: int, first: int = 0) -> TopRun:
    """Raw load ``beats`` (table rows and observations in any order) through ``top`` from reset until
    ``decisions`` results came; the wall cycles counted from beat ``first`` taken."""
    results: list[int] = []
    clocks = {"first": 0, "now": 0}

    async def feed(ctx: SimulatorContext) -> None:
        for i, beat in enumerate(beats):
            ctx.set(top.load.valid, 1)
            ctx.set(top.load.payload.as_value(), beat)
            await ctx.tick().until(top.load.ready)
            if i == first:
                clocks["first"] = clocks["now"]
        ctx.set(top.load.valid, 0)

    async def collect(ctx: SimulatorContext) -> None:
        ctx.set(top.result.ready, 1)
        while len(results) < decisions:
            _, _, valid, payload = await ctx.tick().sample(top.result.valid, top.result.payload.as_value())
            clocks["now"] += 1
            if valid:
                results.append(payload)

    sim = Simulator(top)
    sim.add_clock(1e-8)
    sim.add_testbench(feed, background=True)
    sim.add_testbench(collect)
    sim.run()
    return TopRun(decode_results(top.params, results), clocks["now"] - clocks["first"])
