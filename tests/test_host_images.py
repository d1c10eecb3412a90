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
