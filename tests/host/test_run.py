"""The run API with the machine model: layout, chunking, timeouts, agreement with the reference;
the census model without its neighbour prior, and refused without the machine it needs."""

import numpy as np
import pytest

from bayesmachine.host.images import random_dot_stereogram
from bayesmachine.host.metrics import RmsAccumulator, evaluate, rms_error
from bayesmachine.host.records import counts_dtype
from bayesmachine.host.reference import reference_fast
from bayesmachine.host.run import prepare, run_machine, run_pair
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError

DMAX = 12


@pytest.fixture(scope="module")
def pair():
    return random_dot_stereogram(height=24, width=60, background=2, square=9, seed=7)


@pytest.fixture(scope="module")
def prepared(pair):
    left, right, gt = pair
    return prepare(left, right, ModelParams(name="paper", dmax=DMAX), gt)


def test_outcome_layout_and_metrics(pair, prepared):
    left, right, gt = pair
    machine = MachineParams.for_disparity(DMAX, counter_max=16)
    out = run_pair(left, right, prepared.model, machine, gt=gt, progress=False)
    ho, wo = 20, 60 - 4 - DMAX
    assert out.run.map.shape == (ho, wo) and out.run.map.dtype == np.int16
    assert out.run.counts.shape == (ho, wo, DMAX + 2) and out.run.cycles.shape == (ho, wo)
    # The winner's counter holds n_max on every pixel that did not time out.
    assert (out.run.counts.max(axis=-1) == 16).all()
    rep = out.metrics.to_report()
    assert rep["pixels"] == ho * wo and rep["timeouts"] == 0
    # Textured random dots: the machine should mostly agree with exact inference.
    assert rep["map_agreement"] > 0.7
    assert rep["rms_error"] < 0.2
    assert rep["cycles_per_pixel_mean"] > 16  # at least n_max + 1 cycles per pixel
    assert {"machine_bad2", "reference_bad2", "sgbm_bad2"} <= rep.keys()


def test_chunking_does_not_change_results(prepared):
    machine = MachineParams.for_disparity(DMAX, counter_max=4, seed=3)
    one = run_machine(prepared, machine, progress=False, chunk_rows=1)
    many = run_machine(prepared, machine, progress=False, chunk_rows=7)
    for field in ("map", "counts", "cycles", "timeout"):
        np.testing.assert_array_equal(getattr(one, field), getattr(many, field))


def test_timeouts_count_as_no_match(pair, prepared):
    left, right, _ = pair
    machine = MachineParams.for_disparity(DMAX, counter_max=16, max_cycles=17)
    out = run_pair(left, right, prepared.model, machine, prepared=prepared, progress=False)
    t = out.run.timeout
    assert t.any() and not t.all()
    assert (out.run.map[t] == -1).all()
    assert (out.run.cycles[t] == 17).all()
    assert out.metrics.timeouts == int(t.sum())
    assert out.metrics.machine_nomatch >= int(t.sum())


def test_prepare_without_reference_runs_the_machine_but_not_the_evaluation(pair, prepared):
    # What measuring a machine's cycles needs (synth's throughput): the same run, no reference.
    left, right, gt = pair
    bare = prepare(left, right, ModelParams(name="paper", dmax=DMAX), gt, reference=False)
    assert bare.reference_map is None
    machine = MachineParams.for_disparity(DMAX, counter_max=4, seed=5)
    a = run_machine(bare, machine, progress=False, chunk_rows=5)
    b = run_machine(prepared, machine, progress=False)
    for field in ("map", "counts", "cycles", "timeout"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    with pytest.raises(ValueError, match="without its reference"):
        evaluate(bare, a)


def test_bad_machine_or_engine(prepared):
    with pytest.raises(ValueError, match="dmax \\+ 2"):
        run_machine(prepared, MachineParams.for_disparity(DMAX + 1), progress=False)
    with pytest.raises(ValueError, match="unknown engine"):
        run_machine(prepared, MachineParams.for_disparity(DMAX), engine="fpga", progress=False)


def test_prepare_rejects_mismatched_gt(pair):
    left, right, gt = pair
    with pytest.raises(ValueError, match="ground truth shape"):
        prepare(left, right, ModelParams(name="paper", dmax=DMAX), gt[:, :-1])


def test_pysim_engine_matches_model_through_the_host():
    # The RTL in Amaranth's simulator, fed row by row by the host, equals the model bit for bit.
    left, right, gt = random_dot_stereogram(height=8, width=20, background=1, square=3, seed=11)
    prep = prepare(left, right, ModelParams(name="paper", dmax=4), gt)
    machine = MachineParams.for_disparity(4, counter_max=2, word_bits=8, words_per_beat=6)
    a = run_machine(prep, machine, "model", progress=False)
    b = run_machine(prep, machine, "pysim", progress=False)
    assert a.map.size == 4 * 12
    for field in ("map", "counts", "cycles", "timeout", "nomatch"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_counts_use_the_smallest_dtype_that_holds_counter_max(prepared):
    assert counts_dtype(255) == np.uint8 and counts_dtype(256) == np.uint16
    assert counts_dtype(70000) == np.uint32
    run = run_machine(prepared, MachineParams.for_disparity(DMAX, counter_max=300), progress=False)
    assert run.counts.dtype == np.uint16 and run.counts.max() == 300


def test_banded_rms_equals_the_whole_posterior(pair, prepared):
    """evaluate() recomputes the posterior band by band; the figure is the one of the whole volume."""
    left, right, _ = pair
    run = run_machine(prepared, MachineParams.for_disparity(DMAX, counter_max=8), progress=False)
    whole = reference_fast(*prepared.planes, prepared.model)
    np.testing.assert_array_equal(whole.map, prepared.reference_map)
    expected = rms_error(run.counts, 8, whole.posterior, whole.map >= 0)
    assert evaluate(prepared, run).rms_error == pytest.approx(expected, rel=1e-12)
    # One-row bands: the same figure.
    acc = RmsAccumulator(8)
    for rows, band in prepared.reference_bands(1):
        acc.add(run.counts[rows], band.posterior, band.map >= 0)
    assert acc.value == pytest.approx(expected, rel=1e-12)


def test_run_never_holds_more_than_a_band_of_posterior(pair, monkeypatch):
    """With bands of ~100 pixels, every posterior the host computes is one band, and the figures
    equal those of one big band."""
    import bayesmachine.host.reference as reference_module
    import bayesmachine.region as region_module

    left, right, gt = pair
    model = ModelParams(name="paper", dmax=DMAX)
    machine = MachineParams.for_disparity(DMAX, counter_max=4)
    big = run_pair(left, right, model, machine, gt=gt, progress=False, sgbm=False)
    seen = []
    real = reference_module.pass_reference

    def spy(*args, **kwargs):
        ref = real(*args, **kwargs)
        seen.append(ref.posterior.shape[0])
        return ref

    monkeypatch.setattr(reference_module, "pass_reference", spy)
    monkeypatch.setattr(region_module, "BAND_PIXELS", 100)
    small = run_pair(left, right, model, machine, gt=gt, progress=False, sgbm=False)
    wo = 60 - 4 - DMAX
    assert seen and max(seen) == 100 // wo and sum(seen) == 2 * 20  # prepare's MAP pass + the RMS pass
    np.testing.assert_array_equal(small.prepared.reference_map, big.prepared.reference_map)
    a, b = small.metrics.to_report(), big.metrics.to_report()
    assert a.pop("rms_error") == pytest.approx(b.pop("rms_error"), rel=1e-12)  # summed in another order
    assert a == b


def test_machine_runs_the_census_model_without_the_prior():
    from bayesmachine.host.run import run_pair

    left, right, gt = random_dot_stereogram(height=30, width=70, background=3, square=9, seed=4)
    model = ModelParams(dmax=10, name="census", fuse_columns=False, neighbour_prior=False)
    machine = MachineParams.for_disparity(10, columns=4, rng="sobol", counter_max=16)
    out = run_pair(left, right, model, machine, engine="model", gt=gt, sgbm=False)
    assert set(out.prepared.planes[0]) == {"m25", "gh20", "gv20", "census"}  # prepare(): the model's planes
    assert out.metrics.map_agreement > 0.9
    assert out.metrics.bad["machine"]["bad2"] < 0.1
    # With the neighbour prior the machine needs its neighbour prior (its feedback column, and the
    # above column from its own results): refused, never run with a silently uniform prior.
    with pytest.raises(ParameterError, match="^neighbour_prior"):
        run_pair(left, right, ModelParams(dmax=10, name="census", fuse_columns=False), machine)
    loaded = MachineParams.for_disparity(10, columns=4, prior="loaded")
    with pytest.raises(ParameterError, match="^neighbour_prior"):
        run_pair(left, right, ModelParams(dmax=10, name="census", fuse_columns=False), loaded)
