"""K machines: k machines of one integrator (``BayesianMachine``, or ``LogMachine``) side by side behind
one load stream and one result stream.

Pixels are dealt round-robin: pixel i (counted from reset) goes to machine ``i % k``, and results
come out in pixel order (machine after machine), so the k machines are a drop-in for one machine
with k times the compute. Machine i is the machine of ``nth_machine(params, i)`` (its own seed); the
model twin ``bayesmachine.sim.machines.ParallelMachinesModel`` runs each machine's pixels through
that machine's model (its integrator kind's).

Both streams have the single machine's layouts. The load stream carries one beat per cycle, so k
machines need ``words_per_beat`` large enough to keep them all busy: with runs of about R cycles,
k machines need ``beats_per_pixel <= R / k``.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal
from amaranth.lib import wiring

from bayesmachine.checks import as_int
from bayesmachine.params import MachineParams, ParameterError, nth_machine

from .signatures import MachineSignature

__all__ = ["ParallelMachines", "machine_top"]


def machine_top(params: MachineParams) -> wiring.Component:
    """The one machine of ``params``: its integrator kind's top (``BayesianMachine``; with ``integrator =
    "log"`` the logarithmic one, ``hdl.log.machine.LogMachine``), both with the machine's ports."""
    if not isinstance(params, MachineParams):
        raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
    return params.kind.machine_top(params)  # type: ignore[return-value]


class ParallelMachines(wiring.Component):
    """``machines`` machines of ``params`` (seeds per :func:`nth_machine`), pixels dealt round-robin.

    Parameters
    ----------
    params : MachineParams
        The machines' parameters (machine i's seed from :func:`nth_machine`); an on-chip source.
    machines : int
        k, the machines side by side (1 .. 256).

    Attributes
    ----------
    load, result
        As ``BayesianMachine``'s (:class:`~.signatures.MachineSignature`): pixel i's words go to
        machine ``i % k``, results come out in pixel order.
    """

    def __init__(self, *, params: MachineParams, machines: int) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"ParallelMachines takes a MachineParams, not {type(params).__name__}")
        machines = as_int("machines", machines, 1, 256)
        if params.takes_numbers:
            raise ParameterError(f"K machines need an on-chip random source, not {params.rng!r}")
        if params.feedback_columns:
            # Round-robin: each machine's previous result is pixel i - k's, not the left neighbour's.
            raise ParameterError(
                f"prior = 'neighbour' cannot run on K machines dealt pixels round-robin: each "
                f"machine's feedback column would come from pixel i - {machines}, not the left neighbour "
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
        machines = [machine_top(nth_machine(p, i)) for i in range(k)]
        for i, machine in enumerate(machines):
            m.submodules[f"machine_{i}"] = machine

        # --- Load: beats go to machine ``dest`` (one-hot) until its pixel is complete ---
        dest = Signal(k, init=1)
        beat = Signal(range(max(2, p.beats_per_pixel)))
        for i, machine in enumerate(machines):
            m.d.comb += [machine.load.payload.eq(self.load.payload),
                         machine.load.valid.eq(self.load.valid & dest[i])]
        m.d.comb += self.load.ready.eq((Cat(machine.load.ready for machine in machines) & dest).any())
        with m.If(self.load.valid & self.load.ready):
            with m.If(beat == p.beats_per_pixel - 1):
                m.d.sync += [beat.eq(0), dest.eq(dest.rotate_left(1))]
            with m.Else():
                m.d.sync += beat.eq(beat + 1)

        # --- Result: machine ``src`` (one-hot) hands over the next result in pixel order ---
        src = Signal(k, init=1)
        valid = Cat(machine.result.valid for machine in machines) & src
        m.d.comb += self.result.valid.eq(valid.any())
        payload = Const(0, len(self.result.payload.as_value()))
        for i, machine in enumerate(machines):
            m.d.comb += machine.result.ready.eq(self.result.ready & src[i])
            raw = machine.result.payload.as_value()
            payload = payload | (raw & src[i].replicate(len(raw)))
        m.d.comb += self.result.payload.eq(payload)
        with m.If(self.result.valid & self.result.ready):
            m.d.sync += src.eq(src.rotate_left(1))
        return m
