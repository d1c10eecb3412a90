"""Depth in metres and a coloured point cloud from a disparity map and a :class:`~.calib.StereoCalibration`.

The cloud is a binary little-endian PLY (format 1.0, the layout Open3D, MeshLab and
CloudCompare read): one ``vertex`` element with ``float x, y, z`` (metres, the left camera's
frame: x right, y down, z forward), ``uchar red, green, blue`` (the left image's colour) and,
when the run has counts, ``float confidence``. A point is written for every output pixel with a
finite depth whose x, y and z are finite float32 numbers: no-match pixels, blanked ones
(``--min-confidence``) and points at infinity are left out. A header comment is printable ASCII:
anything else in it (a newline or a non-ASCII character of a path) is written as its Python escape
(``\\n``, ``\\xe9``), so that the header stays one comment line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bayesmachine.extras import optional
from bayesmachine.region import OutputRegion

from .calib import StereoCalibration
from .images import Crop, crop_image

cv2 = optional("cv2", "OpenCV")

__all__ = ["PLY_FIELDS", "left_colours", "point_cloud", "write_ply", "ply_comment"]

# (name, PLY type, NumPy little-endian type), in file order.
PLY_FIELDS = (("x", "float", "<f4"), ("y", "float", "<f4"), ("z", "float", "<f4"),
              ("red", "uchar", "u1"), ("green", "uchar", "u1"), ("blue", "uchar", "u1"),
              ("confidence", "float", "<f4"))


def left_colours(path: str | None, crop: Crop | None = None) -> np.ndarray:
    """The left image as RGB uint8 (H, W, 3), cropped: ``path`` (a gray image is repeated in all three
    channels), or None for the bundled pair's."""
    if path is None:
        from skimage import data

        rgb = np.asarray(data.stereo_motorcycle()[0])
    else:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ValueError(f"cannot read {path} as an image")
        if image.ndim == 2:
            rgb = np.repeat(image[:, :, None], 3, axis=2)
        else:
            code = cv2.COLOR_BGRA2RGB if image.shape[2] == 4 else cv2.COLOR_BGR2RGB
            rgb = cv2.cvtColor(image, code)
    return np.ascontiguousarray(crop_image(rgb, crop))


def point_cloud(depth: np.ndarray, calib: StereoCalibration, region: OutputRegion, colours: np.ndarray,
                confidence: np.ndarray | None = None) -> np.ndarray:
    """The points of the output pixels with a finite ``depth`` (Ho, Wo): a structured array of
    :data:`PLY_FIELDS` (without ``confidence`` when None). ``calib`` is the calibration of the
    (cropped) input image and ``colours`` that image's RGB; ``region`` places the output pixels on it."""
    rows, cols = np.indices((region.image_height, region.image_width))
    v, u = region.cut(rows), region.cut(cols)
    z = np.asarray(depth, np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        xyz = np.stack([(u - calib.cx) * z / calib.fx, (v - calib.cy) * z / calib.fy, z])
    keep = (np.abs(xyz) <= np.finfo(np.float32).max).all(axis=0)  # finite, and finite as float32
    fields = PLY_FIELDS if confidence is not None else PLY_FIELDS[:6]
    points = np.empty(int(keep.sum()), dtype=[(n, t) for n, _, t in fields])
    for i, name in enumerate(("x", "y", "z")):
        points[name] = xyz[i][keep]
    rgb = region.cut(colours)[keep]
    for i, name in enumerate(("red", "green", "blue")):
        points[name] = rgb[:, i]
    if confidence is not None:
        points["confidence"] = confidence[keep]
    return points


def ply_comment(text: str) -> str:
    """``text`` as one line of printable ASCII: every other character as its Python escape (a backslash
    too, so that the escapes read back unambiguously)."""
    return "".join(c if " " <= c <= "~" and c != "\\" else c.encode("unicode_escape").decode("ascii")
                   for c in text)


def write_ply(path: str | Path, points: np.ndarray, comments: tuple[str, ...] = ()) -> None:
    """Write ``points`` (a structured array of :data:`PLY_FIELDS`' names) as a binary little-endian PLY;
    each comment as :func:`ply_comment` makes it."""
    types = {n: p for n, p, _ in PLY_FIELDS}
    header = ["ply", "format binary_little_endian 1.0", *(f"comment {ply_comment(c)}" for c in comments),
              f"element vertex {len(points)}",
              *(f"property {types[n]} {n}" for n in points.dtype.names or ()), "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(np.ascontiguousarray(points).tobytes())
