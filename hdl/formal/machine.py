# amaranth: UnusedElaboratable=no
"""Properties of a small ``BayesianMachine`` seen from its ports (and its documented MAP encoder
submodule): the result stream, the watchdog, the fields of a result, and one result per run.

The machine under check has an off-chip source (``rng = "external"``), so the random numbers are a
free input like the load stream and ``result.ready``: the solver plays every environment and
every sequence of numbers, which covers every stochastic bus an on-chip source could make.
Only the load stream's own rule is assumed (a source holds ``valid`` and its payload until
``ready``: ``amaranth.lib.stream``); ``result.ready`` and the numbers are unconstrained, and the
reset is a free input too (a reset at any cycle is part of the environment).
"""

from __future__ import annotations

from collections.abc import Callable

from amaranth.hdl import Assert, Assume, Cover, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.machine import BayesianMachine, MAPEncoder
from bayesmachine.hdl.signatures import entropy_layout, load_layout, result_layout
from bayesmachine.params import MachineParams
from bayesmachine.sources import source_kind

__all__ = ["CHECKS", "MachineFactory", "MachineProperties"]

CHECKS = ("stream", "watchdog", "result", "runs")
MachineFactory = Callable[..., wiring.Component]


class MachineProperties(wiring.Component):
    """A formal-only wrapper: a machine with free inputs, its port properties and covers.

    Parameters
    ----------
    params : MachineParams
        The machine the properties describe (an off-chip ``rng``: ``external``).
    checks : tuple of str
        Which groups of assertions to include (``CHECKS``): ``stream`` (the result stream rule),
        ``watchdog`` (cycles and timeout), ``result`` (the fields of a result agree), ``runs`` (the
        compute cycles seen on ``entropy_ready`` against the results' ``cycles``). One group per
        run lets a group that closes by induction be proved apart from one checked to a depth.
    machine : callable
        Builds the machine under check from a ``params`` keyword; ``BayesianMachine`` unless a
        mutant is being checked.
    dut_params : MachineParams or None
        The parameters the machine is built with (default ``params``); a mutant may differ (an
        off-by-one watchdog), with the same port widths.

    Attributes
    ----------
    load_valid, load_payload, result_ready, entropy : ``In``
        The environment (free).
    result_valid, result_payload : ``Out``
        The machine's result stream, for the trace.
    """

    def __init__(self, *, params: MachineParams, checks: tuple[str, ...] = CHECKS,
                 machine: MachineFactory = BayesianMachine, dut_params: MachineParams | None = None) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"params must be a MachineParams, not {type(params).__name__}")
        if source_kind(params.rng).on_chip:
            raise ValueError(f"the formal machine takes its numbers on a port (rng 'external'), "
                             f"not {params.rng!r}")
        if params.feedback_columns:
            raise ValueError("the formal machine has no neighbour prior")
        bad = [c for c in checks if c not in CHECKS]
        if bad or not checks:
            raise ValueError(f"checks must be a non-empty subset of {CHECKS}, got {checks!r}")
        dut_params = params if dut_params is None else dut_params
        if result_layout(dut_params).size != result_layout(params).size:
            raise ValueError("dut_params must keep the result's width")
        self._params = params
        self._checks = tuple(checks)
        self._dut = machine(params=dut_params)
        super().__init__({
            "load_valid": In(1), "load_payload": In(load_layout(params)), "result_ready": In(1),
            "entropy": In(entropy_layout(params)),
            "result_valid": Out(1), "result_payload": Out(result_layout(params)),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        m = Module()
        dut = self._dut
        # Built here so that the properties can watch the MAP encoder it instantiates (its nets' encoder).
        m.submodules.dut, nets = dut.build(platform)
        m.d.comb += [
            dut.load.valid.eq(self.load_valid), dut.load.payload.eq(self.load_payload),
            dut.result.ready.eq(self.result_ready), dut.entropy.eq(self.entropy),
            self.result_valid.eq(dut.result.valid), self.result_payload.eq(dut.result.payload),
        ]
        self._load_rule(m, dut.load.ready)
        stall = self._stream(m)
        if "watchdog" in self._checks:
            self._watchdog(m)
        if "result" in self._checks:
            self._result_fields(m)
        if "runs" in self._checks:
            taken = self.result_valid & self.result_ready
            self._runs(m, dut.entropy_ready, taken, self.result_payload.cycles)
        rise, enc_tie = self._encoder_choice(m, nets.encoder)
        self._covers(m, stall, rise, enc_tie)
        return m

    def _load_rule(self, m: Module, ready: Signal) -> None:
        """The environment: the load stream's source follows the stream rule (and nothing more)."""
        load_stall = Signal()
        load_prev = Signal.like(self.load_payload)
        m.d.sync += [load_stall.eq(self.load_valid & ~ready), load_prev.eq(self.load_payload)]
        with m.If(load_stall):
            m.d.comb += Assume(self.load_valid & (self.load_payload.as_value() == load_prev.as_value()))

    def _stream(self, m: Module) -> Signal:
        """``stream``: a result offered and not taken is offered again in the next cycle, unchanged:
        back-pressure never drops, changes or loses a result (the stream rule, from the source side).
        Returns the stall flag (a result was offered and not taken in the cycle before)."""
        valid, ready, res = self.result_valid, self.result_ready, self.result_payload
        stall = Signal()
        prev = Signal.like(res)
        m.d.sync += [stall.eq(valid & ~ready), prev.eq(res)]
        if "stream" in self._checks:
            with m.If(stall):
                m.d.comb += Assert(valid, "result.valid held until ready")
                m.d.comb += Assert(res.as_value() == prev.as_value(), "result payload stable until ready")
        return stall

    def _watchdog(self, m: Module) -> None:
        """``watchdog``: a run counts 1 to max_cycles compute cycles, never more, and a timeout is
        reported only by a run that reached max_cycles (and then map is 0)."""
        p, res = self._params, self.result_payload
        with m.If(self.result_valid):
            m.d.comb += Assert((res.cycles >= 1) & (res.cycles <= p.max_cycles), "1 <= cycles <= max_cycles")
            with m.If(res.timeout):
                m.d.comb += Assert(res.cycles == p.max_cycles, "timeout only at max_cycles")
                m.d.comb += Assert(res.map == 0, "a timeout reports map 0")

    def _result_fields(self, m: Module) -> None:
        """``result``: a result's fields agree: the counters never pass n_max, the winning row holds
        n_max (it overflowed), and nomatch says the no-match row won."""
        p, res = self._params, self.result_payload
        with m.If(self.result_valid):
            for r in range(p.rows):
                m.d.comb += Assert(res.counts[r] <= p.counter_max, f"count {r} <= counter max")
                m.d.comb += Assert(res.timeout | (res.map != r) | (res.counts[r] == p.counter_max),
                                   f"the winner {r} holds counter max")
            m.d.comb += Assert(res.map < p.rows, "map names a row")
            nomatch = (~res.timeout & (res.map == p.rows - 1)) if p.nomatch_row else 0
            m.d.comb += Assert(res.nomatch == nomatch, "nomatch iff the no-match row won")

    def _encoder_choice(self, m: Module, encoder: MAPEncoder) -> tuple[Value, Signal]:
        """A new result (valid rises: a handshake always leaves a cycle without one) was taken in the
        cycle before from the MAP encoder's outputs on the registered overflow flags of the run's
        last compute cycle: keep those outputs a cycle. With ``result``: the result is the encoder's
        choice at the stop (so the machine reports ties by the tie rule proved of the encoder), a
        timeout exactly when no row overflowed. Returns (the rise, a tie of the no-match row then)."""
        p, valid, res = self._params, self.result_valid, self.result_payload
        last = p.rows - 1
        was_valid = Signal()
        enc_valid, enc_index, enc_tie = Signal(), Signal.like(encoder.index), Signal()
        tie = encoder.over[last] & encoder.over[:last].any()
        m.d.sync += [was_valid.eq(valid), enc_valid.eq(encoder.valid), enc_index.eq(encoder.index),
                     enc_tie.eq(tie)]
        rise = valid & ~was_valid
        if "result" in self._checks:
            with m.If(rise):
                m.d.comb += Assert(res.timeout == ~enc_valid, "timeout iff no row overflowed at the stop")
                with m.If(~res.timeout):
                    m.d.comb += Assert(res.map == enc_index, "map is the MAP encoder's choice")
            if p.nomatch_row:
                # The machine's tie rule is the one its parameters name: a tie of the no-match row
                # with a disparity row is no match under nomatch-first, the disparity otherwise.
                with m.If(rise & enc_tie):
                    m.d.comb += Assert(res.nomatch == (p.tie_break == "nomatch-first"),
                                       "the machine's tie rule")
        return rise, enc_tie

    def _covers(self, m: Module, stall: Signal, rise: Value, enc_tie: Signal) -> None:
        """Not vacuous: a timeout, a stalled result, a result from a tie of the no-match row with a
        disparity row (reported as no match under nomatch-first, as the disparity under
        lowest-index), and two results taken."""
        p, valid, res = self._params, self.result_valid, self.result_payload
        m.d.comb += Cover(valid & res.timeout)
        m.d.comb += Cover(stall & valid & ~res.timeout)
        if p.nomatch_row:
            nomatch_wins = p.tie_break == "nomatch-first"
            m.d.comb += Cover(rise & enc_tie & (res.nomatch if nomatch_wins else ~res.nomatch & ~res.timeout))
        taken = Signal(2)
        with m.If(valid & self.result_ready & (taken != 3)):
            m.d.sync += taken.eq(taken + 1)
        m.d.comb += Cover(taken == 2)

    def _runs(self, m: Module, compute: Signal, taken: Signal, cycles: Signal) -> None:
        """A run's compute cycles are a burst of ``entropy_ready`` (the port is high on compute
        cycles, and every run ends with a bubble): the wrapper measures each burst, queues its
        length and checks it against the ``cycles`` of the result taken next."""
        p = self._params
        mc = p.max_cycles
        burst = Signal(range(mc + 2))  # compute cycles of the current burst, saturating past max_cycles
        was = Signal()
        m.d.sync += was.eq(compute)
        with m.If(compute):
            m.d.sync += burst.eq(Mux(burst > mc, burst, burst + 1))
        with m.Else():
            m.d.sync += burst.eq(0)
        # The watchdog stops every run at max_cycles compute cycles at the latest, whatever the numbers.
        m.d.comb += Assert(burst <= mc, "no run computes past max_cycles")
        # The finished runs whose results are not taken yet: one in the result register, one whose
        # bubble waits for it (compute cycles never wait for back-pressure).
        q0, q1 = Signal.like(burst), Signal.like(burst)
        pending = Signal(range(4))
        push = was & ~compute
        m.d.comb += Assert(pending <= 2, "at most two finished runs wait for the result stream")
        with m.If(taken):
            # One result per run, in order: a result is taken only after its run, with its length.
            m.d.comb += Assert(pending >= 1, "no result without a run")
            m.d.comb += Assert(cycles == q0, "a result's cycles are its run's compute cycles")
        with m.If(push & ~taken):
            m.d.sync += pending.eq(pending + 1)
            with m.If(pending == 0):
                m.d.sync += q0.eq(burst)
            with m.Else():
                m.d.sync += q1.eq(burst)
        with m.Elif(taken & ~push):
            m.d.sync += [pending.eq(pending - 1), q0.eq(q1)]
        with m.Elif(taken & push):
            with m.If(pending == 1):
                m.d.sync += q0.eq(burst)
            with m.Else():
                m.d.sync += [q0.eq(q1), q1.eq(burst)]
