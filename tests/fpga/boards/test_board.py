"""The board's protocol, its Python twin and the host link (fpga/boards), without Verilator: the link
talks to the twin through a port that loses, garbles or resets on demand, and must come back with
the model's results or a clear error, never a wrong result."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from conftest import assert_same_results, frame_results, passes_model

from bayesmachine.cli import main
from bayesmachine.fpga.boards import protocol as pr
from bayesmachine.fpga.boards.core import check_board
from bayesmachine.fpga.boards.devices import pll_config
from bayesmachine.fpga.boards.link import BoardError, BoardLink
from bayesmachine.fpga.boards.twin import BoardTwin
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.host.images import bundled_pair
from bayesmachine.models import BOARD_MODEL, DEFAULT_MODEL, ModelParams
from bayesmachine.params import ParameterError

DMAX = 4
WIDTH = DMAX + 12
HEIGHT = 12
MODEL = ModelParams(name="paper", dmax=DMAX)
PARAMS = stereo_machine_params(DMAX, model=MODEL)


def _twin(width: int = WIDTH) -> BoardTwin:
    return BoardTwin(PARAMS, MODEL, width,
                     results=lambda left, right: frame_results(PARAMS, MODEL, left, right))


def _crop(x: int = 300, y: int = 200) -> tuple[np.ndarray, np.ndarray]:
    left, right, _ = bundled_pair()
    return (left[y : y + HEIGHT, x : x + WIDTH].copy(), right[y : y + HEIGHT, x : x + WIDTH].copy())


class TwinPort:
    """A serial port with the twin at its other end. Faults (byte indices of the whole host -> board
    stream, or of the board -> host one): ``drop``, ``garble``, ``reset`` (the board resets after that
    byte), ``garble_back``; ``mute``: the board never answers. A read that finds nothing while the
    twin is mid-frame is the board's receive timeout firing."""

    def __init__(self, twin: BoardTwin, *, drop=(), garble=(), reset=(), garble_back=(), mute=False):
        self.twin, self.mute = twin, mute
        self.drop, self.garble, self.reset, self.garble_back = (
            set(drop),
            set(garble),
            set(reset),
            set(garble_back),
        )
        self.sent = self.back = 0
        self.rx = bytearray()
        self.timeout = 1.0

    def write(self, data: bytes) -> None:
        for b in data:
            i = self.sent
            self.sent += 1
            if i in self.drop:
                continue
            if i in self.garble:
                b ^= 0x55
            self._deliver(self.twin.feed(bytes([b])))
            if i in self.reset:
                self._deliver(self.twin.reset())

    def _deliver(self, data: bytes) -> None:
        if self.mute:
            return
        for b in data:
            self.rx.append(b ^ 0x55 if self.back in self.garble_back else b)
            self.back += 1

    @property
    def in_waiting(self) -> int:
        return len(self.rx)

    def read(self, n: int) -> bytes:
        if not self.rx:
            self._deliver(self.twin.silence())
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out

    def reset_input_buffer(self) -> None:
        self.rx.clear()


def _link(port: TwinPort) -> BoardLink:
    return BoardLink(port, timeout=0.05, log=lambda msg: None)


def _assert_model(
    got: dict[str, dict[str, np.ndarray]], left: np.ndarray, right: np.ndarray, fields: int = pr.FIELDS_ALL
):
    assert list(got) == ["left"]  # the paper model: its own pass
    out = got["left"]
    want = frame_results(PARAMS, MODEL, left, right)
    assert len(out["map"]) == (HEIGHT - 4) * (WIDTH - 4 - DMAX)
    names = (
        ["map", "nomatch", "timeout"]
        + (["counts"] if fields & 1 else [])
        + (["cycles"] if fields & 2 else [])
    )
    assert sorted(out) == sorted(names)
    for name in names:
        np.testing.assert_array_equal(out[name], np.asarray(getattr(want, name)), err_msg=name)


def test_record_round_trip_and_crc() -> None:
    raw = pr.encode_record(pr.FRAME, 300, struct.pack("<BHH", 3, 640, 480))
    assert len(raw) == pr.RECORD_BYTES and raw[:2] == b"BM"
    rec = pr.decode_record(raw)
    assert rec is not None and rec.kind == pr.FRAME and rec.seq == 300 % 256 and rec.name == "frame"
    for i in range(2, pr.RECORD_BYTES):  # any garbled byte fails the CRC
        bad = bytearray(raw)
        bad[i] ^= 0x01
        assert pr.decode_record(bytes(bad)) is None
    with pytest.raises(ValueError, match="payload"):
        pr.encode_record(pr.INFO, 0, bytes(11))


@pytest.mark.parametrize("fields", [0, 1, 2, 3])
def test_result_format_round_trip(fields: int) -> None:
    fmt = pr.ResultFormat.of(PARAMS, fields)
    rng = np.random.default_rng(fields)
    n = 7
    res = {
        "map": rng.integers(0, PARAMS.rows, n),
        "nomatch": rng.integers(0, 2, n).astype(bool),
        "timeout": rng.integers(0, 2, n).astype(bool),
        "counts": rng.integers(0, PARAMS.counter_max + 1, (n, PARAMS.rows)),
        "cycles": rng.integers(0, PARAMS.max_cycles, n),
    }
    raw = fmt.encode(res["map"], res["nomatch"], res["timeout"], res["counts"], res["cycles"])
    assert len(raw) == n * fmt.record_bytes
    back = fmt.decode(raw)
    for name, value in back.items():
        np.testing.assert_array_equal(value, res[name])
    assert ("counts" in back) == bool(fields & 1) and ("cycles" in back) == bool(fields & 2)
    with pytest.raises(ValueError, match="tag"):
        fmt.decode(b"X" + raw[1:])


def test_twin_answers_info_and_refuses_bad_headers() -> None:
    twin = _twin()
    hello = pr.decode_record(twin.reset())
    assert hello is not None and hello.kind == pr.HELLO
    info = pr.parse_info(pr.decode_record(twin.feed(b"junk" + pr.encode_record(pr.INFO, 9))).payload)
    assert (info.width, info.rows, info.version) == (WIDTH, PARAMS.rows, pr.PROTOCOL_VERSION)
    assert info.fingerprint == pr.board_fingerprint(PARAMS.to_dict(), MODEL.to_dict(), WIDTH)
    bad = bytearray(pr.frame_header(1, 3, WIDTH, HEIGHT))
    bad[6] ^= 1
    err = pr.decode_record(twin.feed(bytes(bad)))
    assert err.kind == pr.ERROR and err.payload[0] == pr.ERR_HEADER
    err = pr.decode_record(twin.feed(pr.frame_header(2, 3, WIDTH + 1, HEIGHT)))
    assert err.kind == pr.ERROR and err.payload[0] == pr.ERR_SIZE
    assert struct.unpack("<H", err.payload[1:3])[0] == WIDTH


@pytest.mark.parametrize("fields", [pr.FIELDS_ALL, 0])
def test_link_gives_the_model_results(fields: int) -> None:
    left, right = _crop()
    port = TwinPort(_twin())
    link = _link(port)
    out = link.run_frame(left, right, PARAMS, MODEL, fields)
    _assert_model(out, left, right, fields)
    assert link.stats.attempts == 1 and not link.stats.failures


HEADER_AND_SOME = pr.RECORD_BYTES + 2 * WIDTH * 6 + 3  # a byte in the middle of the pixels


@pytest.mark.parametrize(
    "fault, reason",
    [
        ({"garble": [HEADER_AND_SOME]}, "checksum"),
        ({"garble": [pr.RECORD_BYTES + 5]}, "header"),  # after the info request
        ({"drop": [HEADER_AND_SOME]}, "stopped coming"),
        ({"reset": [HEADER_AND_SOME]}, "reset"),
        ({"garble_back": [pr.RECORD_BYTES * 2 + 40]}, ""),
    ],
)
def test_link_recovers_from_a_fault(fault: dict, reason: str) -> None:
    """A garbled, dropped byte or a board reset fails the attempt (saying why), the frame is sent
    again and the results are the model's."""
    left, right = _crop()
    port = TwinPort(_twin(), **fault)
    link = _link(port)
    link.info()
    out = link.run_frame(left, right, PARAMS, MODEL)
    _assert_model(out, left, right)
    assert link.stats.attempts == 2
    assert reason in link.stats.failures[0]


def test_link_never_accepts_a_frame_that_keeps_failing() -> None:
    left, right = _crop()
    step = pr.RECORD_BYTES + 2 * WIDTH * HEIGHT + 4  # one attempt's bytes, after the info request's
    port = TwinPort(
        _twin(), garble=[pr.RECORD_BYTES + 100 + k * step for k in range(8)]
    )
    link = _link(port)
    link.info()
    with pytest.raises(BoardError, match="failed the frame 4 times"):
        link.run_frame(left, right, PARAMS, MODEL)


def test_link_says_when_the_board_does_not_answer() -> None:
    port = TwinPort(_twin(), mute=True)
    with pytest.raises(BoardError, match="did not answer within"):
        _link(port).info()


def test_link_refuses_a_frame_of_another_width() -> None:
    left, right = _crop()
    port = TwinPort(_twin(WIDTH + 2))
    with pytest.raises(BoardError, match=f"built for {WIDTH + 2}-pixel lines"):
        _link(port).run_frame(left, right, PARAMS, MODEL)


@pytest.mark.parametrize(("fields", "fault"), [(pr.FIELDS_ALL, {}), (0, {}),
                                               (pr.FIELDS_ALL, {"garble_back": [pr.RECORD_BYTES * 2 + 300]})])
def test_link_gives_every_pass_of_census_lr(fields: int, fault: dict) -> None:
    """census-lr on a board: the right pass's records (tag 'a') beside the left pass's ('R'), the end
    record's count and XOR of the two passes' CRCs; every pass's results are the model's (a byte garbled
    on the way back: the attempt fails, the frame is sent again)."""
    model = ModelParams(dmax=DMAX, name="census-lr")
    params = stereo_machine_params(DMAX, model=model)
    left, right = _crop()
    twin = BoardTwin(params, model, WIDTH, results=lambda lf, rf: passes_model([(lf, rf)], model, params))
    link = _link(TwinPort(twin, **fault))
    link.info()
    got = link.run_frame(left, right, params, model, fields)
    want = passes_model([(left, right)], model, params)
    assert set(got) == {"left", "right"} and len(got["right"]["map"]) == (HEIGHT - 6) * (WIDTH - 6)
    for name, res in want.items():
        for field in got[name]:
            np.testing.assert_array_equal(got[name][field], np.asarray(getattr(res, field)), err_msg=field)
        assert ("cycles" in got[name]) == bool(fields & pr.FIELD_CYCLES)
    assert link.stats.attempts == 1 + bool(fault)


@pytest.mark.usefixtures("lr_like")
def test_link_gives_every_pass_of_a_model_from_its_definition() -> None:
    """A model defined outside the package (``conftest.lr_like``: a right pass and a left-reference pass
    beside its own): tags 'a' and 'b' by the passes' order in its definition, every pass's results the
    model's, the link's frame of every pass's records."""
    from bayesmachine.fpga.boards.protocol import board_passes

    model = ModelParams(dmax=DMAX, name="lr-like")
    params = stereo_machine_params(DMAX, model=model)
    assert [(bp.name, chr(bp.tag)) for bp in board_passes(params, model)] == [("mirror", "a"), ("echo", "b"),
                                                                                ("left", "R")]
    left, right = _crop()
    twin = BoardTwin(params, model, WIDTH, results=lambda lf, rf: passes_model([(lf, rf)], model, params))
    got = _link(TwinPort(twin)).run_frame(left, right, params, model)
    want = passes_model([(left, right)], model, params)
    assert set(got) == {"mirror", "echo", "left"} and len(got["echo"]["map"]) == len(got["left"]["map"])
    for name, res in want.items():
        for field in ("map", "nomatch", "timeout", "counts", "cycles"):
            np.testing.assert_array_equal(got[name][field], np.asarray(getattr(res, field)), err_msg=field)


def test_board_engine_gives_the_declared_passes_too() -> None:
    """``run --engine board`` of census-lr: the own pass's results and ``last_passes['right']``."""
    from bayesmachine.fpga.boards.engine import BoardEngine

    model = ModelParams(dmax=DMAX, name="census-lr")
    params = stereo_machine_params(DMAX, model=model)
    left, right = _crop()
    twin = BoardTwin(params, model, WIDTH, results=lambda lf, rf: passes_model([(lf, rf)], model, params))
    want = passes_model([(left, right)], model, params)
    with BoardEngine(params, model, WIDTH, port="twin", timeout=0.05, progress=False,
                     link_port=TwinPort(twin)) as engine:
        assert_same_results(engine.run(left, right), want["left"])
        assert list(engine.last_passes) == ["right"]
        assert_same_results(engine.last_passes["right"], want["right"])


def test_board_refuses_off_chip_sources() -> None:
    smtj = stereo_machine_params(DMAX, model=MODEL, rng="smtj")
    with pytest.raises(ParameterError, match="on-chip random source"):
        check_board(smtj, MODEL, WIDTH)
    lr = ModelParams(dmax=DMAX, name="census-lr")
    with pytest.raises(ParameterError, match="^rng must be an on-chip random source for the census-lr model"):
        check_board(stereo_machine_params(DMAX, model=lr, rng="smtj"), lr, WIDTH)


def test_pll_config() -> None:
    pll = pll_config(60.0)
    assert pll.out_mhz == 60.0 and 400 <= pll.vco_mhz <= 800
    with pytest.raises(ValueError, match="clock"):
        pll_config(500.0)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["run", "--engine", "board", "-o", "{out}"], "--engine board needs --port"),
        (["run", "--port", "/dev/null", "-o", "{out}"], "--port: only with --engine board"),
        (
            ["run", "--engine", "board", "--port", "/dev/null", "--model", "census-lr", "--rng", "lfsr",
             "--dmax", "4", "--crop", "300,200,16,12", "-o", "{out}"],
            "cannot open /dev/null",
        ),
        (["board", "simulate", "--model", "census-lr", "--rng", "smtj"],
         "--rng: rng must be an on-chip random source for the census-lr model on chip"),
        (["board", "build", "--baud", "11000000", "--dmax", "4", "--width", "16"], None),
    ],
)
def test_cli_errors(argv: list[str], message: str | None, tmp_path, capsys) -> None:
    argv = [a.replace("{out}", str(tmp_path / "out")) for a in argv]
    if message is None:  # the baud check comes before any tool runs
        message = "clocks per bit"
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_cli_board_fields_map_only(tmp_path, monkeypatch) -> None:
    """``run --engine board --board-fields map``: the board sends MAP records only (fewer bytes back),
    result.npz has the model's MAP and no counts or cycles, report.json says null for their figures."""
    import json

    from bayesmachine.fpga.boards import link as link_mod

    ports: list[TwinPort] = []

    def open_twin(port: str, baud: int, timeout: float = 2.0) -> TwinPort:
        ports.append(TwinPort(_twin()))
        ports[-1].close = lambda: None
        return ports[-1]

    monkeypatch.setattr(link_mod, "open_port", open_twin)
    crop = ["--crop", f"400,250,{WIDTH},{HEIGHT}", "--dmax", str(DMAX), "--model", "paper"]
    common = ["run", *crop, "--no-sgbm", "--quiet"]
    for name, extra in (("map", ["--board-fields", "map"]), ("all", [])):
        argv = [*common, "--engine", "board", "--port", "twin", *extra, "-o", str(tmp_path / name)]
        assert main(argv) == 0
    assert main([*common, "-o", str(tmp_path / "model")]) == 0
    got, full, want = (np.load(tmp_path / n / "result.npz") for n in ("map", "all", "model"))
    # no counts, so no confidence (its maps are functions of the counts): none is made up
    assert sorted(got.files) == sorted(set(want.files) - {"counts", "cycles", "mass", "confidence", "entropy",
                                                          "nomatch_mass", "filled_confidence"})
    assert sorted(full.files) == sorted(want.files)
    for name in got.files:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    rep, rep_all = (json.loads((tmp_path / n / "report.json").read_text()) for n in ("map", "all"))
    assert rep["board"]["fields"] == ["map"] and rep_all["board"]["fields"] == ["map", "counts", "cycles"]
    assert rep["rms_error"] is None and rep["cycles_per_pixel_mean"] is None and rep["frame_cycles"] is None
    assert rep_all["rms_error"] is not None and rep_all["frame_cycles"] == int(want["cycles"].sum())
    assert rep["map_agreement"] == rep_all["map_agreement"]
    assert 0 < rep["board"]["bytes_received"] < rep_all["board"]["bytes_received"] / 3


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--engine", "board", "--port", "twin", "--board-fields", "map,depth"], "unknown field 'depth'"),
        (["--engine", "board", "--port", "twin", "--board-fields", ","], "--board-fields: give map"),
        (["--board-fields", "map"], "--board-fields: only with --engine board"),
    ],
)
def test_cli_board_fields_errors(extra: list[str], message: str, tmp_path, capsys) -> None:
    assert main(["run", "--dmax", str(DMAX), *extra, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "extra, router, seed", [([], "router1", 1), (["--router", "router2", "--pnr-seed", "3"], "router2", 3)]
)
def test_board_build_routes_with_router1_by_default(extra: list[str], router: str, seed: int, tmp_path,
                                                     monkeypatch) -> None:
    """`board build` hands nextpnr router1 unless told otherwise: router2 does not converge on the
    census design on the ULX3S-85F (docs/board.md). The tools are stood in for; the run stops at
    nextpnr's command line."""
    from bayesmachine.fpga import flow

    class Stop(Exception):
        pass

    seen: list[list[str]] = []

    def fake_run(cmd: list[str], cwd, log: str, what: str, progress) -> None:
        if log == "nextpnr":
            seen.append(cmd)
            raise Stop

    monkeypatch.setattr(flow, "_run", fake_run)
    monkeypatch.setattr(flow, "_tool", lambda name: name)
    out = tmp_path / "b"
    with pytest.raises(Stop):
        main(["board", "build", "--dmax", "4", "--width", "16", "--model", "paper", *extra, "-o", str(out)])
    (cmd,) = seen
    assert cmd[cmd.index("--router") + 1] == router and cmd[cmd.index("--seed") + 1] == str(seed)
    assert not (out / "report.json").exists()  # stopped before the end: nothing half-written


def _twin_on_port(monkeypatch) -> None:
    from bayesmachine.fpga.boards import link as link_mod

    def open_twin(port: str, baud: int, timeout: float = 2.0) -> TwinPort:
        port = TwinPort(_twin())
        port.close = lambda: None
        return port

    monkeypatch.setattr(link_mod, "open_port", open_twin)


class StandInHarness:
    """``BoardSimulation`` stood in for: a harness that has ended at once (``board simulate`` then
    reports and stops)."""

    def __init__(self, params, model, width, **options) -> None:
        self.port, self.running = "/dev/pts/stand-in", False

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass


def test_board_simulate_writes_its_report_and_a_run_names_the_options_that_differ(tmp_path, monkeypatch,
                                                                                   capsys) -> None:
    """``board simulate -o OUT`` writes OUT/report.json (the design, its fingerprint) and records the
    design; a run whose options give another fingerprint names the option that differs. The harness
    is stood in for (no Verilator): it ends at once, after the report."""
    import json

    from bayesmachine.fpga.boards import simulate as simulate_mod

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(simulate_mod, "BoardSimulation", StandInHarness)
    out = tmp_path / "sim"
    assert main(["board", "simulate", "--dmax", str(DMAX), "--width", str(WIDTH), "--model", "paper",
                 "--quiet", "-o", str(out)]) == 2  # the stand-in harness ended
    assert "ended unexpectedly" in capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert report["fingerprint"] == f"{pr.board_fingerprint(PARAMS.to_dict(), MODEL.to_dict(), WIDTH):08x}"
    assert report["machine"] == PARAMS.to_dict() and report["port"] == "/dev/pts/stand-in"
    _twin_on_port(monkeypatch)
    run = ["run", "--crop", f"400,250,{WIDTH},{HEIGHT}", "--dmax", str(DMAX), "--model", "paper", "--no-sgbm",
           "--quiet", "--engine", "board", "--port", "twin"]
    assert main([*run, "--counter-max", "4", "--seed", "7", "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "built for another machine or model" in err and len(err.strip().splitlines()) == 1
    assert f"--counter-max 4 here, {PARAMS.counter_max} on the board; --seed 7 here, {PARAMS.seed} on" in err
    assert main([*run, "-o", str(tmp_path / "r")]) == 0  # the board's own options
    # A board this machine has no record of: the message says where its options are.
    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(tmp_path / "elsewhere"))
    assert main([*run, "--counter-max", "4", "-o", str(tmp_path / "r2")]) == 2
    assert "no record of the board's design: run with the options it was built with (the report.json" in \
        capsys.readouterr().err


def test_a_port_in_use_is_refused_at_once(tmp_path) -> None:
    """Two runs on one port (``board simulate``'s pseudo-terminal): the second is told it is in use."""
    import os
    import pty

    from bayesmachine.fpga.boards.link import open_port

    pytest.importorskip("serial")
    master, slave = pty.openpty()
    try:
        first = open_port(os.ttyname(slave), 3_000_000)
        try:
            with pytest.raises(BoardError, match="is in use: another run is talking to the board on it"):
                open_port(os.ttyname(slave), 3_000_000)
        finally:
            first.close()
        open_port(os.ttyname(slave), 3_000_000).close()  # free again
    finally:
        os.close(master)
        os.close(slave)


LOG_MODEL = ModelParams(name="census-lr", dmax=DMAX)  # two passes and the neighbour prior's feedback


LOG_PARAMS = stereo_machine_params(DMAX, model=LOG_MODEL, integrator="log")


def _log_twin() -> BoardTwin:
    return BoardTwin(LOG_PARAMS, LOG_MODEL, WIDTH,
                     results=lambda lf, rf: passes_model([(lf, rf)], LOG_MODEL, LOG_PARAMS))


def test_a_log_machines_records_carry_its_weights() -> None:
    """A weight is up to 2^W = 1024 (11 bits, where the stochastic machine's counter max 16 takes 5):
    two bytes per row; the cycles (1 clock a pixel without the neighbour prior) one byte. A 16 x 12
    frame of the paper model at Dmax 4 is 64 records and the start and end records, 992 bytes."""
    paper = ModelParams(name="paper", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=paper, integrator="log")
    fmt = pr.ResultFormat.of(params, pr.FIELDS_ALL)
    assert (fmt.count_width, fmt.count_bytes, fmt.record_bytes) == (11, 2, 15)
    assert 64 * fmt.record_bytes + 2 * pr.RECORD_BYTES == 992
    weights = np.array([[1024, 0, 37, 1023, 1, 512], [0, 0, 0, 0, 0, 1024]])
    raw = fmt.encode(np.array([0, 5]), np.array([False, True]), np.array([False, False]), weights,
                     np.array([1, 5]))
    back = fmt.decode(raw)
    np.testing.assert_array_equal(back["counts"], weights)
    np.testing.assert_array_equal(back["map"], [0, 5])
    np.testing.assert_array_equal(back["cycles"], [1, 5])


@pytest.mark.parametrize("fields", [pr.FIELDS_ALL, pr.FIELD_COUNTS])
def test_link_gives_the_log_models_results(fields: int) -> None:
    """Every pass of census-lr on the log machine through the link: the log model's maps, flags, weights
    (the MAP's row weighs 2^W) and cycles."""
    left, right = _crop()
    got = _link(TwinPort(_log_twin())).run_frame(left, right, LOG_PARAMS, LOG_MODEL, fields)
    want = passes_model([(left, right)], LOG_MODEL, LOG_PARAMS)
    assert set(got) == {"left", "right"}
    for name, res in want.items():
        assert sorted(got[name]) == sorted(["map", "nomatch", "timeout", "counts",
                                            *(["cycles"] if fields & pr.FIELD_CYCLES else [])])
        for field in got[name]:
            np.testing.assert_array_equal(got[name][field], np.asarray(getattr(res, field)), err_msg=field)
        assert got[name]["counts"].max() == LOG_PARAMS.readout_max == 1024


def test_the_log_board_commands(tmp_path, monkeypatch, capsys) -> None:
    """``board simulate --integrator log -o OUT`` reports the log machine's design; ``run --engine board
    --integrator log`` on it writes the result.npz of ``run --engine model --integrator log``, array for
    array; a stochastic run is told the integrator differs, a stochastic option is refused, each in one
    line. The harness is stood in for by the twin at the other end of the port."""
    from bayesmachine.fpga.boards import link as link_mod
    from bayesmachine.fpga.boards import simulate as simulate_mod

    def open_twin(port: str, baud: int, timeout: float = 2.0) -> TwinPort:
        twin_port = TwinPort(_log_twin())
        twin_port.close = lambda: None
        return twin_port

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(simulate_mod, "BoardSimulation", StandInHarness)
    monkeypatch.setattr(link_mod, "open_port", open_twin)
    design = ["--dmax", str(DMAX), "--model", "census-lr"]
    assert main(["board", "simulate", *design, "--integrator", "log", "--width", str(WIDTH), "--quiet", "-o",
                 str(tmp_path / "sim")]) == 2  # the stand-in harness ended
    capsys.readouterr()
    report = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert report["machine"] == LOG_PARAMS.to_dict() and report["machine"]["integrator"] == "log"
    run = ["run", "--crop", f"400,250,{WIDTH},{HEIGHT}", *design, "--no-sgbm", "--quiet"]
    assert main([*run, "--integrator", "log", "--engine", "board", "--port", "twin", "-o",
                 str(tmp_path / "b")]) == 0
    assert main([*run, "--integrator", "log", "-o", str(tmp_path / "m")]) == 0
    got, want = np.load(tmp_path / "b" / "result.npz"), np.load(tmp_path / "m" / "result.npz")
    assert sorted(got.files) == sorted(want.files) and "right_map" in want.files
    for name in want.files:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert want["counts"].max() == 1024
    for extra, message in ((["--engine", "board", "--port", "twin"],
                            "--integrator stochastic here, log on the board; run with the board's options"),
                           (["--integrator", "log", "--engine", "board", "--port", "twin", "--seed", "3"],
                            "--seed: without effect on the logarithmic machine")):
        assert main([*run, *extra, "-o", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x").exists()


def test_board_build_without_a_model_builds_the_boards_default(tmp_path, monkeypatch, capsys) -> None:
    """``board build`` without ``--model`` builds census-lr (``BOARD_MODEL``), not the library's default
    census-sgm, which ``--model census-sgm`` asks for (the board carries one machine a pass, as it
    needs); the build itself is stood in for."""
    from bayesmachine.fpga.boards import build as build_mod

    built = []

    def fake_build(machine, model, width, board, out, **kwargs):  # noqa: ANN001, ANN003, ANN202
        built.append(model)
        return {"fmax_mhz": 50.0, "constraint_mhz": 45.0, "timing_met": True, "baud": kwargs["baud"],
                "program": "program", "program_alternative": "alternative"}

    monkeypatch.setenv("BAYESMACHINE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(build_mod, "board_build", fake_build)
    design = ["--dmax", str(DMAX), "--width", str(WIDTH)]
    assert main(["board", "build", *design, "-o", str(tmp_path / "a")]) == 0
    assert main(["board", "build", *design, "--model", "census-sgm", "-o", str(tmp_path / "b")]) == 0
    assert (BOARD_MODEL, DEFAULT_MODEL) == ("census-lr", "census-sgm")
    assert built == [ModelParams(name=BOARD_MODEL, dmax=DMAX), ModelParams(name="census-sgm", dmax=DMAX)]
    assert "timing met" in capsys.readouterr().out


def test_board_build_elaborates_the_log_machine(tmp_path, monkeypatch) -> None:
    """``board build --integrator log`` builds the board's StereoMachine on the log machine (its argmin
    tree in the RTLIL Yosys gets) and goes on to place and route; the tools are stood in for, the run
    stops at nextpnr's command line."""
    from bayesmachine.fpga import flow

    class Stop(Exception):
        pass

    def fake_run(cmd: list[str], cwd, log: str, what: str, progress) -> None:
        if log == "nextpnr":
            raise Stop

    monkeypatch.setattr(flow, "_run", fake_run)
    monkeypatch.setattr(flow, "_tool", lambda name: name)
    out = tmp_path / "b"
    with pytest.raises(Stop):
        main(["board", "build", "--integrator", "log", "--dmax", "4", "--width", "16", "-o", str(out)])
    rtlil = (out / "work" / "top.il").read_text()
    assert "argmin" in rtlil and "encoder" not in rtlil  # not the stochastic machine's MAP encoder
    assert not (out / "report.json").exists()
