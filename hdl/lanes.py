"""Lanes of machines: k ``BayesianMachine`` side by side behind one load stream and one result stream.

Pixels are dealt round-robin: pixel i (counted from reset) goes to lane ``i % k``, and results come
out in pixel order (lane after lane), so the row of lanes is a drop-in for one machine with k times
the compute. Lane i is the machine of ``lane_params(params, i)`` (its own seed); the model twin
``bayesmachine.sim.lanes.LanesModel`` runs each lane's pixels through that lane's machine model.

Both streams have the single machine's layouts. The load stream carries one beat per cycle, so a
row of lanes needs ``lanes`` (words per beat) large enough to keep them all busy: with runs of
about R cycles, k lanes need ``beats_per_pixel <= R / k``.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal
from amaranth.lib import wiring

from bayesmachine.params import MachineParams, ParameterError, lane_params
from bayesmachine.sources import source_kind

from .machine import BayesianMachine
from .signatures import MachineSignature

__all__ = ["MachineLanes"]


class MachineLanes(wiring.Component):
    """``machines`` machines of ``params`` (seeds per :func:`lane_params`), pixels dealt round-robin.

    Parameters
    ----------
    params : MachineParams
        The machines' parameters (lane i's seed from :func:`lane_params`); an on-chip source.
    machines : int
        k, the machines side by side (1 .. 256).

    Attributes
    ----------
    load, result
        As ``BayesianMachine``'s (:class:`~.signatures.MachineSignature`): pixel i's words go to
        lane ``i % k``, results come out in pixel order.
    """

    def __init__(self, *, params: MachineParams, machines: int) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"MachineLanes takes a MachineParams, not {type(params).__name__}")
        if isinstance(machines, bool) or not isinstance(machines, int):
            raise TypeError(f"machines must be an integer, not {type(machines).__name__}")
        if not 1 <= machines <= 256:
            raise ParameterError(f"machines must be an integer in [1, 256], got {machines!r}")
        if not source_kind(params.rng).on_chip:
            raise ParameterError(f"lanes of machines need an on-chip random source, not {params.rng!r}")
        if params.feedback_columns:
            # Round-robin lanes: each lane's previous result is pixel i - k's, not the left neighbour's.
            raise ParameterError(
                f"prior = 'neighbour' cannot run on lanes of machines: pixels are dealt round-robin, so each "
                f"lane's feedback column would come from pixel i - {machines}, not the left neighbour "
                f"(use one machine, or prior = 'loaded')")
        self._params = params
        self._machines = machines
        super().__init__(MachineSignature(params))

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def machines(self) -> int:
        return self._machines

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p, k = self._params, self._machines
        lanes = [BayesianMachine(params=lane_params(p, i)) for i in range(k)]
        for i, lane in enumerate(lanes):
            m.submodules[f"machine_{i}"] = lane

        # --- Load: beats go to lane ``dest`` (one-hot) until its pixel is complete ---
        dest = Signal(k, init=1)
        beat = Signal(range(max(2, p.beats_per_pixel)))
        for i, lane in enumerate(lanes):
            m.d.comb += [lane.load.payload.eq(self.load.payload),
                         lane.load.valid.eq(self.load.valid & dest[i])]
        m.d.comb += self.load.ready.eq((Cat(lane.load.ready for lane in lanes) & dest).any())
        with m.If(self.load.valid & self.load.ready):
            with m.If(beat == p.beats_per_pixel - 1):
                m.d.sync += [beat.eq(0), dest.eq(dest.rotate_left(1))]
            with m.Else():
                m.d.sync += beat.eq(beat + 1)

        # --- Result: lane ``src`` (one-hot) hands over the next result in pixel order ---
        src = Signal(k, init=1)
        valid = Cat(lane.result.valid for lane in lanes) & src
        m.d.comb += self.result.valid.eq(valid.any())
        payload = Const(0, len(self.result.payload.as_value()))
        for i, lane in enumerate(lanes):
            m.d.comb += lane.result.ready.eq(self.result.ready & src[i])
            raw = lane.result.payload.as_value()
            payload = payload | (raw & src[i].replicate(len(raw)))
        m.d.comb += self.result.payload.eq(payload)
        with m.If(self.result.valid & self.result.ready):
            m.d.sync += src.eq(src.rotate_left(1))
        return m
