"""The ``pysim`` engine: the RTL (``BayesianMachine``) in Amaranth's Python simulator.

``PysimEngine(params).run(words)`` streams the pixels' likelihood memories into the load
stream and collects the result stream, with loads overlapping runs (the shadow memory fills
while the active one computes), exactly as a host would drive the hardware. One simulator
lives as long as the engine: the LFSR states (and the cycle count) carry over from one
``run`` call to the next, like :class:`~bayesmachine.sim.model.MachineModel`, so a frame can
be run in chunks. Between calls the simulation just stops advancing; the machine is idle
(no compute cycles), so nothing changes.

Throughput is a few hundred to a few thousand cycles per second depending on the machine size
(about 1,000-1,500/s for the full Dmax = 80 machine on a 2-core machine): crops and tests,
not whole frames.
"""

from __future__ import annotations

import random
from collections import deque

import numpy as np
from amaranth.sim import Simulator, SimulatorContext

from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.params import MachineParams
from bayesmachine.sim.model import MachineResult, check_words
from bayesmachine.sim.testbench import pack_beats, pack_numbers, unpack_result

__all__ = ["PysimEngine"]


class PysimEngine:
    """Run the RTL in Amaranth's simulator; same interface as ``MachineModel``.

    ``load_stall`` / ``result_stall``: probability that the testbench drops ``load.valid`` /
    ``result.ready`` in a given cycle (random back-pressure from ``stall_seed``), to exercise
    the handshakes; results do not depend on them. ``vcd``: write a waveform file.
    ``patience``: clock cycles to wait for the next result before giving up with an error
    (a run of up to ``max_cycles`` cycles would otherwise look like a hang: the simulator takes
    minutes per 100 000 cycles of the full machine).
    """

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
        for name, v in (("load_stall", load_stall), ("result_stall", result_stall)):
            if not 0.0 <= v < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {v}")
        self.params = params
        self._load_stall = load_stall
        self._result_stall = result_stall
        if patience < 1:
            raise ValueError(f"patience must be a positive number of cycles, got {patience}")
        self._patience = patience
        self._stall_seed = stall_seed
        self._vcd = vcd
        self.dut = BayesianMachine(params)
        self._vcd_ctx = None
        self._build()

    def _build(self) -> None:
        """A fresh simulator: the machine as after a hardware reset."""
        self._rnd = random.Random(self._stall_seed)
        self._beats: deque[int] = deque()
        self._raw_results: list[int] = []
        self._numbers: np.ndarray | None = None
        self._t = 0  # next row of self._numbers
        self._starved = False
        self._broken = False  # a run was cut short: pixels in flight would shift later results
        self.clock_cycles = 0  # clock cycles simulated so far (idle, load and compute)
        self.compute_cycles = 0  # compute cycles of the pixels returned so far
        self._sim = Simulator(self.dut)
        self._sim.add_clock(1e-8)
        self._sim.add_testbench(self._feeder, background=True)
        self._sim.add_testbench(self._collector, background=True)
        if self.params.rng == "external":
            self._sim.add_testbench(self._entropy_source, background=True)
        if self._vcd is not None:
            self._vcd_ctx = self._sim.write_vcd(self._vcd)
            self._vcd_ctx.__enter__()

    def reset(self) -> None:
        """Start again from a hardware reset (after a failed run, for instance)."""
        self.close()
        self._build()

    def close(self) -> None:
        if self._vcd_ctx is not None:
            self._vcd_ctx.__exit__(None, None, None)
            self._vcd_ctx = None

    @property
    def wall_cycles(self) -> int:
        """Clock cycles simulated so far: loading, computing and idle cycles alike."""
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
        dut = self.dut
        raw_entropy = dut.entropy.as_value()
        while True:
            nums = self._numbers
            if nums is not None and self._t < len(nums):
                ctx.set(raw_entropy, pack_numbers(self.params, nums[self._t]))
            _, _, taken = await ctx.tick().sample(dut.entropy_ready)
            if taken:  # a compute cycle consumed numbers[t]
                if nums is None or self._t >= len(nums):
                    self._starved = True
                self._t += 1

    # --- Engine interface ---

    def run(self, words: np.ndarray, numbers: np.ndarray | None = None) -> MachineResult:
        """Run pixels through the RTL; same arguments and result as ``MachineModel.run``."""
        p = self.params
        q = check_words(p, words)
        if self._broken:
            raise RuntimeError("pysim: an earlier run failed, so pixels are still in flight and later "
                               "results would not match; call reset() to start again from a hardware reset")
        if p.rng == "external":
            if numbers is None:
                raise ValueError("rng = 'external': pass the random numbers of every compute cycle")
            nums = np.asarray(numbers)
            if nums.ndim != 2 or nums.shape[1] != p.operators:
                raise ValueError(f"random numbers must have shape (cycles, {p.operators}), got {nums.shape}")
            self._numbers, self._t, self._starved = nums, 0, False
        elif numbers is not None:
            raise ValueError("random numbers are only taken with rng = 'external'")
        first = len(self._raw_results)
        for pixel in q:
            self._beats.extend(pack_beats(p, pixel))
        target = first + len(q)
        last_count, last_clock = len(self._raw_results), self.clock_cycles
        self._broken = True  # until every pixel of this call is back
        while len(self._raw_results) < target:
            self._sim.advance()
            if len(self._raw_results) != last_count:
                last_count, last_clock = len(self._raw_results), self.clock_cycles
            elif self.clock_cycles - last_clock > self._patience:
                raise RuntimeError(
                    f"pysim: no result for {self._patience} clock cycles (this machine's watchdog "
                    f"allows runs of up to max_cycles = {p.max_cycles}); lower max_cycles, raise "
                    f"patience, or use the model or verilator engine for long runs"
                )
            if self._starved:
                raise ValueError(
                    f"the {len(self._numbers)} cycles of random numbers ran out before the run ended"
                )
        self._broken = False
        raws = self._raw_results[first:target]
        out = MachineResult.empty(p.rows)
        if raws:
            fields = [unpack_result(p, r) for r in raws]
            out = MachineResult(
                np.array([f[4] for f in fields], np.uint32).reshape(len(raws), p.rows),
                np.array([f[0] for f in fields], np.int32),
                np.array([f[1] for f in fields], bool),
                np.array([f[2] for f in fields], bool),
                np.array([f[3] for f in fields], np.int64),
            )
            self.compute_cycles += int(out.cycles.sum())
        return out
