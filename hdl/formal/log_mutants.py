"""Known bugs of the log blocks, built next to the shipped RTL (never in it), that ``PipelineProperties``
must catch (``tests/hdl/formal/test_log.py`` asserts each proof fails on them).

- argmin nodes: ties to the higher index; an excluded right candidate allowed to win;
- the pipeline (mixins over any block): a held result dropped; a phantom pixel entering a stalled
  pipeline; a held result overwritten by the pixel behind it;
- the integrator (``LogIntegrator``, against ``IntegratorProperties``): its weights stage overwriting a
  held result; a pixel issued before the previous MAP is known (its feedback codes from an older one);
- built with other parameters than the reference follows: the other tie rule, another exp table.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from amaranth.hdl import Const, Module, Mux, Value

from bayesmachine.hdl.log import ArgminTree, LogIntegrator, LogParams, WeightStage
from bayesmachine.hdl.log.argmin import Node
from bayesmachine.hdl.log.pipeline import PipelineNets, StallPipeline, Wire

__all__ = ["DropsHeld", "EarlyIssueIntegrator", "LOG_MUTANTS", "LogMutant", "OverwritesHeld",
           "OverwritesHeldIntegrator", "PhantomPixel", "TieRightArgmin", "ExcludedWinsArgmin", "other_table",
           "other_tie_rule"]


def _node(left: Node, right: Node, wire: Wire, name: str, right_wins: Value) -> Node:
    (lk, li, lx), (rk, ri, rx) = left, right
    right_wins = wire(right_wins, f"{name}_right")
    low = tuple(Mux(right_wins, r, lo) for lo, r in zip(li, ri, strict=True))
    return wire(Mux(right_wins, rk, lk), f"{name}_key"), (*low, right_wins), lx & rx


def _tie_right(left: Node, right: Node, wire: Wire, name: str) -> Node:
    return _node(left, right, wire, name, left[2] | (~right[2] & (right[0] <= left[0])))


def _excluded_wins(left: Node, right: Node, wire: Wire, name: str) -> Node:
    return _node(left, right, wire, name, left[2] | (right[0] < left[0]))


class TieRightArgmin(ArgminTree):
    """A node gives equal keys to its right (higher) candidate: ties go to the highest index."""

    node = staticmethod(_tie_right)


class ExcludedWinsArgmin(ArgminTree):
    """A node forgets the right candidate's excluded flag: an excluded row with a lower sum wins."""

    node = staticmethod(_excluded_wins)


class DropsHeld(StallPipeline):
    """Mixin (before a block): a result offered and not taken is dropped after one cycle (with the
    pixel waiting behind it)."""

    def build(self, platform: object) -> tuple[Module, PipelineNets]:
        m, nets = super().build(platform)
        source = getattr(self, self.stream_names[1])
        with m.If(source.valid & ~source.ready):
            m.d.sync += [v.eq(0) for v in nets.output.entry_valid]  # the last assignment wins
        return m, nets


class PhantomPixel(StallPipeline):
    """Mixin (latency >= 2): the first stage's valid follows the input while the pipeline is stopped
    (a pixel not taken enters, and is then taken again)."""

    def build(self, platform: object) -> tuple[Module, PipelineNets]:
        m, nets = super().build(platform)
        sink = getattr(self, self.stream_names[0])
        with m.If(~nets.go[0]):
            m.d.sync += nets.valid[0].eq(sink.valid)
        return m, nets


class OverwritesHeld(StallPipeline):
    """Mixin (latency >= 2): a held result is overwritten by the pixel arriving behind it (written
    into the entry being read)."""

    def build(self, platform: object) -> tuple[Module, PipelineNets]:
        m, nets = super().build(platform)
        n = nets
        source = getattr(self, self.stream_names[1])
        value = self.remaining(m, self.latency - 2, n.banks[-2])
        e0, e1 = n.output.entries
        with m.If(n.go[-1] & n.valid[-2] & source.valid & ~source.ready):
            with m.If(n.output.reads[0]):
                m.d.sync += e1.eq(value)
            with m.Else():
                m.d.sync += e0.eq(value)
        return m, nets


class OverwritesHeldIntegrator(LogIntegrator):
    """The integrator whose weights stage (its output) overwrites a held result (:class:`OverwritesHeld`)."""

    weights_block = type("OverwritesHeldWeights", (OverwritesHeld, WeightStage), {})


class EarlyIssueIntegrator(LogIntegrator):
    """A pixel issues while the one before it is still in the argmin tree: its feedback codes come from
    an older MAP than its left neighbour's."""

    def issue_known(self, start: Value, pending: Value) -> Value:
        return Const(1, 1)


def other_tie_rule(params: LogParams) -> LogParams:
    """The parameters with the other tie rule (a block built with them, checked against the first)."""
    return replace(params, tie_break={"nomatch-first": "lowest-index",
                                      "lowest-index": "nomatch-first"}[params.tie_break])


def other_table(params: LogParams) -> LogParams:
    """The parameters with the exp table's second entry one higher."""
    table = list(params.weights)
    table[1] += 1
    if table[1] > table[0]:
        table[0] = table[1]
    return replace(params, weights=tuple(table))


@dataclass(frozen=True)
class LogMutant:
    """A known bug: ``block`` the proof's kind it is checked by (``argmin``, ``adders``, ``weights``,
    ``integrator``), ``mixin`` a class put before the block's (or None), ``argmin`` an argmin class
    (or None), ``integrator`` a ``LogIntegrator`` class (or None), ``params`` what changes the
    parameters (or None); ``breaks`` says what."""

    name: str
    block: str
    breaks: str
    mixin: type | None = None
    argmin: type | None = None
    integrator: type | None = None
    params: object = None


LOG_MUTANTS = (
    LogMutant("log-argmin-tie-right", "argmin", "ties go to the highest index", argmin=TieRightArgmin),
    LogMutant("log-argmin-excluded-wins", "argmin", "an excluded row can win", argmin=ExcludedWinsArgmin),
    LogMutant("log-argmin-other-tie", "argmin", "built with the other tie rule", params=other_tie_rule),
    LogMutant("log-integrator-other-tie", "integrator", "built with the other tie rule",
              params=other_tie_rule),
    LogMutant("log-weights-other-table", "weights", "another exp table", params=other_table),
    LogMutant("log-adders-drops-held", "adders", "a held result dropped", mixin=DropsHeld),
    LogMutant("log-argmin-phantom", "argmin", "a pixel not taken enters the pipeline", mixin=PhantomPixel),
    LogMutant("log-integrator-overwrites-held", "integrator", "a held result overwritten",
              integrator=OverwritesHeldIntegrator),
    LogMutant("log-integrator-early-issue", "integrator", "a pixel issued before its left neighbour's MAP",
              integrator=EarlyIssueIntegrator),
)
