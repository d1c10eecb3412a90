"""The output region: one geometry for features, likelihoods, reference, metrics and plots."""

import numpy as np
import pytest

from bayesmachine.host.features import feature_sums
from bayesmachine.region import OutputRegion


def test_vga_geometry():
    r = OutputRegion.of_image((480, 640), 80)
    assert r.feature_shape == (476, 636) and r.shape == (476, 556) and r.pixels == 476 * 556
    assert r.map_slice == slice(80, 636)
    assert OutputRegion.of_features((476, 636), 80) == r


def test_cut_is_centred_and_starts_at_dmax():
    img = np.arange(12 * 20).reshape(12, 20)
    r = OutputRegion.of_image(img.shape, 5)
    cut = r.cut(img)
    assert cut.shape == r.shape == (8, 20 - 4 - 5)
    # Output pixel (0, 0) is map pixel (0, dmax), centred on image pixel (2, dmax + 2).
    assert cut[0, 0] == img[2, 7] and cut[-1, -1] == img[9, 17]
    with pytest.raises(ValueError, match="is not 12x20"):
        r.cut(img[:, :-1])


def test_feature_centre_agrees_with_the_cut():
    img = np.zeros((9, 15), np.uint8)
    img[4, 9] = 250
    r = OutputRegion.of_image(img.shape, 3)
    f = feature_sums(img)
    m = f.m25[:, r.map_slice]
    assert m.shape == r.shape
    # The window centred on the dot (image (4, 9)) is output pixel (2, 4).
    assert r.cut(np.arange(img.size).reshape(img.shape))[2, 4] == 4 * 15 + 9 and m[2, 4] == 250


def test_match_columns():
    r = OutputRegion.of_image((10, 16), 3)
    xr = r.match_columns
    assert xr.shape == (16 - 4 - 3, 4)
    assert xr[0].tolist() == [3, 2, 1, 0] and xr[-1, 0] == 11 and xr.min() == 0


def test_bands_cover_every_row_once():
    r = OutputRegion.of_image((30, 100), 10)
    assert [(s.start, s.stop) for s in r.bands(8)] == [(0, 8), (8, 16), (16, 24), (24, 26)]
    assert r.band_rows(pixels=172) == 2 and r.band_rows(pixels=1) == 1
    assert sum(s.stop - s.start for s in r.bands()) == 26
    with pytest.raises(ValueError, match="band rows"):
        next(r.bands(0))


@pytest.mark.parametrize(
    ("shape", "dmax", "message"),
    [((4, 30), 1, "too small"), ((10, 4), 0, "too small"), ((10, 30), 26, r"dmax \(26\).*usable width \(26")],
)
def test_bad_geometry(shape, dmax, message):
    with pytest.raises(ValueError, match=message):
        OutputRegion.of_image(shape, dmax)


def test_a_models_margin_keeps_its_windows_inside_the_image():
    """The 7x7 census model's region is one pixel further inside (margin 3); the paper model's and a
    5x5 census's are the 5x5 filters' (margin 2, as before margins existed)."""
    from bayesmachine.host.features import model_planes
    from bayesmachine.models import ModelParams

    img = np.arange(12 * 20).reshape(12, 20)
    census = ModelParams(dmax=5, name="census")
    r = OutputRegion.of_model(img.shape, census)
    assert (r.margin, r.feature_shape, r.shape) == (3, (6, 14), (6, 9))
    cut = r.cut(img)
    # Output pixel (0, 0) is map pixel (0, dmax), centred on image pixel (3, dmax + 3).
    assert cut[0, 0] == img[3, 8] and cut[-1, -1] == img[8, 16]
    assert OutputRegion.of_features(r.feature_shape, 5, 3) == r
    assert model_planes(img.astype(np.uint8), census).m25.shape == r.feature_shape
    for paper_like in (ModelParams(name="paper", dmax=5),
                       ModelParams(dmax=5, name="census", census_window=5)):
        assert OutputRegion.of_model(img.shape, paper_like) == OutputRegion.of_image(img.shape, 5)
    with pytest.raises(ValueError, match="too small for the model's 7x7 windows"):
        OutputRegion(6, 20, 1, 3)
    with pytest.raises(ValueError, match=r"usable width \(8 = image width 14 - 6\)"):
        OutputRegion(12, 14, 8, 3)
    with pytest.raises(ValueError, match="margin must be an integer >= 2"):
        OutputRegion(12, 20, 1, 1)
