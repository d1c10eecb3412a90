"""The census model's neighbour prior run end to end from the host (``run_machine``).

The oracle drives the engine by hand, one map row per call: row y's loaded above column from the
machine's own results of row y - 1 (``AbovePrior.loaded``; -1 for no match or a timeout, none for
row 0), its first pixel flagged ``line_start``. ``run_machine`` must give the same results bit for
bit, and the prior must change them.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.columns import AbovePrior
from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine
from bayesmachine.sim.engines import get_engine

DMAX = 10


@pytest.fixture(scope="module")
def prepared():
    left, right, gt = random_dot_stereogram(height=22, width=56, background=3, square=9, seed=3)
    left = left.copy()
    left[6:12, 20:30] = 120  # a flat patch: no-match calls, after which the left factor is flat
    return prepare(left, right, ModelParams(dmax=DMAX, name="census"), gt)


def hand_run(prepared, machine, max_rows: int | None = None):
    model = prepared.model
    fl, fr = prepared.planes
    ho, wo = prepared.shape
    column = model.column(AbovePrior)
    q = column.table(machine.word_bits)
    eng = get_engine("model", machine)
    disp = np.full((ho, wo), -1, np.int64)  # what the row below follows
    maps, cycles = [], []
    for y in range(ho if max_rows is None else max_rows):
        above = disp[y - 1] if y > 0 else np.full(wo, -1)
        words = memory_words(fl, fr, model, machine, rows=slice(y, y + 1), above=above)
        np.testing.assert_array_equal(words[:, :, 0], column.loaded(q, above))  # the above column
        starts = np.arange(wo) == 0
        res = eng.run(words, line_start=starts)
        disp[y] = res.neighbour_answers()  # a timeout's leading row is an answer, not a neighbour's MAP
        maps.append(res.disparities(machine))
        cycles.append(np.asarray(res.cycles))
    return np.array(maps), np.array(cycles)


@pytest.mark.parametrize("rng", ["sobol", "lfsr"])
def test_run_machine_equals_a_hand_driven_row_by_row_run(prepared, rng):
    machine = disparity_machine(prepared.model, counter_max=8, rng=rng)
    run = run_machine(prepared, machine, "model", progress=False, chunk_rows=4)  # chunking ignored
    want_map, want_cycles = hand_run(prepared, machine)
    np.testing.assert_array_equal(run.map, want_map)
    np.testing.assert_array_equal(run.cycles, want_cycles)
    assert (run.map >= 0).mean() > 0.5 and (run.map < 0).any()


def test_the_prior_changes_the_results(prepared):
    machine = disparity_machine(prepared.model, counter_max=8)
    run = run_machine(prepared, machine, "model", progress=False)
    # The same machine with every pixel a line start and no above neighbour: no prior at all.
    fl, fr = prepared.planes
    ho, wo = prepared.shape
    words = np.concatenate([memory_words(fl, fr, prepared.model, machine, rows=slice(y, y + 1),
                                         above=np.full(wo, -1)) for y in range(ho)])
    assert (words[:, :, 0] == machine.word_one).all()  # no above neighbour: a factor 1
    flat = get_engine("model", machine).run(words, line_start=np.ones(ho * wo, bool))
    flat_map = np.where(flat.nomatch | flat.timeout, -1, flat.map).reshape(ho, wo)
    assert (flat_map != run.map).mean() > 0.02
    # A wrong above column (the row above shifted) changes the results too.
    model = prepared.model
    eng = get_engine("model", machine)
    y = 5
    eng2 = get_engine("model", machine)
    good = memory_words(fl, fr, model, machine, rows=slice(y, y + 1), above=run.map[y - 1])
    shifted = memory_words(fl, fr, model, machine, rows=slice(y, y + 1), above=np.roll(run.map[y - 1], 3))
    a = eng.run(good, line_start=np.arange(wo) == 0)
    b = eng2.run(shifted, line_start=np.arange(wo) == 0)
    assert not np.array_equal(a.counts, b.counts)


def test_the_machine_is_close_to_its_references(prepared):
    from bayesmachine.host.reference import reference_quantized_map

    machine = disparity_machine(prepared.model, counter_max=16)
    run = run_machine(prepared, machine, "model", progress=False)
    fl, fr = prepared.planes
    q = reference_quantized_map(fl, fr, prepared.model, machine.word_bits)
    assert np.mean(run.map == q) > 0.85
    assert np.mean(run.map == prepared.reference_map) > 0.85


def test_feed_pixels_runs_the_census_model_on_the_stereo_machine_only(prepared):
    # The census model goes through the front end (tests/sim/test_stereo_engine.py), which is RTL:
    # the model engine cannot take pixels.
    machine = disparity_machine(prepared.model)
    with pytest.raises(ValueError, match="use --engine verilator"):
        run_machine(prepared, machine, "model", progress=False, feed="pixels")
