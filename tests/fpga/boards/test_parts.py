# amaranth: UnusedElaboratable=no
"""The board's stream components, each against its twin in Amaranth's simulator, with random
stalls on their streams: the command parser, the frame receiver, the two record serializers, the
transmit arbiter, the receive timeout, the LEDs and the protocol control. (``BoardCore`` only wires
them: tests/fpga/boards/test_simulate.py holds the whole against ``BoardTwin``.)"""

from __future__ import annotations

import random
import struct
import zlib

import numpy as np
import pytest
from amaranth.hdl import Module
from amaranth.sim import Simulator
from conftest import small_params

from bayesmachine.fpga.boards import protocol as pr
from bayesmachine.fpga.boards.arbiter import TransmitArbiter, TransmitArbiterTwin
from bayesmachine.fpga.boards.control import ProtocolControl
from bayesmachine.fpga.boards.parser import Header, HeaderParser, HeaderParserTwin
from bayesmachine.fpga.boards.receiver import FrameReceiver, FrameReceiverTwin
from bayesmachine.fpga.boards.serializer import ControlSerializer, ResultSerializer, ResultSerializerTwin
from bayesmachine.fpga.boards.status import ReceiveTimeout, ReceiveTimeoutTwin, StatusLEDs, StatusLEDsTwin
from bayesmachine.fpga.boards.streams import CRC16, CRC32
from bayesmachine.fpga.boards.twin import BoardTwin
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sim.results import MachineResult


def _simulate(dut: object, *benches: object) -> None:
    sim = Simulator(dut)
    sim.add_clock(1e-8)
    for bench in benches:
        sim.add_testbench(bench)
    sim.run()


async def _feed(ctx, port, items: list, rnd: random.Random, stall: float = 0.3) -> None:  # noqa: ANN001
    """Offer ``items`` on the stream ``port``, holding ``valid`` low at random."""
    for item in items:
        while rnd.random() < stall:
            ctx.set(port.valid, 0)
            await ctx.tick()
        ctx.set(port.valid, 1)
        ctx.set(port.payload, item)
        await ctx.tick().until(port.ready)
    ctx.set(port.valid, 0)


async def _take(ctx, port, sink: list, count: int, rnd: random.Random, stall: float = 0.3,  # noqa: ANN001
                limit: int = 20_000) -> None:
    """Take ``count`` payloads of the stream ``port`` into ``sink``, holding ``ready`` low at random."""
    for _ in range(limit):
        if len(sink) == count:
            break
        ready = rnd.random() >= stall
        ctx.set(port.ready, ready)
        _, _, valid, payload = await ctx.tick().sample(port.valid, port.payload)
        if valid and ready:
            sink.append(payload)
    ctx.set(port.ready, 0)
    assert len(sink) == count, f"{len(sink)} of {count} came"


def test_the_crcs_are_the_protocols() -> None:
    rnd = random.Random(0)
    for n in (0, 1, 14, 100):
        data = bytes(rnd.randrange(256) for _ in range(n))
        assert CRC16.compute(data) == pr.crc16(data) and CRC32.compute(data) == pr.crc32(data)


def _records_and_garbage(rnd: random.Random) -> bytes:
    """Records (some garbled), sync look-alikes and junk between them."""
    out = b"\x00BBMjunk"
    for i in range(8):
        raw = bytearray(pr.encode_record(rnd.choice([pr.FRAME, pr.INFO, 0x51]), i, rnd.randbytes(10)))
        if i % 3 == 1:
            raw[rnd.randrange(2, 16)] ^= 1 << rnd.randrange(8)
        out += bytes(raw) + rnd.choice([b"", b"B", b"BB", b"xBy", b"M"])
    return out


@pytest.mark.parametrize("seed", [1, 2])
def test_header_parser_is_its_twin(seed: int) -> None:
    rnd = random.Random(seed)
    data = _records_and_garbage(rnd)
    twin = HeaderParserTwin()
    want = [h for b in data if (h := twin.feed(b)) is not None]
    assert sum(h.crc_ok for h in want) >= 3 and sum(not h.crc_ok for h in want) >= 2
    dut = HeaderParser()
    got: list = []

    async def source(ctx) -> None:  # noqa: ANN001
        await _feed(ctx, dut.bytes, list(data), rnd)

    async def sink(ctx) -> None:  # noqa: ANN001
        await _take(ctx, dut.headers, got, len(want), random.Random(seed + 10), stall=0.6)

    _simulate(dut, source, sink)
    assert [Header(h.record.type, h.record.seq, h.record.payload.to_bytes(10, "little"), bool(h.crc_ok))
            for h in got] == want


@pytest.mark.parametrize(("margin", "good"), [(2, True), (3, False)])
def test_frame_receiver_is_its_twin(margin: int, good: bool) -> None:
    width, dmax, height = 13, 3, 2 * margin + 3
    rnd = random.Random(margin)
    pixels = rnd.randbytes(2 * width * height)
    crc = pr.crc32(pixels) ^ (0 if good else 1)
    data = pixels + struct.pack("<I", crc)
    twin = FrameReceiverTwin(width=width, dmax=dmax, margin=margin)
    twin.start(height)
    want = [p for b in data if (p := twin.feed(b)) is not None]
    assert twin.done and twin.crc_ok == good and twin.fed == 3 * (width - 2 * margin - dmax)
    dut = FrameReceiver(width=width, dmax=dmax, margin=margin)
    got: list = []
    seen: dict[str, int] = {}

    async def source(ctx) -> None:  # noqa: ANN001
        ctx.set(dut.height, height)
        assert not ctx.get(dut.waiting)  # idle until started
        ctx.set(dut.start, 1)
        await ctx.tick()
        ctx.set(dut.start, 0)
        await _feed(ctx, dut.bytes, list(data), rnd)
        await ctx.tick().repeat(2)
        seen.update(done=ctx.get(dut.done), crc_ok=ctx.get(dut.crc_ok), fed=ctx.get(dut.fed),
                    waiting=ctx.get(dut.waiting))

    async def sink(ctx) -> None:  # noqa: ANN001
        await _take(ctx, dut.pixels, got, len(want), random.Random(margin + 10))

    _simulate(dut, source, sink)
    assert [(p.left, p.right, bool(p.first)) for p in got] == want
    assert seen == {"done": 1, "crc_ok": int(good), "fed": twin.fed, "waiting": 0}


def test_frame_receiver_stops_and_starts_again() -> None:
    """``stop`` mid-frame leaves it idle (not waiting, taking nothing); ``start`` begins a new frame."""
    dut = FrameReceiver(width=8, dmax=1, margin=2)

    async def bench(ctx) -> None:  # noqa: ANN001
        ctx.set(dut.height, 5)
        ctx.set(dut.start, 1)
        await ctx.tick()
        ctx.set(dut.start, 0)
        ctx.set(dut.bytes.valid, 1)
        ctx.set(dut.pixels.ready, 1)
        await ctx.tick().repeat(7)  # a few pairs in
        assert ctx.get(dut.waiting)
        ctx.set(dut.stop, 1)
        await ctx.tick()
        ctx.set(dut.stop, 0)
        assert not ctx.get(dut.waiting) and not ctx.get(dut.bytes.ready) and not ctx.get(dut.done)
        ctx.set(dut.start, 1)
        await ctx.tick()
        ctx.set(dut.start, 0)
        assert ctx.get(dut.waiting) and ctx.get(dut.fed) == 0

    _simulate(dut, bench)


def test_control_serializer_is_encode_record() -> None:
    rnd = random.Random(3)
    records = [(rnd.randrange(256), rnd.randrange(256), rnd.randrange(1 << 80)) for _ in range(6)]
    want = b"".join(pr.encode_record(t, s, p.to_bytes(10, "little")) for t, s, p in records)
    dut = ControlSerializer()
    got: list = []

    async def source(ctx) -> None:  # noqa: ANN001
        await _feed(ctx, dut.records, [{"type": t, "seq": s, "payload": p} for t, s, p in records], rnd)

    async def sink(ctx) -> None:  # noqa: ANN001
        await _take(ctx, dut.bytes, got, len(want), random.Random(4))

    _simulate(dut, source, sink)
    assert bytes(b.data for b in got) == want
    assert [i for i, b in enumerate(got) if b.last] == [16 * k + 15 for k in range(len(records))]


def _random_results(params: object, n: int, seed: int) -> MachineResult:
    rng = np.random.default_rng(seed)
    return MachineResult(
        map=rng.integers(0, params.rows, n).astype(np.int32),  # type: ignore[attr-defined]
        nomatch=rng.integers(0, 2, n).astype(bool), timeout=rng.integers(0, 2, n).astype(bool),
        counts=rng.integers(0, params.readout_max + 1, (n, params.rows)).astype(np.uint32),  # type: ignore[attr-defined]
        cycles=rng.integers(0, params.max_clocks + 1, n).astype(np.int64))  # type: ignore[attr-defined]


@pytest.mark.parametrize(("fields", "integrator"), [(0, "stochastic"), (1, "stochastic"), (2, "stochastic"),
                                                    (3, "stochastic"), (3, "log"), (1, "log")])
def test_result_serializer_is_its_twin(fields: int, integrator: str) -> None:
    # Two-byte counters (a log machine's weights, up to 2^8 at W = 8) and cycles.
    params = (small_params(counter_max=300, max_cycles=5000) if integrator == "stochastic" else
              MachineParams(rows=5, columns=2, word_bits=8, words_per_beat=3, nomatch_row=True,
                            integrator="log"))
    res = _random_results(params, 5, fields)
    tag = pr.RESULT_TAG if fields % 2 else pr.pass_tag(fields)  # the own pass's records, a declared one's
    twin = ResultSerializerTwin(params, tag)
    want = twin.send(res, fields)
    dut = ResultSerializer(params=params, tag=tag)
    got: list = []
    seen: dict[str, int] = {}
    beats = [{"map": int(res.map[i]), "nomatch": int(res.nomatch[i]), "timeout": int(res.timeout[i]),
              "cycles": int(res.cycles[i]), "counts": [int(c) for c in res.counts[i]]}
             for i in range(len(res))]

    async def source(ctx) -> None:  # noqa: ANN001
        ctx.set(dut.fields, fields)
        ctx.set(dut.clear, 1)
        await ctx.tick()
        ctx.set(dut.clear, 0)
        await _feed(ctx, dut.results, beats, random.Random(fields))

    async def sink(ctx) -> None:  # noqa: ANN001
        await _take(ctx, dut.bytes, got, len(want), random.Random(fields + 10))
        await ctx.tick()
        seen.update({name: ctx.get(getattr(dut, name)) for name in ("taken", "sent", "crc", "busy")})

    _simulate(dut, source, sink)
    assert bytes(b.data for b in got) == want
    record = pr.ResultFormat.of(params, fields).record_bytes
    assert [i for i, b in enumerate(got) if b.last] == [record * k + record - 1 for k in range(len(res))]
    assert {got[record * k].data for k in range(len(res))} == {tag}
    assert seen == {"taken": 5, "sent": 5, "crc": zlib.crc32(want), "busy": 0} and twin.crc == seen["crc"]


@pytest.mark.parametrize("streams", [1, 3])
def test_transmit_arbiter_is_its_twin_cycle_by_cycle(streams: int) -> None:
    """Control records and ``streams`` result streams (a model's passes) onto one byte stream, whole
    records, control first, then the result streams in their order."""
    dut = TransmitArbiter(results=streams)
    twin = TransmitArbiterTwin()
    rnd = random.Random(5 + streams)
    names = ["control", *(f"results{i}" for i in range(streams))]
    ports = [dut.control, *dut.results]
    # Records of 1..5 bytes from each side, offered with gaps; the UART ready now and then.
    queues = {name: [(rnd.randrange(256), i == n - 1) for _ in range(12) for n in [rnd.randint(1, 5)]
                     for i in range(n)] for name in names}
    sent: list[int] = []

    async def bench(ctx) -> None:  # noqa: ANN001
        at = dict.fromkeys(names, 0)
        for _ in range(600 * (streams + 1)):
            offers = {}
            for name, port in zip(names, ports, strict=True):
                q, i = queues[name], at[name]
                valid = i < len(q) and rnd.random() < 0.7
                byte, last = q[i] if i < len(q) else (0, False)
                ctx.set(port.valid, valid)
                ctx.set(port.payload, {"data": byte, "last": last})
                offers[name] = (valid, byte, last)
            ready = rnd.random() < 0.5
            ctx.set(dut.bytes.ready, ready)
            want = twin.step(offers["control"], [offers[n] for n in names[1:]], ready)
            got = {"control_ready": ctx.get(dut.control.ready),
                   "results_ready": [ctx.get(r.ready) for r in dut.results],
                   "valid": ctx.get(dut.bytes.valid), "byte": ctx.get(dut.bytes.payload),
                   "busy": ctx.get(dut.busy)}
            want["results_ready"] = [int(r) for r in want["results_ready"]]
            assert {k: v if isinstance(v, list) else int(v) for k, v in got.items()} == \
                {k: v if isinstance(v, list) else int(v) for k, v in want.items()}
            readies = [want["control_ready"], *want["results_ready"]]
            for name, taken in zip(names, readies, strict=True):
                at[name] += bool(offers[name][0] and taken)
            if want["valid"] and ready:
                sent.append(want["byte"])
            await ctx.tick()
        assert at == {name: len(q) for name, q in queues.items()}  # everything went out

    _simulate(dut, bench)
    assert len(sent) == sum(len(q) for q in queues.values())


def test_receive_timeout_and_leds_are_their_twins() -> None:
    timeout, leds = ReceiveTimeout(cycles=5), StatusLEDs()
    t_twin, l_twin = ReceiveTimeoutTwin(5), StatusLEDsTwin()
    rnd = random.Random(6)
    fired = 0

    async def bench(ctx) -> None:  # noqa: ANN001
        nonlocal fired
        for _ in range(400):
            waiting, busy = rnd.random() < 0.9, rnd.random() < 0.1
            flags = [rnd.random() < 0.5 for _ in range(5)]
            ctx.set(timeout.waiting, waiting)
            ctx.set(timeout.busy, busy)
            ports = (leds.in_frame, leds.error, leds.overflow, leds.received, leds.sent)
            for port, value in zip(ports, flags, strict=True):
                ctx.set(port, value)
            want = t_twin.step(waiting, busy)
            assert ctx.get(timeout.fired) == want
            assert ctx.get(leds.leds) == l_twin.step(*flags)
            fired += want
            await ctx.tick()

    both = Module()
    both.submodules.timeout, both.submodules.leds = timeout, leds
    _simulate(both, bench)
    assert fired >= 3


WIDTH, DMAX = 12, 2
MODEL = ModelParams(name="paper", dmax=DMAX)


def _control_run(headers: list[bytes], records: int, *, frame_done: bool = True, crc_ok: bool = True,
                 dropped_at: int | None = None, model: ModelParams = MODEL,
                 row_results: int | None = None) -> list[bytes]:
    """The ``records`` :class:`ProtocolControl` sends for ``headers`` (raw records, parsed by the twin),
    its frame receiver and result serializers stood in for: a frame's results all sent at once
    (``row_results`` per map row: every pass's); the frame done (``crc_ok``) or, without ``frame_done``,
    the receive timeout firing."""
    info = pr.info_payload(WIDTH, DMAX + 2, 11, 0x1234)
    dut = ProtocolControl(width=WIDTH, dmax=DMAX, margin=model.margin, info=info, row_results=row_results)
    row = dut.row_results
    parser = HeaderParserTwin()
    parsed = [h for raw in headers for b in raw if (h := parser.feed(b)) is not None]
    got: list = []

    async def host(ctx) -> None:  # noqa: ANN001
        for i, h in enumerate(parsed):
            ctx.set(dut.headers.payload, {"record": {"type": h.type, "seq": h.seq,
                                                     "payload": int.from_bytes(h.payload, "little")},
                                          "crc_ok": h.crc_ok})
            ctx.set(dut.headers.valid, 1)
            await ctx.tick().until(dut.headers.ready)
            ctx.set(dut.headers.valid, 0)
            if i == dropped_at:
                ctx.set(dut.dropped, 1)
                await ctx.tick()
                ctx.set(dut.dropped, 0)
            while ctx.get(dut.in_frame):  # the frame: its results, then done or the timeout
                if ctx.get(dut.receiving):
                    await ctx.tick().repeat(3)
                    ctx.set(dut.results_sent, (ctx.get(dut.height) - 2 * model.margin) * row)
                    ctx.set(dut.results_crc, 0xC0FFEE)
                    ctx.set(dut.frame_done if frame_done else dut.timed_out, 1)
                    ctx.set(dut.crc_ok, crc_ok)
                await ctx.tick()
            ctx.set(dut.frame_done, 0)
            ctx.set(dut.timed_out, 0)
            ctx.set(dut.results_sent, 0)

    async def sink(ctx) -> None:  # noqa: ANN001
        await _take(ctx, dut.records, got, records, random.Random(7), stall=0.5)

    _simulate(dut, host, sink)
    return [pr.encode_record(r.type, r.seq, r.payload.to_bytes(10, "little")) for r in got]


def _control_twin(headers: list[bytes], model: ModelParams = MODEL) -> tuple[BoardTwin, list[bytes]]:
    params = small_params(rows=DMAX + 2) if model is MODEL else stereo_machine_params(DMAX, model=model)
    twin = BoardTwin(params, model, WIDTH, results=None, rx_fifo_log2=11)  # type: ignore[arg-type]
    twin.info = pr.info_payload(WIDTH, DMAX + 2, 11, 0x1234)
    parser = HeaderParserTwin()
    answers = [twin.reset()]
    for raw in headers:
        for b in raw:
            if (h := parser.feed(b)) is not None:
                answers.append(twin.answer(h))
    return twin, answers


def test_protocol_control_answers_as_the_twin() -> None:
    bad = bytearray(pr.frame_header(2, 3, WIDTH, 9))
    bad[9] ^= 4
    headers = [pr.encode_record(pr.INFO, 1), bytes(bad), pr.encode_record(0x51, 3),
               pr.frame_header(4, 1, WIDTH + 1, 9), pr.frame_header(5, 3, WIDTH, 4),
               pr.frame_header(6, 2, WIDTH, 9)]
    _, answers = _control_twin(headers)
    sent = (9 - 4) * (WIDTH - 4 - DMAX)
    want = [*answers, BoardTwin.end_record(6, pr.STATUS_OK, sent, 0xC0FFEE)]
    assert _control_run(headers, len(want)) == want


def test_protocol_control_counts_every_pass_results() -> None:
    """census-lr: the start record announces both passes' results (per map row the output pixels and
    the right pass's every right map column), and the end record waits until all of them are sent."""
    lr = ModelParams(name="census-lr", dmax=DMAX)
    row = (WIDTH - 6 - DMAX) + (WIDTH - 6)
    headers = [pr.frame_header(6, 2, WIDTH, 9)]
    _, answers = _control_twin(headers, lr)
    start = pr.decode_record(answers[-1])
    assert start.kind == pr.START and struct.unpack("<I", start.payload[5:9])[0] == (9 - 6) * row
    want = [*answers, BoardTwin.end_record(6, pr.STATUS_OK, (9 - 6) * row, 0xC0FFEE)]
    assert _control_run(headers, len(want), model=lr, row_results=row) == want
    with pytest.raises(ValueError, match="row_results"):
        ProtocolControl(width=WIDTH, dmax=DMAX, margin=3, info=bytes(10), row_results=WIDTH - 7 - DMAX)


@pytest.mark.parametrize(("kw", "status"), [({"crc_ok": False}, pr.STATUS_CHECKSUM),
                                            ({"frame_done": False}, pr.STATUS_TIMEOUT),
                                            ({"dropped_at": 0}, pr.STATUS_OVERFLOW),
                                            ({"dropped_at": 0, "frame_done": False}, pr.STATUS_OVERFLOW)])
def test_protocol_control_ends_a_frame_with_its_status(kw: dict, status: int) -> None:
    headers = [pr.frame_header(9, 3, WIDTH, 7)]
    _, answers = _control_twin(headers)
    got = _control_run(headers, len(answers) + 1, **kw)
    assert got[:-1] == answers
    end = pr.decode_record(got[-1])
    assert end.kind == pr.END and end.seq == 9 and struct.unpack("<BII", end.payload[:9]) == (
        status, 3 * (WIDTH - 4 - DMAX), 0xC0FFEE)


@pytest.mark.parametrize(("cls", "kwargs", "error"), [
    (ReceiveTimeout, {"cycles": 1}, ValueError), (ReceiveTimeout, {"cycles": 2.0}, TypeError),
    (ResultSerializer, {"params": "paper"}, TypeError),
    (ResultSerializer, {"params": small_params(), "tag": ord("X")}, ValueError),
    (TransmitArbiter, {"results": 0}, ValueError),
    (FrameReceiver, {"width": 8, "dmax": 4, "margin": 2}, ValueError),
    (ProtocolControl, {"width": 12, "dmax": 2, "margin": 2, "info": b"short"}, ValueError),
])
def test_components_check_their_parameters(cls: type, kwargs: dict, error: type) -> None:
    with pytest.raises(error):
        cls(**kwargs)


def test_the_simulated_boards_cache_keys_on_every_rtl_module() -> None:
    """``RTL_MODULES`` (the Verilog cache key of ``board simulate``) lists every module of
    fpga/boards that BoardCore's module imports, however deep: an edit to any of them rebuilds."""
    import ast
    from pathlib import Path

    from bayesmachine.fpga.boards import core

    boards = Path(core.__file__).parent
    seen, todo = set(), ["core.py"]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for node in ast.walk(ast.parse((boards / name).read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                todo += [f"{node.module}.py"] if node.module else [f"{a.name}.py" for a in node.names]
    assert seen <= set(core.RTL_MODULES), sorted(seen - set(core.RTL_MODULES))
