# amaranth: UnusedElaboratable=no
"""The pin-saving wrapper (fpga/wrapper.py) driven at its pins as a host would, in Amaranth's simulator:
random idle cycles and chunk widths, one machine, K machines and the StereoMachine behind it, every
result the model's; its parameters and the streams it needs."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_same_results, run_sim, small_params

from bayesmachine.fpga.wrapper import PinWrapper
from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel
from bayesmachine.sim.packing import pack_beats
from bayesmachine.sim.results import MachineResult, decode_results


def _words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    words = rng.integers(0, params.word_one + 1, size=(pixels, params.rows, params.operator_columns))
    words[rng.random(words.shape) < 0.3] = params.word_one
    return words.astype(np.int32)


def _through_wrapper(core: object, beats: list[int], results: int, result_width: int,
                     pin_width: int, idle: float, seed: int) -> list[int]:
    """Drive the wrapper's pins as a host would; return the raw result payloads."""
    dut = PinWrapper(core, pin_width=pin_width)
    chunks = [(beat >> (i * pin_width)) & ((1 << pin_width) - 1)
              for beat in beats for i in range(dut.chunks_in)]
    got: list[int] = []
    rng = np.random.default_rng(seed)

    async def bench(ctx):
        sent, parts = 0, []
        for _ in range(200_000):
            send = sent < len(chunks) and ctx.get(dut.din_ready) and rng.random() >= idle
            ctx.set(dut.din_valid, int(send))
            if send:
                ctx.set(dut.din, chunks[sent])
                sent += 1
            if ctx.get(dut.dout_valid):
                parts.append(ctx.get(dut.dout))
                if len(parts) == dut.chunks_out:
                    raw = sum(c << (i * pin_width) for i, c in enumerate(parts))
                    got.append(raw & ((1 << result_width) - 1))
                    parts = []
            await ctx.tick()
            if len(got) == results:
                return
        raise AssertionError(f"only {len(got)} of {results} results came out")

    run_sim(dut, bench)
    return got


@pytest.mark.parametrize(("pin_width", "idle"), [(8, 0.0), (3, 0.4), (64, 0.1)])
def test_wrapper_protocol_matches_model(pin_width: int, idle: float) -> None:
    params = small_params()
    words = _words(params, 12, seed=pin_width)
    core = BayesianMachine(params=params)
    beats = [b for pixel in words for b in pack_beats(params, pixel)]
    raw = _through_wrapper(core, beats, len(words), _result_width(params), pin_width, idle, seed=1)
    want = MachineModel(params).run(words)
    assert decode_results(params, raw).equal(want)


def _result_width(params: MachineParams) -> int:
    from amaranth.hdl import Shape

    from bayesmachine.hdl.machine import result_layout

    return Shape.cast(result_layout(params)).width


@pytest.mark.parametrize(("pin_width", "idle"), [(8, 0.3), (5, 0.0)])
def test_stereo_machine_through_wrapper_matches_model(pin_width: int, idle: float) -> None:
    """The camera-fed top behind the same wrapper: its input stream is ``pixels`` (17-bit beats),
    taken from its signature; two frames back to back, results equal the model on the host's words."""
    from bayesmachine.hdl.frontend.stereo import StereoMachine, stereo_machine_params
    from bayesmachine.host.features import feature_sums
    from bayesmachine.host.likelihoods import memory_words
    from bayesmachine.sim.stereo_testbench import frame_beats

    dmax, width = 3, 12
    model = ModelParams(name="paper", dmax=dmax, sigma_m=4.0)
    params = stereo_machine_params(dmax, model=model, counter_max=4, max_cycles=500)
    rng = np.random.default_rng(pin_width)
    frames = []
    for height in (6, 5):
        left = rng.integers(0, 256, (height, width), dtype=np.uint8)
        right = np.roll(left, -1, axis=1).astype(np.int64) + rng.integers(-3, 4, (height, width))
        frames.append((left, right.clip(0, 255).astype(np.uint8)))
    beats = [b for lf, rf in frames for b in frame_beats(lf, rf)]
    words = np.concatenate([memory_words(feature_sums(lf), feature_sums(rf), model, params)
                            for lf, rf in frames])
    core = StereoMachine(params=params, model=model, width=width, fifo_pixels=2)
    wrapper = PinWrapper(StereoMachine(params=params, model=model, width=width), pin_width=pin_width)
    assert wrapper.input_name == "pixels" and wrapper.chunks_in == -(-17 // pin_width)
    assert len(words) == 15  # (6 - 4) (12 - 4 - 3) + (5 - 4) (12 - 4 - 3)
    raw = _through_wrapper(core, beats, len(words), _result_width(params), pin_width, idle, seed=3)
    assert_same_results(decode_results(params, raw), MachineModel(params).run(words))


def test_wrapper_rejects_bad_parameters() -> None:
    with pytest.raises(ParameterError, match="pin_width"):
        PinWrapper(BayesianMachine(params=small_params()), pin_width=0)
    with pytest.raises(ParameterError, match="on-chip random source"):
        PinWrapper(BayesianMachine(params=small_params(rng="external")))
    assert PinWrapper(BayesianMachine(params=small_params())).input_name == "load"


def test_wrapper_needs_one_input_stream_and_a_result_stream() -> None:
    from amaranth.hdl import Module
    from amaranth.lib import stream, wiring
    from amaranth.lib.wiring import In, Out

    class Core(wiring.Component):
        def elaborate(self, platform: object) -> Module:
            return Module()

    s4 = stream.Signature(4)
    two_in = Core({"a": In(s4), "b": In(s4), "result": Out(s4)})
    with pytest.raises(ParameterError, match=r"exactly one input stream port \(found 'a', 'b'\)"):
        PinWrapper(two_in)
    with pytest.raises(ParameterError, match=r"exactly one input stream port \(found none\)"):
        PinWrapper(Core({"result": Out(s4)}))
    with pytest.raises(ParameterError, match="'result' output stream"):
        PinWrapper(Core({"a": In(s4), "result": Out(4)}))  # a plain port, not a stream
    with pytest.raises(ParameterError, match="'result' output stream"):
        PinWrapper(Core({"a": In(s4), "out": Out(s4)}))


@pytest.mark.parametrize("machines", [1, 3])
def test_machines_through_wrapper_match_their_model(machines: int) -> None:
    from bayesmachine.hdl.machines import ParallelMachines
    from bayesmachine.sim.machines import ParallelMachinesModel

    params = small_params()
    words = _words(params, 14, seed=5)
    beats = [b for pixel in words for b in pack_beats(params, pixel)]
    raw = _through_wrapper(ParallelMachines(params=params, machines=machines),
                           beats, len(words), _result_width(params),
                           8, 0.2, seed=2)
    model = ParallelMachinesModel(params, machines)
    want = model.run(words[:5])  # two calls: the round-robin deal carries over
    rest = model.run(words[5:])
    assert decode_results(params, raw).equal(MachineResult.concatenate([want, rest], params.rows))
    if machines == 1:  # one lane is the machine itself
        assert MachineModel(params).run(words).equal(ParallelMachinesModel(params, 1).run(words))
    else:  # machines have their own seeds: machine 1's pixels differ from one machine's
        one = MachineModel(params).run(words)
        assert not np.array_equal(one.counts, ParallelMachinesModel(params, machines).run(words).counts)


def test_log_machines_through_wrapper_match_the_log_model() -> None:
    """K log machines dealt pixels round-robin: each machine is the log machine (no seed), results in
    pixel order equal to the log model's on all the pixels."""
    from bayesmachine.hdl.machines import ParallelMachines
    from bayesmachine.sim.log_model import LogMachineModel
    from bayesmachine.sim.machines import ParallelMachinesModel

    params = MachineParams(rows=5, columns=2, word_bits=8, words_per_beat=3, nomatch_row=True,
                           integrator="log")
    codes = np.random.default_rng(7).integers(0, params.load_max + 1, (14, params.words_per_pixel))
    beats = [b for pixel in codes for b in pack_beats(params, pixel)]
    raw = _through_wrapper(ParallelMachines(params=params, machines=2), beats, len(codes),
                           _result_width(params), 8, 0.2, seed=3)
    want = LogMachineModel(params).run(codes)
    assert ParallelMachinesModel(params, 2).run(codes).equal(want)
    assert decode_results(params, raw).equal(want)
