"""Calibration files (host/calib.py), depth in metres and the PLY cloud (host/cloud.py): each format
read into the same numbers, every wrong or missing field one clear error, and the cloud read back by a
PLY parser written here from the spec (not the writer), its depths fx * baseline / (d + doffs)."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bayesmachine.cli import main
from bayesmachine.host.calib import RANGES, StereoCalibration, bundled_calibration_path, read_calibration
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


# --- issue 38: every field in its physical range, no repeated key, only regular files ---------------

JSON = {"fx": 700, "fy": 700, "cx": 300, "cy": 200, "baseline": 0.5, "doffs": 0, "width": 640, "height": 480}
KITTI = f"P0: {KITTI_P2}\nP1: {KITTI_P3}\nP2: {KITTI_P2}\nP3: {KITTI_P3}\n"


@pytest.mark.parametrize("field", ["fx", "fy", "cx", "cy", "baseline", "doffs", "width", "height"])
@pytest.mark.parametrize("value", [10**400, -(10**400), 1e200, 1e-200, 0, -1])
def test_every_json_field_is_in_its_physical_range(tmp_path, field, value) -> None:
    """f x baseline that overflowed gave every depth +inf and an empty cloud (exit 0), one that
    underflowed every point at (0, 0, 0), a 400-digit integer an OverflowError."""
    data = {**JSON, field: value}
    (tmp_path / "c.json").write_text(json.dumps(data))
    lo, hi, unit = RANGES.get(field, (1, 1 << 30, ""))
    if lo <= value <= hi and field not in ("width", "height"):
        assert getattr(read_calibration(tmp_path / "c.json"), field) == value
        return
    with pytest.raises(ValueError, match=f"c.json: {field} must be") as info:
        read_calibration(tmp_path / "c.json")
    assert "\n" not in str(info.value)
    if field not in ("width", "height") or not isinstance(value, int):
        assert f"{unit}" in str(info.value)


@pytest.mark.parametrize("name, text, message", [
    # Middlebury: the baseline in mm, as the file says it; the camera matrix's entries by name.
    ("calib.txt", MIDDLEBURY.replace("baseline=200", "baseline=1e300"),
     "baseline must be a finite number in [0.001, 1e+09] mm, got 1e+300"),
    ("calib.txt", MIDDLEBURY.replace("baseline=200", "baseline=0.0001"), "[0.001, 1e+09] mm, got 0.0001"),
    ("calib.txt", MIDDLEBURY.replace("[1000 0 300; 0 1000 250", "[1e-9 0 300; 0 1e-9 250").replace(
        "cam1=[1000 0 330; 0 1000 250; 0 0 1]\n", ""), "cam0 f must be a finite number in [1, 1e+06] pixels"),
    ("calib.txt", MIDDLEBURY.replace("doffs=30", "doffs=1e9").replace("330", "1e9"),
     "doffs must be a finite"),
    # KITTI: the matrix entry the value comes from.
    ("calib.txt", KITTI.replace("P2: 7.215377e+02", "P2: 7.215377e+12").replace("P3: 7.215377e+02",
                                                                              "P3: 7.215377e+12"),
     "P2[0,0] (fx) must be a finite number in [1, 1e+06] pixels"),
    ("calib.txt", KITTI.replace("4.485728e+01", "4.485728e+301"), "baseline (P2[0,3] - P3[0,3]) / fx"),
])
def test_physical_ranges_are_said_in_the_files_own_units(tmp_path, name, text, message) -> None:
    (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)):
        read_calibration(tmp_path / name)


@pytest.mark.parametrize("name, text, message", [
    ("calib.txt", MIDDLEBURY + "baseline=100\n", "baseline is given twice (lines 4 and 7): keep one"),
    ("calib.txt", "doffs=1\n" + MIDDLEBURY, "doffs is given twice (lines 1 and 4)"),
    ("calib.txt", KITTI + f"P3: {KITTI_P2}\n", "P3 is given twice (lines 4 and 5)"),
    ("c.json", '{"fx": 700, "fy": 700, "cx": 300, "cy": 200, "baseline": 0.5, "fx": 7}',
     "the key 'fx' is given twice"),
    # A rectified pair: cam1 has cam0's focal length and rows; KITTI's right matrix too.
    ("calib.txt", MIDDLEBURY.replace("cam1=[1000 0 330; 0 1000 250", "cam1=[1000 0 330; 0 1000 251"),
     "cam1's cy 251 differs from cam0's 250"),
    ("calib.txt", MIDDLEBURY.replace("cam1=[1000 0 330; 0 1000 250", "cam1=[1000 0 330; 0 999 250"),
     "cam1's fy 999 differs from cam0's 1000"),
    ("calib.txt", MIDDLEBURY.replace("cam1=[1000 0 330", "cam1=[999 0 330"), "cam1's f 999 differs"),
    ("calib.txt", MIDDLEBURY.replace("cam1=[1000 0 330;", "cam1=[1000 1 330;"),
     "cam1 must be [f 0 cx; 0 f cy; 0 0 1]"),
    ("calib.txt", KITTI.replace(f"P3: {KITTI_P3}", f"P3: {KITTI_P3.replace('1.728540e+02', '1.8e+02')}"),
     "P2 and P3 must share [1,2]"),
])
def test_repeated_keys_and_an_unrectified_right_camera_are_refused(tmp_path, name, text, message) -> None:
    (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)):
        read_calibration(tmp_path / name)


@pytest.mark.parametrize("name, text", [("calib.txt", MIDDLEBURY), ("kitti.txt", KITTI),
                                        ("c.json", json.dumps(JSON))])
def test_a_byte_order_mark_is_skipped(tmp_path, name, text) -> None:
    (tmp_path / name).write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / f"plain-{name}").write_text(text)
    got, want = read_calibration(tmp_path / name), read_calibration(tmp_path / f"plain-{name}")
    assert replace(got, source="") == replace(want, source="")


def test_only_a_regular_file_is_read_and_at_most_1_mib(tmp_path) -> None:
    """/dev/zero was read until memory ran out, a FIFO without a writer blocked for ever, a directory
    said 'Is a directory': each is refused before it is opened."""
    import os
    import threading

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "link").symlink_to(fifo)
    (tmp_path / "big.txt").write_text(MIDDLEBURY + "#" * (1 << 20))
    cases = {fifo: "a named pipe", tmp_path / "link": "a named pipe", Path("/dev/zero"): "a device",
             tmp_path: "a directory", tmp_path / "big.txt": "larger than 1024 KiB"}
    for path, what in cases.items():
        done: list[BaseException] = []
        reader = threading.Thread(target=lambda p=path, d=done: d.append(_refusal(p)), daemon=True)
        reader.start()
        reader.join(10)
        assert done and isinstance(done[0], ValueError), (path, done)
        assert f"{path}: {what}" in str(done[0])


def _refusal(path: Path) -> BaseException:
    try:
        read_calibration(path)
    except BaseException as exc:  # noqa: BLE001 - the test looks at what it was
        return exc
    return AssertionError(f"{path} was read")


@pytest.mark.parametrize("cameras, error, message", [
    ("2,3", TypeError, "cameras must be a pair (left, right) of KITTI camera numbers, e.g. (2, 3), not str"),
    ((2,), TypeError, "cameras must be a pair"),
    ((2, 2), ValueError, "cameras must be two different KITTI cameras, got (2, 2)"),
    ((0, 4), ValueError, "cameras[1] must be an integer in [0, 3], got 4"),
    ((2.0, 3), TypeError, "cameras[0] must be an integer, not float"),
])
def test_cameras_say_what_they_take(tmp_path, cameras, error, message) -> None:
    (tmp_path / "kitti.txt").write_text(KITTI)
    with pytest.raises(error, match=re.escape(message)):
        read_calibration(tmp_path / "kitti.txt", cameras=cameras)
    assert read_calibration(tmp_path / "kitti.txt", cameras=(np.int64(0), np.int64(1))).fx == 721.5377


def test_depths_past_float32_are_points_at_infinity(tmp_path) -> None:
    """A doffs within 1e-26 of -d gives a depth past float32's range: +inf (no NumPy warning when
    depth.npy is cast), and the cloud leaves out points whose x, y or z are not finite float32s."""
    import warnings

    from bayesmachine.host.cloud import point_cloud
    from bayesmachine.region import OutputRegion

    calib = StereoCalibration(fx=1e6, fy=1e6, cx=-1e6, cy=0, baseline=1e6, doffs=1e-30)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        depth = calib.depth(np.array([[0.0, 1.0, -1.0]])).astype(np.float32)
    assert depth[0, 0] == np.inf and depth[0, 1] == np.float32(1e12) and np.isnan(depth[0, 2])
    region = OutputRegion.of_image((5, 9), 2, 2)  # one output row of three pixels
    wide = StereoCalibration(fx=1, fy=1, cx=-1e6, cy=0, baseline=1)
    depths = np.array([[1e33, 1e12, 1.0]], np.float32)
    points = point_cloud(depths, wide, region, np.zeros((5, 9, 3), np.uint8))
    # x = (u + 1e6) z: past float32 (3.4e38) for z = 1e33 only.
    assert points["z"].tolist() == [np.float32(1e12), 1.0] and np.isfinite(points["x"]).all()


@pytest.mark.parametrize("name", ["calib_é.txt", "new\nline.txt", "back\\slash.txt"])
def test_any_path_makes_a_valid_ply_header(tmp_path, name) -> None:
    """A non-ASCII path failed after the whole run ('ascii' codec), a newline made an invalid header
    (exit 0): the comment holds the path's Python escape, one printable ASCII line."""
    (tmp_path / name).write_text(bundled_calibration_path().read_text())
    out = tmp_path / "o"
    assert main(["run", "--crop", "300,150,130,32", "--dmax", "64", "--model", "census", "--no-sgbm",
                 "--quiet", "--calib", str(tmp_path / name), "-o", str(out)]) == 0
    header, points = read_ply(out / "cloud.ply")
    comments = [h for h in header if h.startswith("comment ")]
    assert len(comments) == 1 and all(" " <= c <= "~" for c in comments[0])
    escaped = str(tmp_path / name).encode("unicode_escape").decode("ascii")
    assert comments[0].endswith(f"calibration {escaped}") and len(points) > 0


def test_an_empty_calibration_path_is_refused(tmp_path, capsys) -> None:
    assert main(["run", "--calib", "", "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["bayesmachine run: error: argument --calib: the path is empty (an unset variable?); "
                   "name the file"]
