"""A machine's cycles measured on the bundled pair: the throughput figures of ``bayesmachine synth``
(:func:`bayesmachine.fpga.synth.synth` takes :func:`measure_cycles` as its ``measure``; the command line
passes it).

The machine alone: the model engine's cycles on the whole pair and the RTL's per-pixel timing on top.
The camera-fed StereoMachine: the same design under Verilator on a frame of its line width and 480
lines cut from the pair (:func:`measure_frame`), its wall cycles counted from the frame's first pixel
in to its last result out, and every result checked against the model engine's."""

from __future__ import annotations

import numpy as np

from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams
from bayesmachine.region import VGA_HEIGHT

from .records import MachineRun

__all__ = ["FRAME_HEIGHT", "frame_crop", "measure_cycles", "measure_frame"]

FRAME_HEIGHT = VGA_HEIGHT  # the StereoMachine's frame rate is measured on frames this tall


def measure_cycles(params: MachineParams, model: ModelParams, progress: bool = True, *,
                   stereo: dict[str, int] | None = None) -> dict[str, object]:
    """Compute and wall cycles per pixel of ``params`` running the disparity ``model``'s words of the
    bundled pair (the model engine's cycles, and the RTL's per-pixel timing ``pixel_wall_cycles`` on
    top: loading included).

    ``stereo`` (``width``, ``fifo_pixels``, ``machines``: a StereoMachine's): the frame measured by
    :func:`measure_frame` too, under the key ``"frame_run"`` (None where the pair is narrower than
    the line)."""
    from .images import bundled_pair
    from .run import prepare, run_machine

    left, right, _ = bundled_pair()
    # The cycles need the machine only: no float64 reference.
    prepared = prepare(left, right, model, reference=False)
    run = run_machine(prepared, params, "model", progress=progress, chunk_rows=32)
    c, timeout = run.cycles.reshape(-1), run.timeout.reshape(-1)
    out: dict[str, object] = {
        "pair": f"bundled Middlebury Motorcycle {left.shape[1]}x{left.shape[0]}, model engine",
        "pixels": int(c.size),
        "samples_per_clock": params.samples_per_clock,
        "compute_cycles_per_pixel": round(float(c.mean()), 3),
        "wall_cycles_per_pixel": round(float(params.kind.pixel_wall_cycles(params, c, timeout).mean()), 3),
    }
    if stereo is not None:
        out["frame_run"] = measure_frame(params, model, progress=progress, **stereo)
    return out


def frame_crop(width: int, shape: tuple[int, int]) -> tuple[int, int] | None:
    """The top-left corner (x, y) of the ``width`` x :data:`FRAME_HEIGHT` frame centred in an image of
    ``shape`` (rows, columns); None if the image is smaller."""
    h, w = shape
    if width > w or FRAME_HEIGHT > h:
        return None
    return (w - width) // 2, (h - FRAME_HEIGHT) // 2


def measure_frame(params: MachineParams, model: ModelParams, *, width: int, fifo_pixels: int,
                  machines: int = 1, progress: bool = True) -> dict[str, object] | None:
    """The StereoMachine (``params``, ``model``, ``width``-pixel lines, ``fifo_pixels``, ``machines``)
    under Verilator on the ``width`` x 480 frame centred in the bundled pair (:func:`frame_crop`):
    its wall cycles (first pixel in to last result out) and whether its maps, counts, cycles and
    timeouts equal the model engine's on the same frame (``run --engine model``; census-lr's right
    pass's too). None if the pair is narrower than ``width``."""
    from bayesmachine.sim.verilator.tools import VerilatorError

    from .images import Crop, bundled_pair, crop_image
    from .run import prepare, run_machine

    left, right, _ = bundled_pair()
    corner = frame_crop(width, left.shape)
    if corner is None:
        return None
    crop = Crop(*corner, width, FRAME_HEIGHT)
    prepared = prepare(crop_image(left, crop), crop_image(right, crop), model, reference=False)
    want = run_machine(prepared, params, "model", progress=progress, machines=machines,
                       chunk_rows=1 if machines > 1 else 32)
    got = run_machine(prepared, params, "verilator", progress=progress, feed="pixels", machines=machines,
                      engine_options={"fifo_pixels": fifo_pixels, "verbose": progress})
    if got.wall_cycles is None:
        raise VerilatorError("the StereoMachine's Verilator run reported no wall cycles")
    pixels = int(want.cycles.size)
    return {
        "pair": f"{width}x{FRAME_HEIGHT} crop at ({crop.x}, {crop.y}) of the bundled Middlebury Motorcycle, "
                f"the StereoMachine under Verilator (--feed pixels), {machines} machine(s)",
        "crop": str(crop),
        "frame_wall_cycles": int(got.wall_cycles),
        "output_pixels": pixels,
        "wall_cycles_per_pixel": round(got.wall_cycles / pixels, 3),
        "compute_cycles_per_pixel": round(float(want.cycles.mean()), 3),
        "equals_model": _same_run(got, want),
    }


def _same_run(got: MachineRun, want: MachineRun) -> bool:
    """Whether two runs' maps, counts, cycles, timeouts and no-match flags (and each declared pass's
    MAPs, cycles and timeouts: census-lr's right pass) are equal."""
    names = ("map", "counts", "cycles", "timeout", "nomatch")
    if not all(np.array_equal(getattr(got, n), getattr(want, n)) for n in names):
        return False
    if got.passes.keys() != want.passes.keys():
        return False
    return all(np.array_equal(getattr(got.passes[k], n), getattr(want.passes[k], n))
               for k in got.passes for n in ("map", "cycles", "timeout"))
