"""The 5x5 feature filters on hand-computed cases (exact integer sums)."""

import numpy as np
import pytest

from bayesmachine.host.features import feature_sums, feature_sums_plain


def test_horizontal_ramp():
    img = np.tile(np.arange(5, dtype=np.uint8), (5, 1))  # img[y, x] = x
    f = feature_sums(img)
    assert f.shape == (1, 1)
    assert f.m25[0, 0] == 5 * (0 + 1 + 2 + 3 + 4)  # 50: the window sum
    assert f.gh20[0, 0] == 5 * (3 + 4) - 5 * (0 + 1)  # 30: right two columns - left two
    assert f.gv20[0, 0] == 0


def test_vertical_ramp():
    img = (10 * np.arange(5, dtype=np.uint8))[:, None].repeat(5, axis=1)  # img[y, x] = 10 y
    f = feature_sums(img)
    assert f.m25[0, 0] == 5 * 10 * 10
    assert f.gh20[0, 0] == 0
    assert f.gv20[0, 0] == 5 * 10 * (3 + 4) - 5 * 10 * (0 + 1)  # bottom two rows - top two


@pytest.mark.parametrize(
    ("y", "x", "m", "gh", "gv"),
    [
        (2, 2, 255, 0, 0),
        (0, 4, 255, 255, -255),
        (4, 0, 255, -255, 255),
        (3, 1, 255, -255, 255),
        (1, 3, 255, 255, -255),
    ],
)
def test_single_dot(y, x, m, gh, gv):
    img = np.zeros((5, 5), np.uint8)
    img[y, x] = 255
    f = feature_sums(img)
    assert (f.m25[0, 0], f.gh20[0, 0], f.gv20[0, 0]) == (m, gh, gv)


def test_map_pixel_is_centred_on_image_pixel_plus_2():
    img = np.zeros((11, 13), np.uint8)
    img[5, 7] = 200  # inside the windows of map pixels (1..5, 3..7)
    f = feature_sums(img)
    assert f.shape == (7, 9)
    assert f.m25[3, 5] == 200  # centred on (5, 7)
    assert np.count_nonzero(f.m25) == 25
    # The dot is in the rightmost column of the window centred 2 pixels to its left.
    assert f.gh20[3, 3] == 200 and f.gh20[3, 7] == -200 and f.gh20[3, 5] == 0


def test_extremes_fit_int32_and_match_bounds():
    img = np.zeros((5, 5), np.uint8)
    img[:, 3:] = 255
    f = feature_sums(img)
    assert f.gh20[0, 0] == 10 * 255 and f.m25[0, 0] == 10 * 255
    assert f.m25.dtype == np.int32


def test_matches_direct_correlation_on_random_images():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, size=(23, 31), dtype=np.uint8)
    fast, plain = feature_sums(img), feature_sums_plain(img)
    assert list(fast) == list(plain) == ["m25", "gh20", "gv20"]
    for name in fast:
        assert fast[name].shape == (19, 27)
        np.testing.assert_array_equal(fast[name], plain[name])


def test_too_small():
    with pytest.raises(ValueError, match="too small"):
        feature_sums(np.zeros((4, 9), np.uint8))
