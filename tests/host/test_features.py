"""The 5x5 feature filters on hand-computed cases (exact integer sums); the census codes against a
plain pixel-by-pixel computation, their bit order and their grid."""

import numpy as np
import pytest

from bayesmachine.host.features import (
    census_codes,
    census_codes_plain,
    census_offsets,
    feature_sums,
    feature_sums_plain,
    model_planes,
)
from bayesmachine.models import ModelParams


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


# --- Planes declared by the columns ---

def test_a_model_computes_exactly_the_planes_its_columns_declare():
    from bayesmachine.host.features import census_codes, model_planes
    from bayesmachine.models import ModelParams

    img = np.random.default_rng(4).integers(0, 256, (15, 21), dtype=np.uint8)
    sums = ["m25", "gh20", "gv20"]
    for kwargs, planes, margin in (({"name": "paper"}, sums, 2),
                                   ({"name": "paper", "gradient_magnitude": True}, [*sums, "g20"], 2),
                                   ({"name": "census"}, [*sums, "census"], 3),
                                   ({"name": "census", "census_window": 5}, [*sums, "census"], 2)):
        model = ModelParams(**kwargs)
        got = model_planes(img, model)
        assert list(got) == planes and model.margin == margin, kwargs
        assert got.shape == (15 - 2 * margin, 21 - 2 * margin)
        k = margin - 2  # the 5x5 sums cut to the model's grid
        np.testing.assert_array_equal(got.gv20, feature_sums(img).gv20[k : 11 - k, k : 17 - k])
    np.testing.assert_array_equal(model_planes(img, ModelParams(name="census")).census, census_codes(img, 7))
    with pytest.raises(AttributeError, match="no plane 'census' \\(planes: m25, gh20, gv20\\)"):
        _ = model_planes(img, ModelParams(name="paper")).census


def test_two_declarations_of_one_plane_name_are_refused():
    """The right pass keeping the census model's 5x5 window beside the left pass's 7x7: one name, two
    planes."""
    from bayesmachine.columns import AbovePrior, Census, LeftPrior, Mean, consistency
    from bayesmachine.models import MODELS, ModelDef, ModelParams, PassDef, register_model

    definition = ModelDef(name="two-windows", description="a right pass of another census window",
                          columns=(LeftPrior, AbovePrior, Mean, Census, consistency("right")),
                          passes=(PassDef(name="right", model="census", reference="right", machine_index=1,
                                          not_inherited=("census_window",)),),
                          defaults={"census_window": 5})
    with pytest.raises(ValueError, match="^model 'two-windows': its defaults give no model: plane census: "
                       "the left pass \\(model two-windows\\)'s census reads it of 5x5 windows, the right "
                       "pass \\(model census\\)'s fused of 7x7"):
        register_model(definition)
    assert "two-windows" not in MODELS
    assert ModelParams(name="census-lr", census_window=5).margin == 2  # both passes' windows follow


def test_planes_are_a_read_only_mapping():
    from bayesmachine.host.features import Planes

    a = np.zeros((3, 4), np.int32)
    planes = Planes({"m25": a, "gv20": a + 1})
    assert planes.shape == (3, 4) and len(planes) == 2 and planes["gv20"][0, 0] == 1
    assert planes.band(slice(1, 2)).shape == (1, 4)
    with pytest.raises(AttributeError, match="read-only"):
        planes.m25 = a
    with pytest.raises(ValueError, match="2-D arrays of one shape"):
        Planes({"m25": a, "gv20": np.zeros((2, 4))})
    with pytest.raises(ValueError, match="at least one"):
        Planes({})
    import pickle

    again = pickle.loads(pickle.dumps(planes))
    assert list(again) == ["m25", "gv20"] and np.array_equal(again.gv20, planes.gv20)


@pytest.mark.parametrize("window", [5, 7])
@pytest.mark.parametrize("seed", [0, 1])
def test_census_codes_equal_plain(window, seed):
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (15, 19), dtype=np.uint8)
    img[4:9, 3:10] = 77  # flat patch: equal neighbours give 0 bits
    img[0, :] = 255  # a bright border row (the 7x7 windows of the grid's first row reach it)
    codes = census_codes(img, window)
    k = window // 2  # the map grid's margin: every window inside the image
    assert codes.dtype == np.uint64 and codes.shape == (15 - 2 * k, 19 - 2 * k)
    np.testing.assert_array_equal(codes, census_codes_plain(img, window))
    bits = window * window - 1
    assert int(codes.max()) < (1 << bits) and int(codes.max()).bit_length() == bits


def test_census_bit_order_is_raster():
    offs = census_offsets(7)
    assert len(offs) == 48 and offs[0] == (-3, -3) and offs[23] == (0, -1) and offs[24] == (0, 1)
    img = np.full((9, 9), 100, np.uint8)
    img[4 - 3, 4 - 3] = 10  # darker top-left neighbour of map pixel (2, 2): bit 0
    img[4, 5] = 10  # darker right neighbour: bit 24
    assert int(census_codes(img, 7)[1, 1]) == (1 << 0) | (1 << 24)  # map grid of margin 3
    # The grid keeps every 7x7 window inside the image: a 7x7 image has one code, all 48 bits read.
    dark = np.full((7, 7), 50, np.uint8)
    dark[3, 3] = 200
    dark[0, 0] = 255  # not darker: bit 0 clear
    codes = census_codes(dark, 7)
    assert codes.shape == (1, 1) and int(codes[0, 0]) == ((1 << 48) - 1) & ~1
    # The features of a 7x7-census model share that grid: the 5x5 sums around the same centres.
    img2 = np.random.default_rng(5).integers(0, 256, (12, 14), dtype=np.uint8)
    census = ModelParams(dmax=2, name="census")
    f7, f5 = model_planes(img2, census), feature_sums(img2)
    assert census.margin == 3 and f7.census.shape == f7.m25.shape == (6, 8)
    np.testing.assert_array_equal(f7.m25, f5.m25[1:-1, 1:-1])
    np.testing.assert_array_equal(f7.gv20, f5.gv20[1:-1, 1:-1])
    assert ModelParams(dmax=2, name="census", census_window=5).margin == ModelParams(name="paper").margin == 2
