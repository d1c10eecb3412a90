"""The ``pysim`` engine: the RTL (``BayesianMachine``) in Amaranth's Python simulator.

``PysimEngine(params).run(words)`` streams the pixels' likelihood memories into the load
stream and collects the result stream, with loads overlapping runs (the shadow memory fills
while the active one computes), exactly as a host would drive the hardware. One simulator
lives as long as the engine: the LFSR states (and the cycle count) carry over from one
``run`` call to the next, like :class:`~bayesmachine.sim.model.MachineModel`, so a frame can
be run in chunks. Between calls the simulation just stops advancing; the machine is idle
(no compute cycles), so nothing changes.

Throughput falls with the machine's size: about 100 clock cycles per CPU second for the full
Dmax = 80 machine, a few thousand for a Dmax = 8 one (``benchmarks/bench_pysim.py``): crops and
tests, not whole frames.
"""

from __future__ import annotations

import random
from collections import deque

import numpy as np
from amaranth.sim import Simulator, SimulatorContext

from bayesmachine.hdl.machines import machine_top
from bayesmachine.params import MachineParams
from bayesmachine.sim.engines import EngineBase
from bayesmachine.sim.packing import pack_beats, pack_numbers
from bayesmachine.sim.results import MachineResult, NumberFeed, decode_results, ran_out_error

__all__ = ["PysimEngine"]

_PREFETCH = 64  # compute cycles of random numbers packed at a time


class PysimEngine(EngineBase):
    """Run the RTL in Amaranth's simulator; the engines' contract (see :mod:`bayesmachine.sim.engines`).

    ``load_stall`` / ``result_stall``: probability that the testbench drops ``load.valid`` /
    ``result.ready`` in a given cycle (random back-pressure from ``stall_seed``), to exercise
    the handshakes; results do not depend on them. ``vcd``: write a waveform file.
    ``patience``: clock cycles to wait for the next result before giving up with an error
    (a run of up to ``max_cycles`` cycles would otherwise look like a hang: the simulator takes
    minutes per 100 000 cycles of the full machine).
    """

    name = "pysim"
    FEEDBACK = True
    OPTIONS = ("load_stall", "result_stall", "stall_seed", "vcd", "patience")

    def __init__(
        self,
        params: MachineParams,
        *,
        load_stall: float = 0.0,
        result_stall: float = 0.0,
        stall_seed: int = 0,
        vcd: str | None = None,
        patience: int = 200_000,
    ) -> None:
        super().__init__(params)
        for name, v in (("load_stall", load_stall), ("result_stall", result_stall)):
            if not 0.0 <= v < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {v}")
        if patience < 1:
            raise ValueError(f"patience must be a positive number of cycles, got {patience}")
        self._load_stall = load_stall
        self._result_stall = result_stall
        self._patience = patience
        self._stall_seed = stall_seed
        self._vcd = vcd
        self._vcd_ctx = None
        self._build()

    def _build(self) -> None:
        """A fresh simulator: the machine as after a hardware reset."""
        self._rnd = random.Random(self._stall_seed)
        self._beats: deque[int] = deque()
        self._raw_results: list[int] = []
        self._entropy_feed: NumberFeed | None = None
        self._entropy_raw: deque[int] = deque()  # packed rows fetched from the feed, not yet consumed
        self._starved = False
        self.clock_cycles = 0  # clock cycles simulated so far (idle, load and compute)
        self.compute_cycles = 0  # compute cycles of the pixels returned so far
        self._sim: Simulator | None = None  # made by the first run (an engine never run makes none)

    def _simulator(self) -> Simulator:
        if self._sim is None:
            self.dut = machine_top(self.params)
            self._sim = Simulator(self.dut)
            self._sim.add_clock(1e-8)
            self._sim.add_testbench(self._feeder, background=True)
            self._sim.add_testbench(self._collector, background=True)
            if "entropy" in self.dut.signature.members:
                self._sim.add_testbench(self._entropy_source, background=True)
            if self._vcd is not None:
                self._vcd_ctx = self._sim.write_vcd(self._vcd)
                self._vcd_ctx.__enter__()
        return self._sim

    def _reset(self) -> None:
        self._close()
        self._build()

    def _close(self) -> None:
        if self._vcd_ctx is not None:
            self._vcd_ctx.__exit__(None, None, None)
            self._vcd_ctx = None

    @property
    def wall_cycles(self) -> int:
        """Clock cycles simulated since reset: loading, computing and idle cycles alike."""
        return self.clock_cycles

    # --- Testbench processes (they run forever; run() advances the simulation) ---

    async def _feeder(self, ctx: SimulatorContext) -> None:
        load = self.dut.load
        raw_payload = load.payload.as_value()
        while True:
            if not self._beats or (self._load_stall and self._rnd.random() < self._load_stall):
                ctx.set(load.valid, 0)
                await ctx.tick()
                continue
            # Once offered, a beat stays valid until the machine takes it (stream rules).
            ctx.set(load.valid, 1)
            ctx.set(raw_payload, self._beats[0])
            while True:
                _, _, ready = await ctx.tick().sample(load.ready)
                if ready:
                    self._beats.popleft()
                    break

    async def _collector(self, ctx: SimulatorContext) -> None:
        res = self.dut.result
        raw_payload = res.payload.as_value()
        while True:
            ready = not (self._result_stall and self._rnd.random() < self._result_stall)
            ctx.set(res.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(res.valid, raw_payload)
            self.clock_cycles += 1
            if valid and ready:
                self._raw_results.append(payload)

    async def _entropy_source(self, ctx: SimulatorContext) -> None:
        """Presents the next row of numbers; a compute cycle (``entropy_ready``) consumes it."""
        dut = self.dut
        raw_entropy = dut.entropy.as_value()
        layout = dut.entropy.shape()
        while True:
            feed = self._entropy_feed
            if not self._entropy_raw and feed is not None:
                self._entropy_raw.extend(pack_numbers(self.params, layout, feed.take_clocks(_PREFETCH)))
            if self._entropy_raw:
                ctx.set(raw_entropy, self._entropy_raw[0])
            _, _, taken = await ctx.tick().sample(dut.entropy_ready)
            if taken:
                if self._entropy_raw:
                    self._entropy_raw.popleft()
                else:
                    self._starved = True

    # --- Engine interface ---

    def _run_feedback(self, q: np.ndarray, feed: NumberFeed | None, line_start: np.ndarray) -> MachineResult:
        return self._run(q, feed, line_start)

    def _run(self, q: np.ndarray, feed: NumberFeed | None,
             line_start: np.ndarray | None = None) -> MachineResult:
        p = self.params
        if self._new_supply:
            # Rows prefetched from another source are dropped; the machine is idle between
            # calls, so none of them is on the port of a compute cycle.
            self._entropy_raw.clear()
        self._entropy_feed = feed
        first = len(self._raw_results)
        self._beats.extend(pack_beats(p, q, line_start))
        target = first + len(q)
        last_count, last_clock = len(self._raw_results), self.clock_cycles
        sim = self._simulator()
        while len(self._raw_results) < target:
            sim.advance()
            if len(self._raw_results) != last_count:
                last_count, last_clock = len(self._raw_results), self.clock_cycles
            elif self.clock_cycles - last_clock > self._patience:
                raise RuntimeError(
                    f"pysim: no result for {self._patience} clock cycles (this machine's watchdog "
                    f"allows runs of up to max_cycles = {p.max_cycles}); lower max_cycles, raise "
                    f"patience, or use the model or verilator engine for long runs"
                )
            if self._starved:
                raise ran_out_error(feed.source if feed is not None else None)
        out = decode_results(p, self._raw_results[first:target])
        self.compute_cycles += int(out.cycles.sum())
        return out
