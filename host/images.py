"""Stereo images: loading, gray conversion, crops, the bundled pair, random-dot stereograms.

Every image the host processes is a rectified 8-bit grayscale array (H, W) uint8.
Colour inputs are converted with OpenCV (``cv2.cvtColor``, BGR order as ``cv2.imread``
returns it; the bundled pair is RGB and converted as such). Ground-truth disparity maps
are float32 arrays of the same shape with ``inf`` for "unknown", decoded from what a file
stores by one function, :func:`decode_disparity` (formats: :data:`GT_FORMATS`).
OpenCV's own log is silenced while it reads a file: a file it cannot read gives our one
error line, not its ``[ WARN ]``/``[ERROR]`` lines first.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bayesmachine.extras import optional, require
from bayesmachine.region import FILTER_SIZE, MARGIN, OutputRegion

cv2 = optional("cv2", "OpenCV")

# FFmpeg (OpenCV's video back end) logs to stderr by itself ("moov atom not found" before our own
# error line); it reads this once, at its first use. A user's own setting wins.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

__all__ = [
    "FILTER_SIZE",
    "MARGIN",
    "Crop",
    "parse_crop",
    "crop_image",
    "to_gray",
    "load_image",
    "load_gt",
    "check_readable",
    "opencv_quiet",
    "decode_disparity",
    "GT_FORMATS",
    "bundled_pair",
    "validate_pair",
    "random_dot_stereogram",
]


@dataclass(frozen=True)
class Crop:
    """A rectangle in input-image pixel coordinates (x, y of the top-left corner)."""

    x: int
    y: int
    width: int
    height: int

    def __str__(self) -> str:
        return f"{self.x},{self.y},{self.width},{self.height}"


def parse_crop(text: str) -> Crop:
    """Parse ``X,Y,W,H`` (the ``--crop`` option)."""
    parts = text.split(",")
    if len(parts) != 4:
        raise ValueError(f"crop must be X,Y,W,H (four integers), got {text!r}")
    try:
        x, y, w, h = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"crop must be X,Y,W,H (four integers), got {text!r}") from None
    if x < 0 or y < 0 or w <= 0 or h <= 0:
        raise ValueError(f"crop {text!r}: X and Y must be >= 0, W and H > 0")
    return Crop(x, y, w, h)


def crop_image(image: np.ndarray, crop: Crop | None) -> np.ndarray:
    """Cut ``crop`` out of ``image``; a crop that leaves the image is an error, not clipped."""
    if crop is None:
        return image
    h, w = image.shape[:2]
    if crop.x + crop.width > w or crop.y + crop.height > h:
        raise ValueError(
            f"crop {crop} (x={crop.x}..{crop.x + crop.width - 1}, y={crop.y}..{crop.y + crop.height - 1}) "
            f"lies outside the {w}x{h} image"
        )
    return image[crop.y : crop.y + crop.height, crop.x : crop.x + crop.width]


def to_gray(image: np.ndarray, rgb: bool = False) -> np.ndarray:
    """An 8-bit image as (H, W) uint8 luminance; colour converted with OpenCV.

    ``rgb`` says the channel order is RGB (scikit-image) rather than OpenCV's BGR.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"images must be 8-bit (uint8), got {image.dtype}")
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY if rgb else cv2.COLOR_BGR2GRAY)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_RGBA2GRAY if rgb else cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"unsupported image shape {image.shape}: expected gray, BGR or BGRA")


def check_readable(path: Path, what: str) -> None:
    """A clear error for a path that is not a readable file (before a reader says something vaguer)."""
    if not path.exists():
        raise FileNotFoundError(f"{what} not found: {path}")
    if path.is_dir():
        raise ValueError(f"{what} {path} is a directory, not a file")
    if not path.is_file():
        raise ValueError(f"{what} {path} is not a regular file")
    if not os.access(path, os.R_OK):
        raise PermissionError(13, "permission denied (cannot read it)", str(path))


@contextlib.contextmanager
def opencv_quiet() -> Iterator[None]:
    """OpenCV's own log silenced in the block (its ``[ WARN ]`` lines; FFmpeg's are off from import)."""
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is None:  # an OpenCV without the logging module
        yield
        return
    previous = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        log.setLogLevel(previous)


# Netpbm and PFM headers: the magic, then width and height (comments allowed in Netpbm's).
_PNM_MAGIC = (b"P1", b"P2", b"P3", b"P4", b"P5", b"P6", b"P7", b"PF", b"Pf")


def _declared_size(path: Path) -> tuple[int, int] | None:
    """The width and height a Netpbm/PFM file's header declares (None: another format, or no
    numbers where they belong)."""
    try:
        with open(path, "rb") as f:
            head = f.read(512)
    except OSError:
        return None
    if head[:2] not in _PNM_MAGIC:
        return None
    tokens = re.sub(rb"#[^\n]*", b" ", head[2:]).split()[:2]
    if len(tokens) < 2 or not all(re.fullmatch(rb"[-+]?\d+", t) for t in tokens):
        return None
    return int(tokens[0]), int(tokens[1])


MAX_PIXELS = 1 << 30  # OpenCV's own limit on an image it reads


def _imread(path: Path) -> np.ndarray | None:
    """``cv2.imread(path, IMREAD_UNCHANGED)`` with OpenCV's log silenced (None if it cannot read it;
    ValueError naming the file for a header declaring 0, negative or over 2^30 pixels)."""
    try:
        with opencv_quiet():
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    except cv2.error:  # OpenCV asserts on some headers instead of returning None
        image = None
        refused = True
    else:
        refused = False
    if image is None:
        size = _declared_size(path)
        if size is not None and not (size[0] > 0 and size[1] > 0 and size[0] * size[1] <= MAX_PIXELS):
            raise ValueError(f"cannot read {path}: its header declares {size[0]} x {size[1]} pixels (an "
                             "image holds 1 to 2^30)")
        if refused:
            raise ValueError(f"cannot read {path}: OpenCV refuses its header (a corrupt file?)")
    return image


def load_image(path: str | Path) -> np.ndarray:
    """Read an 8-bit image file with OpenCV and return it as gray (H, W) uint8."""
    path = Path(path)
    check_readable(path, "image file")
    image = _imread(path)
    if image is None:
        raise ValueError(f"cannot read {path} as an image (not an image, or an unknown or corrupt format)")
    if image.dtype != np.uint8:
        raise ValueError(f"{path}: images must be 8-bit, got {image.dtype}")
    return to_gray(image)


def _load_npy(path: Path) -> np.ndarray:
    with open(path, "rb") as f:
        magic = f.read(len(np.lib.format.MAGIC_PREFIX))
    if magic != np.lib.format.MAGIC_PREFIX:
        raise ValueError(f"{path} is not a NumPy array file (.npy): it does not start with the NPY header")
    try:
        gt = np.load(path, allow_pickle=False)
    except ValueError as exc:  # e.g. an array of Python objects
        raise ValueError(f"{path} is not a NumPy array of numbers: {exc}") from None
    except (EOFError, OSError) as exc:
        raise ValueError(f"{path} is not a readable NumPy array file (truncated or corrupt: {exc})") from None
    return gt


GT_FORMATS = (
    "accepted: .pfm (floats, inf = unknown), .npy (numbers, non-finite = unknown), a one-channel "
    "image (integers, 0 = unknown; 8-bit at face value, 16-bit with --gt-scale, e.g. 256 for KITTI)"
)


def decode_disparity(
    raw: np.ndarray, name: str, *, image: bool, scale: float | None = None
) -> np.ndarray:
    """The one decoding of a stored disparity map: float32 disparities, ``inf`` = unknown.

    ``image``: ``raw`` is an image file's pixels: integer pixels are disparities with 0 =
    unknown, and wider than 8 bits they are stored scaled (KITTI: disparity x 256), so a
    ``scale`` must be given. Otherwise (``.npy``, the bundled map) the numbers as stored.
    Floats of either kind: non-finite = unknown (Middlebury's ``.pfm``: inf). ``scale``
    divides every value (default 1). Refused, with what is accepted: several channels
    that differ (a colour image, not a map), any other shape or type, negative disparities.
    """
    a = np.asarray(raw)
    if a.ndim == 3 and a.shape[2] > 1:
        if not all(np.array_equal(a[:, :, c], a[:, :, 0], equal_nan=a.dtype.kind == "f")
                   for c in range(1, a.shape[2])):
            raise ValueError(f"{name}: a colour image ({a.shape[2]} channels that differ), not a disparity "
                             f"map of one channel; {GT_FORMATS}")
    if a.ndim == 3:
        a = a[:, :, 0]  # one channel, or several equal ones
    if a.ndim != 2:
        raise ValueError(f"{name}: a disparity map must be 2-D, got shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise ValueError(f"{name}: a disparity map must hold integers or floats, got {a.dtype}; {GT_FORMATS}")
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"{name}: the ground-truth scale must be a finite number > 0, got {scale}")
    integers = np.issubdtype(a.dtype, np.integer)
    if image and integers and a.dtype.itemsize > 1 and scale is None:
        raise ValueError(
            f"{name}: a {8 * a.dtype.itemsize}-bit image stores its disparities scaled; say by how much "
            "with --gt-scale (--gt-scale 256 for KITTI, whose PNGs hold disparity x 256, 0 = unknown)"
        )
    unknown = (a == 0) if image and integers else ~np.isfinite(a)
    negative = (a < 0) & ~unknown
    if negative.any():
        raise ValueError(
            f"{name}: {int(negative.sum())} negative disparities (the smallest {a[negative].min():g}); "
            "disparities are >= 0, unknown ones "
            + ("0 in an image" if image and integers else "inf or nan")
        )
    d = a.astype(np.float64)
    if scale is not None:
        d = d / scale
    return np.where(unknown, np.inf, d).astype(np.float32)


def load_gt(path: str | Path, scale: float | None = None, bits: int | None = None) -> np.ndarray:
    """Read a ground-truth disparity map as float32, inf = unknown (:func:`decode_disparity`).

    ``.npy``: the numbers as stored, non-finite = unknown. ``.pfm`` (Middlebury): floats,
    inf = unknown. Any other image format: one channel (or equal ones) of integer
    disparities with 0 = unknown, 16-bit ones only with a ``scale``. ``scale``: the file
    stores disparity x ``scale`` (``--gt-scale``). ``bits``: the depth an image must have (a
    dataset layout's, KITTI's 16): another is refused, naming the file and its depth.
    """
    path = Path(path)
    check_readable(path, "ground-truth file")
    if path.suffix.lower() == ".npy":
        return decode_disparity(_load_npy(path), str(path), image=False, scale=scale)
    raw = _imread(path)
    if raw is None:
        raise ValueError(f"cannot read {path} as a disparity map (not an image, or a corrupt .pfm); "
                         f"{GT_FORMATS}")
    if bits is not None and raw.dtype.kind in "iu" and 8 * raw.dtype.itemsize != bits:
        raise ValueError(f"{path}: {8 * raw.dtype.itemsize}-bit ground truth, where this layout's is "
                         f"{bits}-bit (disparity x {scale or 1:g}); --gt-scale S reads it as disparity x S")
    return decode_disparity(raw, str(path), image=True, scale=scale)


def bundled_pair() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Middlebury 2014 Motorcycle (500x741), shipped inside scikit-image: left, right, gt.

    Loads offline. gt is float32 with +inf where unknown.
    """
    data = require("skimage.data", "scikit-image")
    left, right, gt = data.stereo_motorcycle()
    gt = decode_disparity(gt, "the bundled Motorcycle ground truth", image=False)
    return to_gray(left, rgb=True), to_gray(right, rgb=True), gt


def validate_pair(left: np.ndarray, right: np.ndarray, dmax: int, margin: int = MARGIN) -> None:
    """Raise ValueError naming the problem if the pair cannot be processed with ``dmax`` (by a model
    of ``margin``: ``ModelParams.margin``)."""
    for name, image in (("left", left), ("right", right)):
        if image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(f"{name} image must be 2-D uint8 gray, got {image.dtype} {image.shape}")
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in shape: {left.shape} vs {right.shape}")
    OutputRegion.of_image(left.shape, dmax, margin)  # raises naming the size problem


def random_dot_stereogram(
    height: int = 64,
    width: int = 96,
    background: int = 4,
    square: int = 12,
    square_box: tuple[int, int, int, int] | None = None,
    dot: int = 1,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A textured random right image and a left image with known disparity.

    The left image is the right one seen at disparity ``background`` except inside the
    square ``square_box`` = (x, y, w, h) (left-image coordinates, default centred),
    which is at disparity ``square``: left(y, x) = right(y, x - d(y, x)). ``dot`` is the
    side of the random dots. Returns (left, right, gt) with gt float32 = d, and +inf
    where x - d falls outside the right image (no match exists).
    """
    rng = np.random.default_rng(seed)
    dots = rng.integers(0, 256, size=(-(-height // dot), -(-width // dot)), dtype=np.uint8)
    right = np.repeat(np.repeat(dots, dot, axis=0), dot, axis=1)[:height, :width]
    if square_box is None:
        square_box = (width // 3, height // 4, width // 3, height // 2)
    sx, sy, sw, sh = square_box
    disp = np.full((height, width), background, dtype=np.int64)
    disp[sy : sy + sh, sx : sx + sw] = square
    xs = np.arange(width)[None, :] - disp
    valid = xs >= 0
    fill = rng.integers(0, 256, size=(height, width), dtype=np.uint8)
    left = np.where(valid, right[np.arange(height)[:, None], np.clip(xs, 0, width - 1)], fill)
    gt = np.where(valid, disp, np.inf).astype(np.float32)
    return left.astype(np.uint8), right, gt
