"""The throughput figures of ``synth``'s report (fpga/report.py): pixels and frames per second of a
machine, of the StereoMachine and of a measured frame, and what the Markdown report says of them."""

from __future__ import annotations

import pytest


def test_frame_throughput_figures() -> None:
    """Frames per second = fmax / the measured frame's wall cycles; the input is every pixel pair."""
    from bayesmachine.fpga.report import frame_throughput, markdown

    frame = {"output_pixels": 264_656, "frame_wall_cycles": 2_000_000, "pair": "a frame",
             "wall_cycles_per_pixel": 7.557, "compute_cycles_per_pixel": 7.0, "equals_model": False}
    t = frame_throughput(120.0, frame, 640)
    assert t["vga_fps"] == pytest.approx(60.0) and t["frame"] == "640x480"
    assert t["pixels_per_second"] == pytest.approx(60.0 * 264_656, rel=1e-6)
    assert t["input_bits_per_second"] == pytest.approx(16 * 640 * 480 * 60.0, rel=1e-6)
    assert t["fmax_for_camera_rate_mhz"] == pytest.approx(120.0)  # the clock that gives 60 fps
    untimed = frame_throughput(None, frame, 640)
    assert "vga_fps" not in untimed and untimed["fmax_for_camera_rate_mhz"] == pytest.approx(120.0)
    report = {"target": "ecp5-85k", "device": "LFE5U-85F", "machine_summary": "m", "pin_width": 8,
              "resources": {"lut4": 1, "carry": 1, "ff": 1, "bram": 1, "dsp": 0, "lutram": 0},
              "utilization": {"lut4": 0.1, "ff": 0.1, "bram": 0.1}, "machines_fit": 1, "machines": 1,
              "per_operator": {"lut4": 1.0, "ff": 1.0}, "per_machine": {"lut4": 1.0, "ff": 1.0},
              "stereo": {"fifo_pixels": 8, "fifo_beats": 112, "width": 640, "beat_bits": 330},
              "fmax_mhz": 120.0, "throughput": t, "measured": "a test"}
    text = markdown(report)
    assert "DIFFERENT from the model's" in text  # a mismatch is said, not hidden
    assert "60 frames/s would need 120.0 MHz" in text


def test_stereo_throughput_figures() -> None:
    from bayesmachine.fpga.report import stereo_throughput

    t = stereo_throughput(100.0, 25.0, 640, 80)  # VGA, Dmax 80: 476 x 556 output pixels
    assert t["frame"] == "640x480" and t["frame_output_pixels"] == 264_656
    assert t["input_bits_per_pixel"] == pytest.approx(16 * 640 * 480 / 264_656, abs=0.01)
    assert t["pixels_per_second"] == pytest.approx(4e6)
    assert t["vga_fps"] == pytest.approx(4e6 / 264_656, abs=0.01)
    assert t["input_bits_per_second"] == pytest.approx(16 * 640 * 480 * 4e6 / 264_656, rel=1e-6)
    assert set(stereo_throughput(None, 25.0, 640, 80)) == {"frame", "frame_output_pixels",
                                                          "input_bits_per_pixel", "assumes"}
    with pytest.raises(ValueError, match="no output pixel"):
        stereo_throughput(100.0, 25.0, 84, 80)


def test_throughput_figures() -> None:
    from bayesmachine.fpga.report import VGA_PIXELS, throughput

    t = throughput(100.0, 2, 25.0, 8, 176)  # compute-bound: 2 lanes x 4 Mpx/s < 12.5 Mpx/s of loads
    assert t["pixels_per_second"] == pytest.approx(8e6)
    assert t["vga_fps"] == pytest.approx(8e6 / VGA_PIXELS, abs=0.01)
    assert not t["load_bound"]
    assert t["load_bits_per_second"] == pytest.approx(8e6 * 8 * 176)
    t = throughput(100.0, 4, 25.0, 16, 176)  # load-bound: one beat per cycle, 16 per pixel
    assert t["load_bound"] and t["pixels_per_second"] == pytest.approx(100e6 / 16)
