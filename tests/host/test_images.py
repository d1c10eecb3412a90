"""Input handling: loading, gray conversion, crops, validation; clear errors on bad input."""

import cv2
import numpy as np
import pytest

from bayesmachine.host.images import (
    Crop,
    bundled_pair,
    crop_image,
    load_gt,
    load_image,
    parse_crop,
    random_dot_stereogram,
    to_gray,
    validate_pair,
)


def test_validate_accepts_a_good_pair():
    img = np.zeros((10, 30), np.uint8)
    validate_pair(img, img, dmax=25)  # usable width 26 > 25


@pytest.mark.parametrize(
    ("left", "right", "dmax", "message"),
    [
        (np.zeros((10, 30), np.uint8), np.zeros((10, 31), np.uint8), 4, "differ in shape"),
        (np.zeros((4, 30), np.uint8), np.zeros((4, 30), np.uint8), 4, "too small"),
        (np.zeros((10, 4), np.uint8), np.zeros((10, 4), np.uint8), 0, "too small"),
        (np.zeros((10, 30), np.uint8), np.zeros((10, 30), np.uint8), 26, r"dmax \(26\).*usable width \(26"),
        (np.zeros((10, 30), np.uint16), np.zeros((10, 30), np.uint16), 4, "uint8"),
    ],
)
def test_validate_rejects_bad_pairs(left, right, dmax, message):
    with pytest.raises(ValueError, match=message):
        validate_pair(left, right, dmax)


def test_crop():
    img = np.arange(12 * 20).reshape(12, 20)
    c = parse_crop("3,2,10,5")
    assert c == Crop(3, 2, 10, 5)
    np.testing.assert_array_equal(crop_image(img, c), img[2:7, 3:13])
    assert crop_image(img, None) is img
    with pytest.raises(ValueError, match="outside the 20x12 image"):
        crop_image(img, Crop(15, 0, 10, 5))
    for bad in ("1,2,3", "a,b,c,d", "0,0,0,5", "-1,0,4,4"):
        with pytest.raises(ValueError, match="crop"):
            parse_crop(bad)


def test_load_image_converts_colour_with_opencv(tmp_path):
    rng = np.random.default_rng(0)
    bgr = rng.integers(0, 256, size=(8, 9, 3), dtype=np.uint8)
    path = tmp_path / "c.png"
    cv2.imwrite(str(path), bgr)
    np.testing.assert_array_equal(load_image(path), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    gray = bgr[:, :, 0]
    cv2.imwrite(str(tmp_path / "g.png"), gray)
    np.testing.assert_array_equal(load_image(tmp_path / "g.png"), gray)


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        load_image(tmp_path / "missing.png")
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image at all")
    with pytest.raises(ValueError, match="cannot read"):
        load_image(junk)
    cv2.imwrite(str(tmp_path / "deep.png"), np.zeros((5, 5), np.uint16))
    with pytest.raises(ValueError, match="8-bit"):
        load_image(tmp_path / "deep.png")
    with pytest.raises(ValueError, match="8-bit"):
        to_gray(np.zeros((5, 5), np.float32))


def test_load_gt(tmp_path):
    gt = np.array([[1.5, np.inf], [3.0, 4.0]], np.float32)
    np.save(tmp_path / "gt.npy", gt)
    np.testing.assert_array_equal(load_gt(tmp_path / "gt.npy"), gt)
    cv2.imwrite(str(tmp_path / "gt.png"), np.array([[0, 7]], np.uint8))
    out = load_gt(tmp_path / "gt.png")
    assert np.isinf(out[0, 0]) and out[0, 1] == 7  # 0 = unknown in integer images


def test_random_dot_stereogram_geometry():
    left, right, gt = random_dot_stereogram(
        height=20, width=40, background=2, square=7, square_box=(15, 5, 10, 8)
    )
    assert left.shape == right.shape == gt.shape == (20, 40) and left.dtype == np.uint8
    assert gt[6, 16] == 7 and gt[0, 30] == 2 and np.isinf(gt[0, 1])
    ys, xs = np.nonzero(np.isfinite(gt))
    np.testing.assert_array_equal(left[ys, xs], right[ys, xs - gt[ys, xs].astype(int)])


def test_bundled_pair_loads_offline():
    left, right, gt = bundled_pair()
    assert left.shape == right.shape == gt.shape == (500, 741)
    assert left.dtype == np.uint8 and gt.dtype == np.float32
    assert np.isinf(gt).any() and np.isfinite(gt).mean() > 0.5


def _pfm(path, array):
    """A little-endian grayscale PFM (rows bottom to top), as Middlebury writes them."""
    h, w = array.shape
    with open(path, "wb") as f:
        f.write(f"Pf\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(array[::-1], dtype="<f4").tobytes())


def test_gt_16_bit_png_needs_its_scale(tmp_path):
    """KITTI stores disparity x 256 in 16-bit PNGs (0 = unknown): read at face value every pixel
    would be "bad"; without --gt-scale it is refused, naming the KITTI scale."""
    stored = np.array([[0, 256 * 3 + 128], [256 * 40, 1]], np.uint16)
    cv2.imwrite(str(tmp_path / "kitti.png"), stored)
    with pytest.raises(ValueError, match="16-bit image.*--gt-scale 256 for KITTI"):
        load_gt(tmp_path / "kitti.png")
    got = load_gt(tmp_path / "kitti.png", scale=256)
    assert np.isinf(got[0, 0]) and got[0, 1] == 3.5 and got[1, 0] == 40 and got[1, 1] == 1 / 256
    # An 8-bit map at face value, as before; a scale divides it (Middlebury 2003 quarter size: 4).
    cv2.imwrite(str(tmp_path / "m.png"), np.array([[0, 20]], np.uint8))
    assert load_gt(tmp_path / "m.png")[0, 1] == 20 and load_gt(tmp_path / "m.png", scale=4)[0, 1] == 5


def test_gt_colour_png_is_refused_unless_its_channels_agree(tmp_path):
    gray = np.array([[0, 5], [9, 12]], np.uint8)
    cv2.imwrite(str(tmp_path / "same.png"), np.dstack([gray, gray, gray]))
    np.testing.assert_array_equal(load_gt(tmp_path / "same.png"), load_gt_from(tmp_path, gray))
    colour = np.dstack([gray, gray + 1, gray])
    cv2.imwrite(str(tmp_path / "colour.png"), colour)
    with pytest.raises(ValueError, match=r"colour image \(3 channels that differ\).*accepted: \.pfm"):
        load_gt(tmp_path / "colour.png")


def load_gt_from(tmp_path, gray):
    cv2.imwrite(str(tmp_path / "gray.png"), gray)
    return load_gt(tmp_path / "gray.png")


def test_gt_negative_disparities_are_refused(tmp_path):
    np.save(tmp_path / "neg.npy", np.array([[1.0, -2.5], [np.inf, 3.0]], np.float32))
    with pytest.raises(ValueError, match=r"1 negative disparities \(the smallest -2.5\)"):
        load_gt(tmp_path / "neg.npy")
    _pfm(tmp_path / "neg.pfm", np.array([[1.0, -1.0]], np.float32))
    with pytest.raises(ValueError, match="negative disparities"):
        load_gt(tmp_path / "neg.pfm")
    np.save(tmp_path / "negint.npy", np.array([[-1, 2]], np.int16))
    with pytest.raises(ValueError, match="negative disparities"):
        load_gt(tmp_path / "negint.npy")


def test_gt_non_finite_is_unknown_in_pfm_and_npy(tmp_path):
    stored = np.array([[1.5, np.inf], [np.nan, 0.0]], np.float32)
    _pfm(tmp_path / "m.pfm", stored)
    np.save(tmp_path / "m.npy", stored)
    for name in ("m.pfm", "m.npy"):
        got = load_gt(tmp_path / name)
        assert got.dtype == np.float32 and got[0, 0] == 1.5 and got[1, 1] == 0  # 0 is a disparity here
        assert np.isinf(got[0, 1]) and np.isinf(got[1, 0])  # inf and nan: unknown, as inf
    # .npy integers are the numbers as stored, 16 bits too (no image convention applies).
    np.save(tmp_path / "u16.npy", np.array([[0, 300]], np.uint16))
    assert load_gt(tmp_path / "u16.npy").tolist() == [[0.0, 300.0]]


def test_decode_disparity_is_the_one_decoding():
    from bayesmachine.host.images import decode_disparity

    bgra = np.zeros((2, 2, 4), np.uint8)
    bgra[..., 3] = 255  # an opaque alpha channel: not a disparity
    with pytest.raises(ValueError, match="4 channels that differ"):
        decode_disparity(bgra, "x.png", image=True)
    with pytest.raises(ValueError, match="integers or floats"):
        decode_disparity(np.zeros((2, 2), bool), "x.npy", image=False)
    with pytest.raises(ValueError, match="2-D"):
        decode_disparity(np.zeros((2, 2, 2, 1)), "x.npy", image=False)
    with pytest.raises(ValueError, match="scale must be a finite number > 0"):
        decode_disparity(np.ones((2, 2)), "x.npy", image=False, scale=0)


@pytest.mark.parametrize("name", ["garbage.png", "corrupt.pfm"])
def test_unreadable_files_print_no_opencv_log(tmp_path, capfd, name):
    """OpenCV's own ``[ WARN ]``/``[ERROR]`` lines (written to the process's stderr) stay silent: the
    one error line is ours."""
    path = tmp_path / name
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 50 if name.endswith(".png") else
                     b"Pf\n40 16\n-1.0\n" + b"\0" * 100)
    with pytest.raises(ValueError, match="cannot read"):
        load_gt(path)
    if name.endswith(".png"):
        with pytest.raises(ValueError, match="cannot read"):
            load_image(path)
    captured = capfd.readouterr()
    assert captured.err == "" and captured.out == ""
