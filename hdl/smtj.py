"""A synthesizable SMTJ emulator: the SMTJ devices of an ``rng = "smtj"`` machine as digital logic.

Each device is a two-state Markov chain (one state flip-flop) driven by its own xorshift32
generator: on each cycle ``advance`` is high, the generator steps and the device flips when the
top 16 bits of the new value are below its state's flip threshold, the device's per-cycle
P(s -> not s) rounded to 1/65536 (``bayesmachine.sources.smtj.SMTJEmulatorSpec``: the same dwell,
spread and seed as the device model). ``numbers`` packs the states into each operator's W-bit
number as ``SMTJSource`` does. The Python twin is ``SMTJEmulatorTwin``; ``tests/sources/test_smtj.py``
holds this RTL to it.

``SMTJEmulatedMachine`` puts it in front of a machine's ``entropy`` port, so that the SMTJ
machine runs on an FPGA: W devices per column (``smtj_share = "column"``) cost 30 x (32 + 1)
flip-flops for Dmax = 80; W per operator, 2,460 x 33.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources.smtj import EMULATOR_RANDOM_BITS, SMTJEmulatorSpec

from .machine import BayesianMachine
from .signatures import MachineSignature, entropy_layout

__all__ = ["SMTJEmulatedMachine", "SMTJEmulator"]


def _xorshift32_expr(x: Signal) -> object:
    a = x ^ (x << 13)[:32]
    b = a ^ (a >> 17)
    return b ^ (b << 5)[:32]


class SMTJEmulator(wiring.Component):
    """The SMTJ devices of ``params`` (``rng = "smtj"``) emulated on chip.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (``rng = "smtj"``: dwell, spread, sharing, seed).

    Attributes
    ----------
    numbers : ``Out(entropy_layout(params))``
        This cycle's number of every operator.
    advance : ``In(1)``
        The devices step at the clock edge.
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"SMTJEmulator takes a MachineParams, not {type(params).__name__}")
        if params.rng != "smtj":
            raise ParameterError(f"SMTJEmulator needs rng = 'smtj', got {params.rng!r}")
        self._params = params
        self._spec = SMTJEmulatorSpec(params)
        super().__init__({
            "numbers": Out(entropy_layout(params)),
            "advance": In(1),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def spec(self) -> SMTJEmulatorSpec:
        return self._spec

    def elaborate(self, platform: object) -> Module:
        m = Module()
        spec = self._spec
        top = EMULATOR_RANDOM_BITS
        states = []
        for d in range(spec.devices):
            s = Signal(init=int(spec.init_state[d]), name=f"smtj_{d}")
            x = Signal(32, init=int(spec.init_x[d]), name=f"smtj_x_{d}")
            t0, t1 = (int(v) for v in spec.thresholds[d])
            nx = Signal(32, name=f"smtj_nx_{d}")
            m.d.comb += nx.eq(_xorshift32_expr(x))
            with m.If(self.advance):
                m.d.sync += [x.eq(nx), s.eq(s ^ (nx[32 - top :] < Mux(s, t1, t0)))]
            states.append(s)
        for o, devs in enumerate(spec.index):
            m.d.comb += self.numbers[o].eq(Cat(*(states[int(d)] for d in devs)))
        return m


class SMTJEmulatedMachine(wiring.Component):
    """``BayesianMachine(params=params)`` (``rng = "smtj"``) with its entropy port driven by the emulator.

    The emulator advances on the machine's compute cycles (``entropy_ready``), so it gives the
    numbers of ``SMTJEmulatorTwin(params)``, row by row, to the machine model.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (``rng = "smtj"``).

    Attributes
    ----------
    load, result
        As ``BayesianMachine``'s (``MachineSignature(params, entropy=False)``: the numbers are
        made on chip).
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"SMTJEmulatedMachine takes a MachineParams, not {type(params).__name__}")
        if params.rng != "smtj":
            raise ParameterError(f"SMTJEmulatedMachine needs rng = 'smtj', got {params.rng!r}")
        self._params = params
        super().__init__(MachineSignature(params, entropy=False))

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        m = Module()
        m.submodules.machine = machine = BayesianMachine(params=self._params)
        m.submodules.emulator = emulator = SMTJEmulator(params=self._params)
        wiring.connect(m, wiring.flipped(self.load), machine.load)
        wiring.connect(m, machine.result, wiring.flipped(self.result))
        m.d.comb += [machine.entropy.eq(emulator.numbers), emulator.advance.eq(machine.entropy_ready)]
        return m
