"""A machine's cycles per pixel measured on the bundled pair: the throughput figures of
``bayesmachine synth`` (:func:`bayesmachine.fpga.synth.synth` takes :func:`measure_cycles` as its
``measure``; the command line passes it)."""

from __future__ import annotations

from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams

__all__ = ["measure_cycles"]


def measure_cycles(params: MachineParams, model: ModelParams, progress: bool = True) -> dict[str, object]:
    """Compute and wall cycles per pixel of ``params`` running the disparity ``model``'s words of the
    bundled pair (the model engine's cycles, and the RTL's per-pixel timing ``pixel_wall_cycles`` on
    top: loading included)."""
    from bayesmachine.hdl.machine import pixel_wall_cycles

    from .images import bundled_pair
    from .run import prepare, run_machine

    left, right, _ = bundled_pair()
    # The cycles need the machine only: no float64 reference.
    prepared = prepare(left, right, model, reference=False)
    run = run_machine(prepared, params, "model", progress=progress, chunk_rows=32)
    c, timeout = run.cycles.reshape(-1), run.timeout.reshape(-1)
    return {
        "pair": f"bundled Middlebury Motorcycle {left.shape[1]}x{left.shape[0]}, model engine",
        "pixels": int(c.size),
        "samples_per_clock": params.samples_per_clock,
        "compute_cycles_per_pixel": round(float(c.mean()), 3),
        "wall_cycles_per_pixel": round(float(pixel_wall_cycles(params, c, timeout).mean()), 3),
    }
