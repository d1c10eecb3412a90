"""``--feed pixels``: the ``StereoMachine`` (front end + FIFO + machine) compiled with Verilator.

``StereoVerilatorEngine(params, model, width).run(left, right)`` streams a rectified pair into the
design's pixel port (16 bits per pixel pair; the host computes nothing) and returns the machine's
result for every output pixel, in raster order of the output region: the same
:class:`MachineResult` as ``MachineModel(params).run(memory_words(...))`` on the host's words,
bit for bit. Frames run back to back in one simulation (the machine's random sources carry over,
as in the model); the front end restarts at each frame's first pixel. ``wall_cycles`` counts
every clock cycle since reset, filtering and loading included. With ``machines`` = K > 1 the design
is ``StereoMachine(machines=K)`` and its results are ``host.run.machines_model``'s (map row r on
machine r mod K, each machine's random source over its own rows). A model with declared passes
(census-lr's right pass) has a machine per pass beside the own one; the harness also collects each
pass's results (``<pass>_result``) and the engine keeps the last frame's as ``last_passes[name]`` (every
pixel of the pass of every output row, raster order: a right-reference pass's every right map column).

With an off-chip random source (``rng = "smtj"``) the design's ``entropy`` port is fed, one row
per compute cycle, from the kind's device model, one stream from reset on, exactly as the word
engines feed the machine's (``MachineModel(params).run(words)`` without ``numbers``): the
harness asks for rows as the machine consumes them. ``external`` has no device model, so it
cannot run here.

Everything but the design and the harness's protocol is the Verilator engine's
(:mod:`bayesmachine.sim.verilator`): the wrapper and header helpers (``codegen``), the build
cache (``build.build_design``: builds under ``<cache>/stereo-<key>/``), the harness process
and the result decoding (``engine.HarnessProcess``, ``decode_results``). The harness is
``harness/stereo.cpp`` (with ``harness/common.h``), its header generated from the layouts.
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
import time
from pathlib import Path
from typing import Any

import numpy as np

from bayesmachine.hdl.signatures import pixel_in_layout
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.sim.activity import ACTIVITY_FLAGS, activity_env
from bayesmachine.sim.engines import PixelEngineBase
from bayesmachine.sim.results import MachineResult, NumberFeed, decode_results, layout_fields, result_words
from bayesmachine.sim.verilator import VerilatorError, cache_dir, find_toolchain
from bayesmachine.sim.verilator.build import HarnessSources, VerilatorBuild, build_design, cached_verilog
from bayesmachine.sim.verilator.codegen import entropy_header, header_prologue, wrapper_verilog
from bayesmachine.sim.verilator.engine import HarnessProcess

__all__ = ["StereoVerilatorEngine", "build_stereo_harness", "pass_ports"]

HEADER = "stereo_design.h"
_MAGIC_FRAME = 0x46534D42  # "BMSF", see harness/stereo.cpp


def stereo_header(params: MachineParams, model: ModelParams, width: int, signature: Any,
                  machines: int = 1) -> str:
    """``stereo_design.h``: the shared prologue (ports, result size), the pixel beat's offsets and,
    with an off-chip source, the entropy port's (fed as in the machine's harness); per declared pass
    (:func:`pass_ports`) its results' size and pixels per map row, and ``take_passes``, which collects
    the results on their ports."""
    ports = {"PIXELS_PAYLOAD": ("pixels", "payload"), "PIXELS_VALID": ("pixels", "valid"),
             "PIXELS_READY": ("pixels", "ready"), "RESULT_PAYLOAD": ("result", "payload"),
             "RESULT_VALID": ("result", "valid")}
    entropy_ports, external = entropy_header(params, signature)
    pix = layout_fields(pixel_in_layout())
    # A hung design: no pixel taken and no result for longer than a pixel's longest run and a line.
    # (K machines: a frame's first pixel may wait for every machine to go idle.)
    hang = machines * (params.max_clocks + 8 * params.words_per_pixel + 2 * model.margin * width + 64)
    passes = pass_ports(params, model, width)
    for i, (name, pp, _) in enumerate(passes):
        ports |= {f"PASS{i}_PAYLOAD": (f"{name}_result", "payload"),
                  f"PASS{i}_VALID": (f"{name}_result", "valid")}
        # The pass's longest run and a line's flush of Dmax pixels.
        hang += pp.max_clocks + (model.dmax + 1) * 8 * pp.words_per_pixel
    prologue = header_prologue(signature, params, ports | entropy_ports, hang_cycles=hang,
                               generator="bayesmachine.sim.stereo_engine")
    return prologue + f"""static const unsigned WIDTH = {width};
static const unsigned DMAX = {model.dmax};
static const unsigned MARGIN = {model.margin};  // the output region's (bayesmachine.region)
static const unsigned LEFT_OFFSET = {pix["left"][0]}, RIGHT_OFFSET = {pix["right"][0]};
static const unsigned FIRST_OFFSET = {pix["first"][0]};
{_passes_header(passes)}{external}"""


def pass_ports(params: MachineParams, model: ModelParams, width: int) -> list[tuple[str, MachineParams, int]]:
    """Per declared pass of ``model`` (in order): its name (its results on ``<name>_result``), its
    machine on chip and its pixels (results) per map row of ``width``-pixel frames."""
    from bayesmachine.hdl.frontend.passes import pass_row_pixels
    from bayesmachine.hdl.frontend.words import pass_params

    return [(p.name, pass_params(model, params, p.name), pass_row_pixels(model, p.name, width))
            for p in model.passes[:-1]]


def _passes_header(passes: list[tuple[str, MachineParams, int]]) -> str:
    """``BM_PASSES``, ``PASS_WORDS``, ``PASS_ROW_PIXELS`` and ``BM_TAKE_PASSES(top, records, collected,
    expected, any)``: each declared pass's valid result this cycle into its records (a macro: it expands
    after common.h, whose ``get_port`` it calls)."""
    words = [result_words(pp) for _, pp, _ in passes]
    rows = [n for *_, n in passes]
    takes = "".join(f"""    if ((top).BM_PORT_PASS{i}_VALID) {{ \\
        if ((collected)[{i}] >= (expected)[{i}]) fail("more {name}-pass results than its pixels"); \\
        uint32_t buf{i}[{w} + 2] = {{0}}; \\
        get_port((top).BM_PORT_PASS{i}_PAYLOAD, buf{i}); \\
        std::memcpy(&(records)[{i}][(collected)[{i}]++ * {w}], buf{i}, {w} * sizeof(uint32_t)); \\
        (any) = true; \\
    }} \\
""" for i, ((name, _, _), w) in enumerate(zip(passes, words, strict=True)))
    return f"""#define BM_PASSES {len(passes)}
static const unsigned PASS_WORDS[BM_PASSES + 1] = {{{", ".join(map(str, [*words, 0]))}}};
static const unsigned PASS_ROW_PIXELS[BM_PASSES + 1] = {{{", ".join(map(str, [*rows, 0]))}}};
// Each declared pass's result this cycle (observed as it leaves: the wrapper ties its ready high).
#define BM_TAKE_PASSES(top, records, collected, expected, any) \\
    do {{ \\
{takes}    }} while (0)
"""


def build_stereo_harness(
    params: MachineParams,
    model: ModelParams,
    width: int,
    fifo_pixels: int = 8,
    build_dir: str | os.PathLike[str] | None = None,
    machines: int = 1,
    activity: bool = False,
    **options: Any,
) -> VerilatorBuild:
    """Compile (or find in the cache) the stereo harness, through the Verilator engine's build cache
    (``options``: ``jobs``, ``verbose``, as :func:`~bayesmachine.sim.verilator.build.build_design`).
    ``activity``: a build that counts every signal bit's toggles (:mod:`bayesmachine.sim.activity`)."""
    from bayesmachine.hdl.frontend.stereo import StereoMachine, check_stereo_machine, stereo_signature

    find_toolchain()  # a missing tool is reported before the seconds of emitting the Verilog
    check_stereo_machine(params, model, width, fifo_pixels, machines)  # as StereoMachine's constructor
    signature = stereo_signature(params, model)
    root = Path(build_dir) if build_dir is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    key: list[object] = [params.to_dict(), model.to_dict(), width, fifo_pixels]
    design_key = json.dumps(key + ([machines] if machines != 1 else []))
    name = f"stereo-{hashlib.sha256(design_key.encode()).hexdigest()[:20]}"

    def build_top() -> StereoMachine:
        return StereoMachine(params=params, model=model, width=width, fifo_pixels=fifo_pixels,
                             machines=machines)

    design = HarnessSources(
        verilog=cached_verilog(name, build_top, root),
        wrapper=wrapper_verilog(signature),
        header=stereo_header(params, model, width, signature, machines),
        sources=("stereo.cpp",),
        label=f"the stereo machine, Dmax {model.dmax}, width {width}, {machines} machine(s),",
        header_name=HEADER,
        extra_flags=ACTIVITY_FLAGS if activity else (),
        info={"params": params.to_dict(), "model": model.to_dict(), "width": width,
              "fifo_pixels": fifo_pixels, "machines": machines, "activity": activity},
        prefix="stereo-",
    )
    return build_design(design, build_dir=root, **options)


class StereoVerilatorEngine(HarnessProcess, PixelEngineBase):
    """Pixel pairs through the compiled ``StereoMachine`` (the pixel engine ``verilator``,
    :class:`~bayesmachine.sim.engines.PixelEngine`); results as ``MachineModel`` gives them for the
    host's words of the same frames.

    ``run(left, right)``: one frame ((H, width) uint8 each, H >= 2k + 1 for the model's margin k);
    returns the results of its (H - 2k) x (width - 2k - Dmax) output pixels, row-major. The
    engines' life cycle otherwise:
    ``reset()`` (a hardware reset: the next frame starts a fresh simulation), ``close()`` (then
    ``run()``/``reset()`` raise ``EngineClosedError``), ``EngineStateError`` after a frame cut
    short, ``wall_cycles`` since reset. After each frame, as the Verilator engine:
    ``last_wall_cycles`` (first pixel presented to last result taken), ``last_compute_cycles``
    and ``stats``. ``activity``: a directory where the harness, built to count every signal bit's
    toggles, writes each frame's (:func:`bayesmachine.sim.activity.activity_env`).
    """

    name = "verilator"
    OPTIONS = ("fifo_pixels", "build_dir", "jobs", "verbose", "machines", "activity")

    def __init__(
        self,
        params: MachineParams,
        model: ModelParams,
        width: int,
        *,
        fifo_pixels: int = 8,
        build_dir: str | os.PathLike[str] | None = None,
        jobs: int = 2,
        verbose: bool = True,
        machines: int = 1,
        activity: str | os.PathLike[str] | None = None,
    ) -> None:
        kind = params.source  # None: the machine draws no random numbers
        if params.takes_numbers and kind.numbers is None:  # type: ignore[union-attr]
            raise ValueError(f"--feed pixels feeds an off-chip source from its device model; rng = "
                             f"{params.rng!r} has none (its numbers come from the caller)")
        super().__init__(params, model, width)  # last_passes: the declared passes' results of the last frame
        self._kind = kind
        self._feed = NumberFeed(params)
        self.machines = machines
        self._args: list[str] = []
        self.build = build_stereo_harness(params, model, width, fifo_pixels=fifo_pixels, build_dir=build_dir,
                                          machines=machines, activity=activity is not None, jobs=jobs,
                                          verbose=verbose)
        self._env = activity_env(activity, self.build)  # each frame's toggle counts (harness/common.h)
        self._init_process()

    def run(self, left: np.ndarray, right: np.ndarray) -> MachineResult:
        self._check_open()
        n = self._check_frame(left, right).pixels
        height, width = left.shape
        k = self.model.margin
        pairs = np.stack([left, right], axis=-1).astype(np.uint8)
        with self._in_flight():
            proc = self._start()
            t0 = time.perf_counter()
            try:
                self._write(proc, struct.pack("<IIII", _MAGIC_FRAME, 0, height, width), pairs.tobytes())
                self._serve_numbers(proc, self._numbers() if self.params.takes_numbers else None)
                out = self._read_results(proc, n, t0)
                # then each declared pass's results, every pixel of the pass of every output row
                self.last_passes = {name: self._read_pass(proc, pp, (height - 2 * k) * row)
                                    for name, pp, row in pass_ports(self.params, self.model, width)}
                return out
            except (VerilatorError, ValueError):
                raise
            except BaseException:
                self._kill()  # an interrupt leaves the pipes mid-frame
                raise

    def _read_pass(self, proc: Any, pp: MachineParams, n: int) -> MachineResult:
        """A declared pass's ``n`` raw payloads (its machine ``pp``'s) after the DONE reply, decoded."""
        words = result_words(pp)
        raw = self._read(proc, n * words * 4)
        return decode_results(pp, np.frombuffer(raw, dtype="<u4", count=n * words).reshape(n, words))

    def _numbers(self) -> NumberFeed:
        """The device model's stream (one from reset on: a fresh harness holds no rows)."""
        if self._feed.source is None:
            assert self._kind.numbers is not None
            self._feed.use(self._kind.numbers(self.params))
        return self._feed

    def _reset(self) -> None:
        super()._reset()
        self._feed.use(None)  # a hardware reset: the device model starts a fresh stream
