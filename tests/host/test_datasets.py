"""Datasets on disk (issue 20): every layout built small and synthetic here (PFM and 16-bit PNG
written by the project's own writers), resolved to pairs and loaded back as the host sees them."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from bayesmachine.host.datasets import load_pair, resolve_dataset, write_pfm, write_png16
from bayesmachine.host.images import load_gt, random_dot_stereogram

H, W = 20, 40


def stereo(seed: int, colour: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A small random-dot pair (gray, or as BGR with three equal channels) and its disparity."""
    left, right, gt = random_dot_stereogram(height=H, width=W, background=3, square=6, seed=seed)
    if colour:
        left, right = (np.dstack([im, im, im]) for im in (left, right))
    return left, right, gt


def as_uint8(gt: np.ndarray, scale: float) -> np.ndarray:
    """A ground truth as an 8-bit image of disparity x ``scale``, 0 = unknown (Middlebury 2001-2006)."""
    return np.where(np.isfinite(gt), np.round(np.where(np.isfinite(gt), gt, 0) * scale), 0).astype(np.uint8)


def middlebury2014(root: Path, scenes: int = 2, size: str = "trainingQ") -> Path:
    for i in range(scenes):
        left, right, gt = stereo(i, colour=True)
        d = root / size / f"Scene{i}"
        d.mkdir(parents=True)
        cv2.imwrite(str(d / "im0.png"), left)
        cv2.imwrite(str(d / "im1.png"), right)
        write_pfm(d / ("disp0GT.pfm" if i % 2 else "disp0.pfm"), gt)
        (d / "calib.txt").write_text("cam0=[100 0 20; 0 100 10; 0 0 1]\ndoffs=0\nbaseline=100\n"
                                     f"width={W}\nheight={H}\nndisp=12\n")
    return root


def middlebury_old(root: Path) -> Path:
    """2001 (tsukuba: x 16, others x 8, .ppm/.pgm), 2003 (.png, x 4), 2005 (view1/view5, x 1)."""
    specs = [("2001/tsukuba", "im2.ppm", "im6.ppm", "disp2.pgm", 16), ("2001/venus", "im2.ppm", "im6.ppm",
             "disp2.pgm", 8), ("2003/cones", "im2.png", "im6.png", "disp2.png", 4),
             ("2005/Art", "view1.png", "view5.png", "disp1.png", 1)]
    for i, (scene, lname, rname, gname, scale) in enumerate(specs):
        left, right, gt = stereo(10 + i, colour=True)
        d = root / scene
        d.mkdir(parents=True)
        cv2.imwrite(str(d / lname), left)
        cv2.imwrite(str(d / rname), right)
        cv2.imwrite(str(d / gname), as_uint8(gt, scale))
    return root


def kitti(root: Path, year: int = 2015, frames: int = 2) -> Path:
    ldir, rdir, gdir = (("image_2", "image_3", "disp_noc_0") if year == 2015
                        else ("image_0", "image_1", "disp_noc"))
    for sub in (ldir, rdir, gdir):
        (root / "training" / sub).mkdir(parents=True)
    for i in range(frames):
        left, right, gt = stereo(20 + i, colour=year == 2015)
        name = f"{i:06d}_10.png"
        cv2.imwrite(str(root / "training" / ldir / name), left)
        cv2.imwrite(str(root / "training" / rdir / name), right)
        cv2.imwrite(str(root / "training" / ldir / f"{i:06d}_11.png"), left)  # the next frame: no gt
        if i != frames - 1:  # the last frame's ground truth is missing
            write_png16(root / "training" / gdir / name, gt)
    return root


def pair_list(root: Path) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    lines = ["left,right,gt,gt_scale"]
    for i in range(2):
        left, right, gt = stereo(30 + i)
        cv2.imwrite(str(root / f"l{i}.png"), left)
        cv2.imwrite(str(root / f"r{i}.png"), right)
        write_png16(root / f"g{i}.png", gt, scale=64)
        lines.append(f"l{i}.png,r{i}.png,g{i}.png,64")
    lines.append("l0.png r0.png   # a pair without ground truth, white-space separated")
    (root / "pairs.csv").write_text("\n".join(lines) + "\n")
    return root / "pairs.csv"


def frame_dirs(root: Path, frames: int = 3) -> tuple[Path, Path]:
    for side in ("left", "right"):
        (root / side).mkdir(parents=True)
    for i in range(frames):
        left, right, _ = stereo(40 + i)
        cv2.imwrite(str(root / "left" / f"f{i:03d}.png"), left)
        cv2.imwrite(str(root / "right" / f"f{i:03d}.png"), right)
    return root / "left", root / "right"


def expect_gt(spec_gt: np.ndarray | None, gt: np.ndarray, step: float) -> None:
    """Loaded ground truth equals the stereogram's up to the storage's step; unknown stays unknown."""
    assert spec_gt is not None
    np.testing.assert_array_equal(np.isfinite(spec_gt), np.isfinite(gt))
    known = np.isfinite(gt)
    assert np.abs(spec_gt[known] - gt[known]).max() <= step / 2 + 1e-6


def test_pfm_and_png16_writers_round_trip(tmp_path) -> None:
    gt = np.array([[0.5, np.inf, 3.25], [7.0, 0.0, 12.75]], np.float32)
    write_pfm(tmp_path / "d.pfm", gt)
    np.testing.assert_array_equal(load_gt(tmp_path / "d.pfm"), gt)  # rows not flipped, inf kept
    write_png16(tmp_path / "d.png", np.where(gt == 0, np.inf, gt))
    raw = cv2.imread(str(tmp_path / "d.png"), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16 and raw[0, 0] == 128 and raw[0, 1] == 0
    back = load_gt(tmp_path / "d.png", scale=256)
    np.testing.assert_array_equal(back, np.where(gt == 0, np.inf, gt))


def test_middlebury_2014_scenes_with_calib_and_pfm(tmp_path) -> None:
    ds = resolve_dataset([str(middlebury2014(tmp_path / "MiddEval3"))])
    assert ds.layout == "middlebury2014"
    assert [p.name for p in ds.pairs] == ["trainingQ/Scene0", "trainingQ/Scene1"]
    assert [p.dmax_hint for p in ds.pairs] == [11, 11]  # ndisp - 1
    for i, spec in enumerate(ds.pairs):
        left, right, gt = load_pair(spec)
        want_l, want_r, want_gt = stereo(i)
        np.testing.assert_array_equal(left, want_l)  # three equal channels -> the same luminance
        np.testing.assert_array_equal(right, want_r)
        np.testing.assert_array_equal(gt, want_gt)


def test_middlebury_2001_to_2006_scales(tmp_path) -> None:
    ds = resolve_dataset([str(middlebury_old(tmp_path / "mb"))])
    assert [(p.name, p.gt_scale) for p in ds.pairs] == [
        ("2001/tsukuba", 16.0), ("2001/venus", 8.0), ("2003/cones", 4.0), ("2005/Art", None)]
    for i, (spec, step) in enumerate(zip(ds.pairs, (1 / 16, 1 / 8, 1 / 4, 1), strict=True)):
        _, _, gt = load_pair(spec)
        expect_gt(gt, stereo(10 + i)[2], step)
    # --gt-scale replaces the layout's factor.
    assert {p.gt_scale for p in resolve_dataset([str(tmp_path / "mb")], gt_scale=2).pairs} == {2.0}


@pytest.mark.parametrize("year", [2012, 2015])
def test_kitti_frames_with_16_bit_ground_truth(tmp_path, year) -> None:
    ds = resolve_dataset([str(kitti(tmp_path / "kitti", year))])
    assert ds.layout == "kitti"
    assert [p.name for p in ds.pairs] == ["training/000000_10", "training/000001_10"]  # *_11 are not pairs
    left, right, gt = load_pair(ds.pairs[0])
    np.testing.assert_array_equal(left, stereo(20)[0])
    expect_gt(gt, stereo(20)[2], 1 / 256)
    # The frame without ground truth still runs, and says so.
    assert ds.pairs[1].gt is None and "no ground truth" in ds.pairs[1].note
    assert load_pair(ds.pairs[1])[2] is None
    assert ds.notes == [f"training/000001_10: {ds.pairs[1].note}"]


def test_a_list_file_with_csv_header_scales_and_comments(tmp_path) -> None:
    ds = resolve_dataset([str(pair_list(tmp_path / "list"))])
    assert ds.layout == "list"
    assert [(p.name, p.gt_scale, p.gt is not None) for p in ds.pairs] == [
        ("l0", 64.0, True), ("l1", 64.0, True), ("l0~2", None, False)]
    _, _, gt = load_pair(ds.pairs[1])
    expect_gt(gt, stereo(31)[2], 1 / 64)


def test_frame_directories_and_videos(tmp_path) -> None:
    left_dir, right_dir = frame_dirs(tmp_path / "seq")
    for paths in ([str(tmp_path / "seq")], [str(left_dir), str(right_dir)]):
        ds = resolve_dataset(paths)
        assert ds.layout == "frames" and len(ds.pairs) == 3
        assert all(p.gt is None for p in ds.pairs)
        np.testing.assert_array_equal(load_pair(ds.pairs[2])[0], stereo(42)[0])
    # Two videos: frame i with frame i (MJPEG is lossy: compare loosely, but in order).
    videos = []
    for side, k in (("left", 0), ("right", 1)):
        path = tmp_path / f"{side}.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (W, H))
        if not writer.isOpened():
            pytest.skip("this OpenCV cannot write MJPEG .avi")
        for i in range(3):
            writer.write(cv2.cvtColor(stereo(40 + i)[k], cv2.COLOR_GRAY2BGR))
        writer.release()
        videos.append(str(path))
    ds = resolve_dataset(videos)
    assert ds.layout == "video" and [p.frame for p in ds.pairs] == [0, 1, 2]
    for i in range(3):
        left, right, gt = load_pair(ds.pairs[i])
        errors = [np.abs(left.astype(int) - stereo(40 + j)[0].astype(int)).mean() for j in range(3)]
        assert int(np.argmin(errors)) == i and gt is None


def test_problems_are_per_pair_never_silent(tmp_path) -> None:
    root = middlebury2014(tmp_path / "mb", scenes=3, size="q")
    (root / "q" / "Scene1" / "im1.png").write_text("not an image")
    small = stereo(2)[1][:, : W - 4]
    cv2.imwrite(str(root / "q" / "Scene2" / "im1.png"), small)
    ds = resolve_dataset([str(root)])
    assert len(ds.pairs) == 3  # resolving lists them all; loading says what is wrong with each
    load_pair(ds.pairs[0])
    with pytest.raises(ValueError, match="cannot read .*Scene1/im1.png as an image"):
        load_pair(ds.pairs[1])
    with pytest.raises(ValueError, match=f"differ in size: {W}x{H} vs {W - 4}x{H}"):
        load_pair(ds.pairs[2])
    (root / "q" / "Scene0" / "im1.png").unlink()
    with pytest.raises(FileNotFoundError, match="Scene0/im1.png"):
        load_pair(ds.pairs[0])


def test_nothing_usable_is_one_clear_error(tmp_path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no stereo pair found"):
        resolve_dataset([str(tmp_path / "empty")])
    with pytest.raises(FileNotFoundError, match="does not exist"):
        resolve_dataset([str(tmp_path / "nowhere")])
    (tmp_path / "bad.txt").write_text("a.png\n")
    with pytest.raises(ValueError, match="line 1: expected 'left right"):
        resolve_dataset([str(tmp_path / "bad.txt")])
    with pytest.raises(ValueError, match="two frame directories or two video files"):
        resolve_dataset([str(tmp_path / "bad.txt"), str(tmp_path / "empty")])
