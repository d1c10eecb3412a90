"""Known bugs, built next to the shipped RTL (never in it), that the properties must catch.

Each mutant is a drop-in for the block a wrapper checks (``counter=``, ``encoder=``, ``machine=``
or ``dut_params=`` of the wrappers in this package); ``tests/hdl/formal/test_formal.py`` asserts that the
proof fails on every one, so the properties are shown to bite. A mutant of a block with a builder
(``build``: the module and the nets a proof reads, what ``elaborate`` gives) changes what ``build``
returns, so that a wrapper building it and the design elaborating it both get the mutant.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from amaranth.hdl import Cat, Module, Mux, Signal, Value

from bayesmachine.hdl.frontend.pipeline import PipelineNets
from bayesmachine.hdl.frontend.stereo import FeaturePipeline, FrontEnd, StereoMachine, StereoNets
from bayesmachine.hdl.frontend.words import WordGenerator, WordPipeline
from bayesmachine.hdl.machine import BayesianMachine, MachineNets
from bayesmachine.hdl.machine.counters import count_ones, overflow_counter_full
from bayesmachine.hdl.machine.encoder import MAPEncoder, map_encoder
from bayesmachine.params import MachineParams

__all__ = [
    "CountsPastStopMachine", "DriftingCountStereoMachine", "EarlyReadStereoMachine", "FirstIgnoredFrontEnd",
    "HighestIndexEncoder", "LateCountsMachine", "LateSampleMachine", "LostBeatMachine", "Mutant",
    "NoMatchBlindEncoder", "PayloadFollowsEncoderMachine",
    "ShortWordGenerator", "SkippedSwapMachine", "ValidDropMachine", "counter_early_overflow",
    "counter_late_overflow", "counter_wraps", "mutants", "other_tie_rule",
]


# --- overflow counter ------------------------------------------------------------------------

def counter_early_overflow(row: Value, count: Value, full: Value, n_max: int) -> tuple[Value, Value, Value]:
    """Off by one: overflows on the n_max-th 1 (compares with n_max - 1)."""
    over = row & (full | (count == n_max - 1))
    _, next_count, next_full = overflow_counter_full(row, count, full, n_max)
    return over, next_count, next_full


def counter_late_overflow(row: Value, count: Value, full: Value, n_max: int) -> tuple[Value, Value, Value]:
    """Off by one: the full flag is set a 1 late (on count == n_max), so the counter overflows on
    the (n_max + 2)-th 1."""
    over = row & full
    next_count = (count + (row & ~full))[: len(count)]
    next_full = full | (row & (count == n_max))
    return over, next_count, next_full


def counter_wraps(row: Value, count: Value, full: Value, n_max: int) -> tuple[Value, Value, Value]:
    """The counter keeps counting after it is full (no hold at n_max): it wraps past n_max."""
    over = row & full
    next_count = (count + row)[: len(count)]
    next_full = full | (row & (count == n_max - 1))
    return over, next_count, next_full


# --- MAP encoder -----------------------------------------------------------------------------

def other_tie_rule(**kwargs: Any) -> MAPEncoder:
    """The encoder built with the other tie rule than the one it is checked against."""
    rule = {"nomatch-first": "lowest-index", "lowest-index": "nomatch-first"}[kwargs["tie_break"]]
    return MAPEncoder(**{**kwargs, "tie_break": rule})


class HighestIndexEncoder(MAPEncoder):
    """The priority tree the wrong way round: the highest overflowing row wins."""

    def elaborate(self, platform: object) -> Module:
        m = Module()
        rows = self.rows
        valid, rev = map_encoder(self.over[::-1], False, "lowest-index")
        index = (rows - 1 - rev)[: len(self.index)]
        if self.nomatch_row and self.tie_break == "nomatch-first":
            index = Mux(self.over[rows - 1], rows - 1, index)
        m.d.comb += [self.valid.eq(valid), self.index.eq(index)]
        return m


class NoMatchBlindEncoder(MAPEncoder):
    """``valid`` forgets the no-match row (an OR over the disparity rows only)."""

    def elaborate(self, platform: object) -> Module:
        m = super().elaborate(platform)
        m.d.comb += self.valid.eq(self.over[: self.rows - 1].any())
        return m


# --- machine ---------------------------------------------------------------------------------

class ValidDropMachine(BayesianMachine):
    """``result.valid`` is a one-cycle pulse: a result not taken at once is lost."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        with m.If(self.result.valid & ~self.result.ready):
            m.d.sync += self.result.valid.eq(0)  # the last assignment wins
        return m, n


class PayloadFollowsEncoderMachine(BayesianMachine):
    """The held result's ``map`` follows the MAP encoder, whose flags the next run already changes."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        with m.If(self.result.valid):
            m.d.sync += self.result.payload.map.eq(m.submodules.encoder.index)
        return m, n


class SkippedSwapMachine(BayesianMachine):
    """A swap in a bubble starts the next run but leaves the active memory as it was: the pixel
    loaded is skipped and the previous one is run again (an idle machine's swap still copies)."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        with m.If(n.start_rep[0] & n.stop):
            m.d.sync += [w.eq(w) for w in n.active]  # the last assignment wins
        return m, n


class LostBeatMachine(BayesianMachine):
    """A beat taken right behind another is not written into the shadow memory (its write enable
    is dropped while the previous beat's is up): back-to-back beats lose one."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        with m.If(n.write_q.any()):
            m.d.sync += n.write_q.eq(0)
        return m, n


class LateCountsMachine(BayesianMachine):
    """The result takes the counters a cycle late: their values before the run's last compute cycle."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        counts_q = [Signal.like(c, name=f"{c.name}_late") for c in n.counts]
        m.d.sync += [q.eq(c) for q, c in zip(counts_q, n.counts, strict=True)]
        with m.If(n.leave):
            m.d.sync += self.result.payload.counts.eq(Cat(*counts_q))
        return m, n


class LateSampleMachine(BayesianMachine):
    """B samples per clock: the stop's rows are those overflowing by the cycle's last sample, not at
    the first sample where one does (a row overflowing later in the cycle joins the tie)."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        b = self.params.samples_per_clock
        for r in range(self.params.rows):
            with m.If(n.compute_rep[r // n.rows_per_group] & n.G.any()):
                m.d.sync += n.over_q[r].eq(n.flags[r][b - 1])
        return m, n


class CountsPastStopMachine(BayesianMachine):
    """B samples per clock: the counters add the stop cycle's samples after the stop too (capped at
    n_max), so the losing rows' counts run past the stop."""

    def build(self, platform: object) -> tuple[Module, MachineNets]:
        m, n = super().build(platform)
        p = self.params
        b = p.samples_per_clock
        for r in range(p.rows):
            total = n.counts[r] + count_ones(n.row[r * b:(r + 1) * b])
            with m.If(n.compute_rep[r // n.rows_per_group]):
                m.d.sync += n.counts[r].eq(Mux(total > p.counter_max, p.counter_max, total))
        return m, n


# --- front end -------------------------------------------------------------------------------

class ShortWordGenerator(WordGenerator):
    """Off by one: an output pixel's last beat is never issued (the pixel ends a beat early)."""

    def build(self, platform: object) -> tuple[Module, WordPipeline]:
        m, n = super().build(platform)
        with m.If(n.issue & (n.beat == self.params.beats_per_pixel - 2)):
            m.d.sync += [n.beat.eq(0), n.active.eq(0)]
        return m, n


class FirstIgnoredPipeline(FeaturePipeline):
    """The frame-start marker is ignored: the position counters run on across frames."""

    def build(self, platform: object) -> tuple[Module, PipelineNets]:
        m, n = super().build(platform)
        m.d.comb += [n.cur_col.eq(n.col), n.cur_line.eq(n.line)]
        return m, n


class FirstIgnoredFrontEnd(FrontEnd):
    """A front end whose feature pipeline (where the position counters live) is
    :class:`FirstIgnoredPipeline`."""

    feature_pipeline = FirstIgnoredPipeline


class EarlyReadStereoMachine(StereoMachine):
    """The machine's load ``valid`` from the beat count ``StereoMachine`` keeps instead of the FIFO's
    read side: a beat just written (not yet readable) is read, an underflow."""

    def build(self, platform: object) -> tuple[Module, StereoNets]:
        m, n = super().build(platform)
        m.d.comb += n.machines[0].load.valid.eq(n.loads[0].used != 0)
        return m, n


class DriftingCountStereoMachine(StereoMachine):
    """The beat count ``StereoMachine`` keeps misses a read in a cycle with a write: it drifts above
    the FIFO's level (and its registered ready falls too early)."""

    def build(self, platform: object) -> tuple[Module, StereoNets]:
        m, n = super().build(platform)
        load = n.loads[0]
        with m.If(load.write & load.read):
            m.d.sync += load.used.eq(load.used + 1)
        return m, n


@dataclass(frozen=True)
class Mutant:
    """One known bug: its name, the wrapper it is checked in (``counter``, ``encoder``, ``machine``,
    ``control``, ``miter``, ``generator``, ``frontend``, ``fifo``),
    the keyword arguments that inject it, and what it breaks."""

    name: str
    wrapper: str
    inject: dict[str, Any]
    breaks: str


def mutants(machine_params: MachineParams) -> list[Mutant]:
    """The mutants ``tests/hdl/formal/test_formal.py`` checks; ``machine_params`` is the small machine the
    machine's properties are checked on (the watchdog mutants change its ``max_cycles`` by one).
    The ``samples`` ones are checked in the control wrapper on a machine with B samples per clock
    (``tests/hdl/formal/test_formal.py``: ``SAMPLES``)."""
    late = dataclasses.replace(machine_params, max_cycles=machine_params.max_cycles + 1)
    early = dataclasses.replace(machine_params, max_cycles=machine_params.max_cycles - 1)
    swap = {"nomatch-first": "lowest-index", "lowest-index": "nomatch-first"}
    other_tie = dataclasses.replace(machine_params, tie_break=swap[machine_params.tie_break])
    return [
        Mutant("counter-early", "counter", {"counter": counter_early_overflow},
               "overflows on the n_max-th 1"),
        Mutant("counter-late", "counter", {"counter": counter_late_overflow},
               "overflows on the (n_max+2)-th 1"),
        Mutant("counter-wraps", "counter", {"counter": counter_wraps}, "count passes n_max"),
        Mutant("counter-no-clear", "counter", {"clear_full": False}, "the full flag survives a new pixel"),
        Mutant("encoder-other-tie", "encoder", {"encoder": other_tie_rule}, "the other tie rule"),
        Mutant("encoder-highest", "encoder", {"encoder": HighestIndexEncoder}, "the highest row wins"),
        Mutant("encoder-nomatch-blind", "encoder", {"encoder": NoMatchBlindEncoder},
               "valid misses the no-match row"),
        Mutant("machine-valid-drop", "machine", {"machine": ValidDropMachine}, "a stalled result is dropped"),
        Mutant("machine-payload-moves", "machine", {"machine": PayloadFollowsEncoderMachine},
               "a stalled result's map changes"),
        Mutant("machine-other-tie", "machine", {"dut_params": other_tie}, "the machine's other tie rule"),
        Mutant("watchdog-late", "machine", {"dut_params": late}, "a run goes one cycle past max_cycles"),
        Mutant("watchdog-early", "machine", {"dut_params": early}, "a timeout one cycle before max_cycles"),
        Mutant("control-skipped-swap", "control", {"machine": SkippedSwapMachine},
               "a bubble's swap leaves the active memory: the previous pixel runs again"),
        Mutant("control-lost-beat", "control", {"machine": LostBeatMachine},
               "a beat right behind another is not written"),
        Mutant("control-late-counts", "control", {"machine": LateCountsMachine},
               "the result's counts are taken a cycle late"),
        Mutant("control-other-tie", "control", {"dut_params": other_tie}, "the machine's other tie rule"),
        Mutant("control-watchdog-late", "control", {"dut_params": late},
               "a run goes one cycle past max_cycles"),
        Mutant("control-valid-drop", "control", {"machine": ValidDropMachine}, "a stalled result is dropped"),
        Mutant("miter-payload-moves", "miter", {"machine": PayloadFollowsEncoderMachine},
               "a stalled result's map changes"),
        Mutant("samples-late-sample", "samples", {"machine": LateSampleMachine},
               "the stop's rows are those overflowing by the cycle's last sample"),
        Mutant("samples-counts-past-stop", "samples", {"machine": CountsPastStopMachine},
               "the counters add the samples after the stop"),
        Mutant("generator-short", "generator", {"generator": ShortWordGenerator},
               "an output pixel gets beats_per_pixel - 1 beats"),
        Mutant("frontend-first-ignored", "frontend", {"frontend": FirstIgnoredFrontEnd},
               "a frame start does not restart the position counters"),
        Mutant("fifo-early-read", "fifo", {"stereo": EarlyReadStereoMachine},
               "the machine reads a beat the FIFO does not offer yet (underflow)"),
        Mutant("fifo-count-drift", "fifo", {"stereo": DriftingCountStereoMachine},
               "the beat count misses a read in a cycle with a write"),
    ]


