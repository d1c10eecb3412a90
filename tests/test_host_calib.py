"""Calibration files (host/calib.py), depth in metres and the PLY cloud (host/cloud.py): each format
read into the same numbers, every wrong or missing field one clear error, and the cloud read back by a
PLY parser written here from the spec (not the writer), its depths fx * baseline / (d + doffs)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.host.calib import StereoCalibration, bundled_calibration_path, read_calibration
from bayesmachine.host.datasets import load_calibration, resolve_dataset
from bayesmachine.host.images import Crop

# The rectified P_rect_02 / P_rect_03 of KITTI raw's 2011_09_26 calib_cam_to_cam.txt (images 1242x375).
KITTI_P2 = ("7.215377e+02 0 6.095593e+02 4.485728e+01 0 7.215377e+02 1.728540e+02 2.163791e-01 "
            "0 0 1 2.745884e-03")
KITTI_P3 = ("7.215377e+02 0 6.095593e+02 -3.395242e+02 0 7.215377e+02 1.728540e+02 2.199936e+00 "
            "0 0 1 2.729905e-03")


def test_the_bundled_calibration_is_middlebury_scaled_to_the_pair() -> None:
    calib = read_calibration(bundled_calibration_path())
    # Middlebury 2014 Motorcycle: cam0 f 3979.911, cx 1244.772, cy 1019.507, doffs 124.343, baseline
    # 193.001 mm, 2964x2000; scikit-image's pair is that reduced by 4 (741x500).
    assert (calib.fx, calib.cx, calib.cy, calib.doffs) == pytest.approx(
        (3979.911 / 4, 1244.772 / 4, 1019.507 / 4, 124.343 / 4))
    assert calib.baseline == pytest.approx(0.193001) and (calib.width, calib.height) == (741, 500)
    # Depth does not change with the reduction: Z = f B / (d + doffs) at full size and at quarter size.
    assert calib.depth(np.array([10.0]))[0] == pytest.approx(3979.911 * 0.193001 / (40 + 124.343))
    depth = calib.depth(np.array([-1, 0, np.nan]))
    assert np.isnan(depth[0]) and np.isnan(depth[2])
    assert depth[1] == pytest.approx(calib.fx * 0.193001 / calib.doffs)


def test_kitti_json_and_middlebury_give_the_same_calibration(tmp_path) -> None:
    (tmp_path / "calib.txt").write_text(f"P0: {KITTI_P2}\nP1: {KITTI_P3}\nP2: {KITTI_P2}\nP3: {KITTI_P3}\n")
    (tmp_path / "cam_to_cam.txt").write_text(
        f"calib_time: 09-Jan-2012\nS_rect_02: 1.242000e+03 3.750000e+02\nP_rect_02: {KITTI_P2}\n"
        f"P_rect_03: {KITTI_P3}\n")
    kitti = read_calibration(tmp_path / "calib.txt")
    rect = read_calibration(tmp_path / "cam_to_cam.txt")
    baseline = (44.85728 + 339.5242) / 721.5377
    for c in (kitti, rect):
        assert (c.fx, c.fy, c.cx, c.cy, c.doffs) == pytest.approx((721.5377, 721.5377, 609.5593, 172.854, 0))
        assert c.baseline == pytest.approx(baseline)
    assert (rect.width, rect.height) == (1242, 375) and kitti.width is None
    assert read_calibration(tmp_path / "calib.txt", cameras=(0, 1)).baseline == pytest.approx(baseline)
    fields = {"fx": 721.5377, "fy": 721.5377, "cx": 609.5593, "cy": 172.854, "baseline": baseline}
    (tmp_path / "c.json").write_text(json.dumps(fields))
    assert read_calibration(tmp_path / "c.json").depth([20.0]) == pytest.approx(kitti.depth([20.0]))
    assert kitti.depth([0.0])[0] == np.inf  # doffs 0: disparity 0 is a point at infinity


MIDDLEBURY = "cam0=[1000 0 300; 0 1000 250; 0 0 1]\ncam1=[1000 0 330; 0 1000 250; 0 0 1]\ndoffs=30\n" \
             "baseline=200\nwidth=640\nheight=480\n"


@pytest.mark.parametrize("name, text, message", [
    ("calib.txt", MIDDLEBURY.replace("baseline=200\n", ""), "baseline missing"),
    ("calib.txt", MIDDLEBURY.replace("doffs=30", "doffs=7.5"), "doffs=7.5 and cam1 disagree"),
    ("calib.txt", MIDDLEBURY.replace("cam0=[1000 0 300;", "cam0=[1000 0 x;"), "cam0: expected 9 numbers"),
    ("calib.txt", MIDDLEBURY.replace("baseline=200", "baseline=-200"),
     "baseline must be a finite number in [0.001, 1e+09] mm, got -200"),
    ("calib.txt", f"P2: {KITTI_P2}\n", "without P3"),
    ("calib.txt", f"P2: {KITTI_P3}\nP3: {KITTI_P2}\n", "is not to the right of"),
    ("c.json", '{"fx": 700, "fy": 700, "cx": 300, "cy": 200}', "missing baseline"),
    ("c.json", '{"fx": 700, "fy": 700, "cx": 300, "cy": 200, "baseline": 0.5, "base": 1}', "unknown base"),
    ("c.json", '{"fx": "700", "fy": 700, "cx": 300, "cy": 200, "baseline": 0.5}', "fx must be a number"),
    ("c.json", '[1, 2]', "expected a JSON object"),
    ("calib.txt", "focal 700\n", "not a calibration this reads"),
])
def test_wrong_or_missing_fields_are_named(tmp_path, name, text, message) -> None:
    (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)):
        read_calibration(tmp_path / name)


def test_size_is_checked_and_a_crop_moves_the_principal_point(tmp_path) -> None:
    calib = StereoCalibration(fx=1000, fy=1000, cx=300, cy=250, baseline=0.2, doffs=30, width=640, height=480)
    with pytest.raises(ValueError, match="for 640x480 images, the pair is 320x240"):
        calib.for_input((240, 320))
    cut = calib.for_input((480, 640), Crop(100, 50, 200, 100))
    assert (cut.cx, cut.cy, cut.width, cut.height) == (200, 200, 200, 100)
    with pytest.raises(TypeError):
        StereoCalibration(1000, 1000, 300, 250, 0.2)  # keyword-only


def read_ply(path: Path) -> tuple[list[str], np.ndarray]:
    """A binary little-endian PLY's header lines and its vertices, parsed by the PLY spec."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert header[0] == "ply" and header[1] == "format binary_little_endian 1.0"
    count = next(int(h.split()[2]) for h in header if h.startswith("element vertex "))
    types = {"float": "<f4", "uchar": "u1"}
    props = [h.split()[1:] for h in header if h.startswith("property ")]
    dtype = np.dtype([(name, types[kind]) for kind, name in props])
    assert len(data) - end == count * dtype.itemsize
    return header, np.frombuffer(data[end:], dtype=dtype)


def test_cloud_points_are_at_the_calibrated_depth(tmp_path) -> None:
    out = tmp_path / "o"
    crop = Crop(300, 150, 130, 32)
    assert main(["run", "--crop", str(crop), "--dmax", "64", "--model", "census", "--no-sgbm", "--quiet",
                 "--calib", "bundled", "-o", str(out)]) == 0
    res = np.load(out / "result.npz")
    header, points = read_ply(out / "cloud.ply")
    assert [h.split()[-1] for h in header if h.startswith("property")] == \
        ["x", "y", "z", "red", "green", "blue", "confidence"]
    dmap = res["map"].astype(np.float64)
    matched = dmap >= 0
    f, baseline, doffs = 3979.911 / 4, 0.193001, 124.343 / 4
    want_z = f * baseline / (dmap[matched] + doffs)
    np.testing.assert_allclose(points["z"], want_z, rtol=1e-6)
    # The census model's output pixel (y, x) is image pixel (y + 3, x + 3 + Dmax) of the crop.
    v, u = np.nonzero(matched)
    u_full, v_full = u + 3 + 64 + crop.x, v + 3 + crop.y
    np.testing.assert_allclose(points["x"], (u_full - 1244.772 / 4) * want_z / f, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(points["y"], (v_full - 1019.507 / 4) * want_z / f, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(points["confidence"], res["confidence"][matched])
    from skimage import data

    rgb = data.stereo_motorcycle()[0]
    assert np.array_equal(np.stack([points[c] for c in ("red", "green", "blue")], 1), rgb[v_full, u_full])
    depth = np.load(out / "depth.npy")
    assert np.array_equal(np.isnan(depth), ~matched)
    np.testing.assert_allclose(depth[matched], want_z, rtol=1e-6)
    report = json.loads((out / "report.json").read_text())
    assert report["cloud_points"] == len(points) and report["calibration"]["doffs"] == pytest.approx(doffs)


@pytest.mark.parametrize("extra, message", [
    (["--calib", "{tmp}/none.txt"], "none.txt"),
    (["--calib", "{tmp}/small.txt"], "the calibration is for 640x480 images, the pair is 741x500"),
    (["--calib-cameras", "0,1"], "--calib-cameras: it picks a KITTI --calib file's matrices"),
    (["--calib", "bundled", "--calib-cameras", "2,2"], "expected two different KITTI cameras"),
    (["--calib", "bundled", "--calib-cameras", "0,1"], "cameras 0,1 pick a KITTI calibration's matrices"),
    (["--calib", "{tmp}/cam.json", "--calib-cameras", "0,1"], "this file is not a KITTI calibration"),
])
def test_calibration_errors_are_one_line(tmp_path, capsys, extra, message) -> None:
    (tmp_path / "small.txt").write_text(MIDDLEBURY)
    (tmp_path / "cam.json").write_text('{"fx": 995, "fy": 995, "cx": 311, "cy": 255, "baseline": 0.193}')
    argv = ["run", "--crop", "300,150,130,32", "--dmax", "64", "--model", "census", "--no-sgbm", "--quiet",
            *(e.format(tmp=tmp_path) for e in extra), "-o", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "o").exists()


def test_bundled_calibration_is_refused_for_other_images(tmp_path, capsys) -> None:
    import cv2

    from bayesmachine.host.images import random_dot_stereogram

    left, right, _ = random_dot_stereogram(height=16, width=40, seed=3)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    assert main(["run", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--dmax", "8", "--model", "paper",
                 "--calib", "bundled", "-o", str(tmp_path / "o")]) == 2
    assert "--calib bundled is the bundled Motorcycle pair's calibration" in capsys.readouterr().err


def test_datasets_pass_each_pair_calibration_along(tmp_path) -> None:
    import cv2

    from bayesmachine.host.datasets import bundled_spec, write_pfm, write_png16

    image = np.random.default_rng(1).integers(0, 255, (480, 640), dtype=np.uint8)
    scene = tmp_path / "mb" / "Scene"
    scene.mkdir(parents=True)
    for name in ("im0.png", "im1.png"):
        cv2.imwrite(str(scene / name), image)
    write_pfm(scene / "disp0.pfm", np.full((480, 640), 10.0))
    (scene / "calib.txt").write_text(MIDDLEBURY + "ndisp=64\n")
    pair = resolve_dataset([str(tmp_path / "mb")]).pairs[0]
    assert pair.calib == str(scene / "calib.txt") and pair.to_dict()["calib"] == pair.calib
    assert load_calibration(pair).doffs == 30
    kitti = tmp_path / "kitti"
    for d in ("image_0", "image_1", "disp_noc", "calib"):
        (kitti / d).mkdir(parents=True)
    cv2.imwrite(str(kitti / "image_0" / "000000_10.png"), image[:375])
    cv2.imwrite(str(kitti / "image_1" / "000000_10.png"), image[:375])
    write_png16(kitti / "disp_noc" / "000000_10.png", np.full((375, 640), 5.0))
    (kitti / "calib" / "000000.txt").write_text(f"P0: {KITTI_P2}\nP1: {KITTI_P3}\n")
    pair = resolve_dataset([str(kitti)]).pairs[0]
    assert pair.calib == str(kitti / "calib" / "000000.txt") and pair.calib_cameras == (0, 1)
    assert load_calibration(pair).fx == pytest.approx(721.5377)
    assert load_calibration(bundled_spec()).width == 741
