"""Benchmark: which Sobol variant earns its place (the full bundled pair, counter max 16 by default).

The ``sobol`` source restarts its sequence at every pixel and XORs each block of 2^W points with
a fresh random digital shift. This script runs the alternatives through the same per-cycle
bus/counter/encoder helpers as the model (``sim/model.py``), with the same column numbers
shared by all rows:

- ``restart+shift``: the ``sobol`` source as built (the script checks it equals the model);
- ``continue+shift``: one sequence through all pixels, a fresh shift every 2^W cycles;
- ``restart, no shift``: the plain Sobol points from index 0 at every pixel (deterministic);
- ``continue, no shift``: the plain points, one sequence through all pixels.

Prints cycles per pixel, RMS error, no-match F1 and MAP agreement of each. Asserts nothing. Run:
    python benchmarks/bench_sobol_variants.py [--counter-max 4,16]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numba
import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import counter_max_list
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.metrics import f1_score, map_agreement, rms_error
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sim.model import _finish_cycle, _nm_index
from bayesmachine.sources.lfsr import column_lfsr_specs, lfsr_numbers
from bayesmachine.sources.sobol import sobol_points


@numba.njit(cache=True)
def _run_variant(q, points, shifts, restart, rows, opcols, n_max, max_cycles, nm_index,
                 counts_out, map_out, cycles_out):
    """Column c's number in global compute cycle t / pixel cycle k: points[j, c] ^ shifts[b, c] with
    (j, b) from k (restart) or t (continue); a new block (next shift row) every 2^W cycles."""
    pixels, ops = q.shape
    block = points.shape[0]
    bits = np.zeros(ops, np.uint8)
    counts = np.zeros(rows, np.uint32)
    over = np.zeros(rows, np.uint8)
    nums = np.zeros(opcols, np.int64)
    t = 0
    b = -1  # shift row in use
    for p in range(pixels):
        counts[:] = 0
        k = 0
        winner = -1
        while True:
            idx = k if restart else t
            j = idx % block
            if j == 0:
                b += 1
            for c in range(opcols):
                nums[c] = points[j, c] ^ shifts[b % shifts.shape[0], c]
            for r in range(rows):
                for c in range(opcols):
                    bits[r * opcols + c] = nums[c] < q[p, r * opcols + c]
            k += 1
            t += 1
            winner = _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index)
            if winner >= 0 or k == max_cycles:
                break
        counts_out[p] = counts
        map_out[p] = winner
        cycles_out[p] = k


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counter-max", type=counter_max_list, default="16")
    args = ap.parse_args(argv)
    left, right, gt = bundled_pair()
    model = ModelParams(name="paper")
    prep = prepare(left, right, model, gt)
    ho, wo = prep.shape
    ref = prep.reference
    for n in args.counter_max:
        machine = MachineParams.for_disparity(model.dmax, counter_max=n, rng="sobol")
        q = memory_words(*prep.planes, model, machine, rows=slice(0, ho))
        q = np.ascontiguousarray(q.reshape(q.shape[0], -1), dtype=np.int64)
        w, cols, rows = machine.word_bits, machine.operator_columns, machine.rows
        points = np.array([sobol_points(c, w) for c in range(cols)], np.int64).T.copy()
        blocks = 4 * q.shape[0]  # shifts for every block: one per pixel, more for runs over 2^W cycles
        specs = column_lfsr_specs(machine)
        shifts = np.array([list(lfsr_numbers(s, blocks)) for s in specs], np.int64).T.copy()
        model_run = run_machine(prep, machine, "model", progress=False)
        print(f"counter max {n}: {q.shape[0]} pixels")
        variants = [("restart+shift", True, True), ("continue+shift", False, True),
                    ("restart, no shift", True, False), ("continue, no shift", False, False)]
        for name, restart, shifted in variants:
            counts = np.zeros((q.shape[0], rows), np.uint32)
            mp = np.zeros(q.shape[0], np.int64)
            cyc = np.zeros(q.shape[0], np.int64)
            sh = shifts if shifted else np.zeros((1, cols), np.int64)
            _run_variant(q, points, sh, restart, rows, cols, n, machine.max_cycles, _nm_index(machine),
                         counts, mp, cyc)
            disp = np.where((mp < 0) | (mp == rows - 1), -1, mp).reshape(ho, wo)
            if name == "restart+shift":
                same = np.array_equal(counts.reshape(ho, wo, rows), model_run.counts) and np.array_equal(
                    cyc.reshape(ho, wo), model_run.cycles)
                print(f"  (restart+shift equals the sobol model: {same})")
            print(
                f"  {name:18s}: cycles/px {cyc.mean():.2f}, RMS "
                f"{rms_error(counts.reshape(ho, wo, rows), n, ref.posterior, ref.map >= 0):.4f}, "
                f"no-match F1 {f1_score(disp < 0, ref.map < 0):.3f}, "
                f"MAP agreement {map_agreement(disp, ref.map):.3f}, "
                f"timeouts {(mp < 0).sum()}"
            )


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
