"""The pixel engines' one contract and registry (``sim.engines``): the board is the engine ``board``,
reached by name (its twin at the other end of the link here), with the same frame checks as the
Verilator engine and the model's results."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_same_results, frame_results

from bayesmachine.fpga.boards import protocol as pr
from bayesmachine.fpga.boards.link import BoardError
from bayesmachine.models import ModelParams
from bayesmachine.sim.engines import (
    PIXEL_ENGINES,
    EngineClosedError,
    PixelEngineBase,
    check_pixel_engine_options,
    get_pixel_engine,
)

from .test_board import DMAX, HEIGHT, MODEL, PARAMS, WIDTH, TwinPort, _crop, _twin


def _board(twin=None, **options):  # noqa: ANN001, ANN202
    port = TwinPort(twin or _twin())
    port.close = lambda: None
    return get_pixel_engine("board", PARAMS, MODEL, WIDTH, port="twin", link_port=port, progress=False,
                            **options)


def test_the_registry_names_the_pixel_engines() -> None:
    assert PIXEL_ENGINES == ("verilator", "board")
    with pytest.raises(ValueError, match="unknown pixel engine 'model': choose one of verilator, board"):
        get_pixel_engine("model", PARAMS, MODEL, WIDTH)
    with pytest.raises(ValueError, match="engine 'board' does not take option.s. trace"):
        get_pixel_engine("board", PARAMS, MODEL, WIDTH, port="x", trace=(0, 1, "w.vcd"))


def test_the_board_engine_gives_the_model_results() -> None:
    left, right = _crop()
    with _board() as engine:
        assert isinstance(engine, PixelEngineBase)
        assert engine.wall_cycles is None and engine.last_passes == {}
        got = engine.run(left, right)
        again = engine.run(left, right)  # the board resets its machine at every frame
        figures = engine.figures
    want = frame_results(PARAMS, MODEL, left, right)
    assert_same_results(got, want)
    assert_same_results(again, want)
    assert figures["attempts"] == 2 and figures["fields"] == ["map", "counts", "cycles"]
    assert figures["bytes_sent"] > 2 * (2 * WIDTH * HEIGHT) and figures["wall_seconds"] > 0
    with pytest.raises(EngineClosedError):
        engine.run(left, right)


def test_the_board_engine_without_counts_and_cycles() -> None:
    left, right = _crop()
    with _board(fields="map") as engine:
        got = engine.run(left, right)
    want = frame_results(PARAMS, MODEL, left, right)
    assert got.counts is None and got.cycles is None
    for name in ("map", "nomatch", "timeout"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


def test_pixel_engines_check_a_frame_alike() -> None:
    left, right = _crop()
    with _board() as engine:
        with pytest.raises(ValueError, match="built for 16-pixel lines, the frame has 15"):
            engine.run(left[:, :-1], right[:, :-1])
        with pytest.raises(ValueError, match="at least 5 lines"):
            engine.run(left[:4], right[:4])
        with pytest.raises(ValueError, match="2-D uint8"):
            engine.run(left.astype(np.int16), right)
        with pytest.raises(ValueError, match="differ in shape"):
            engine.run(left, right[:-1])


def test_the_board_engine_refuses_a_board_built_for_something_else() -> None:
    with pytest.raises(BoardError, match=f"built for {WIDTH + 2}-pixel lines, the pair has {WIDTH}"):
        _board(_twin(WIDTH + 2))
    other = ModelParams(name="paper", dmax=DMAX, sigma_m=5.0)
    twin = _twin()
    twin.fingerprint = pr.board_fingerprint(PARAMS.to_dict(), other.to_dict(), WIDTH)
    twin.info = pr.info_payload(WIDTH, PARAMS.rows, 12, twin.fingerprint)
    with pytest.raises(BoardError, match="built for another machine or model"):
        _board(twin)


@pytest.mark.parametrize(("options", "error", "message"), [
    ({"port": "p", "fields": "map,depth"}, ValueError, "unknown field 'depth'"),
    ({"port": "p", "fields": 7}, ValueError, r"fields must be an integer in \[0, 3\], got 7"),
    ({"port": "p", "baud": 0}, ValueError, "baud must be an integer >= 1, got 0"),
    ({"port": "p", "baud": 1.5}, TypeError, "baud must be an integer"),
    ({"port": "p", "timeout": -1.0}, ValueError, "timeout must be positive"),
    ({"port": "p", "depth": 1}, ValueError, "does not take option.s. depth"),
])
def test_board_options_are_checked_before_any_work(options: dict, error: type, message: str) -> None:
    with pytest.raises(error, match=message):
        check_pixel_engine_options("board", **options)
