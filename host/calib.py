"""Stereo calibration: what turns a disparity into a depth in metres.

:func:`read_calibration` reads the three formats ``--calib`` takes, each into one
:class:`StereoCalibration` (focal lengths and principal point in pixels, baseline in metres,
``doffs`` in pixels):

* Middlebury 2014/2021 ``calib.txt``: ``cam0=[f 0 cx; 0 f cy; 0 0 1]``, ``cam1=[...]`` (optional: the
  right camera, whose f and cy must equal cam0's and whose cx is cam0's + doffs), ``doffs`` (the
  x-difference of the principal points, cam1 - cam0), ``baseline`` in **mm** (converted to metres),
  ``width``, ``height``;
* KITTI: a stereo ``calib/*.txt`` (``P0:`` .. ``P3:``, 3x4 projection matrices) or a raw-data
  ``calib_cam_to_cam.txt`` (``P_rect_00:`` .. ``P_rect_03:``, ``S_rect_0i:`` the image size): the
  left and right cameras' matrices (2 and 3 by default, the colour pair; 0 and 1 for the gray
  pair), which share fx, fy and cy (rectified), baseline = (P_left[0,3] - P_right[0,3]) / fx,
  doffs = P_right[0,2] - P_left[0,2];
* a JSON object ``{"fx", "fy", "cx", "cy", "baseline"}`` (baseline in **metres**) with optional
  ``"doffs"`` (pixels, default 0), ``"width"`` and ``"height"`` (the image size it is for).

Depth is ``Z = fx * baseline / (d + doffs)``; a point at image pixel (u, v) is
``X = (u - cx) Z / fx``, ``Y = (v - cy) Z / fy`` (x right, y down, z forward: the left camera's
frame). A missing, repeated, malformed or inconsistent field is a ValueError naming it, and so is a
value outside its physical range (:data:`RANGES`; said in the file's own units: a Middlebury baseline
in mm), which keeps every depth a finite float; a calibration whose image size differs from the
pair's is refused: a cloud is never silently scaled. The file is read only if it is a regular file
of at most :data:`MAX_CALIB_BYTES` (a device, a pipe or a directory is refused before it is opened),
a UTF-8 byte-order mark skipped.
"""

from __future__ import annotations

import json
import os
import re
import stat
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from bayesmachine.checks import as_int, as_real, type_name
from bayesmachine.errors import ParameterError

from .images import Crop

__all__ = ["StereoCalibration", "read_calibration", "BUNDLED_CALIB", "bundled_calibration_path",
           "KITTI_CAMERAS", "RANGES", "MAX_CALIB_BYTES"]

BUNDLED_CALIB = "bundled"  # --calib bundled: the shipped calibration of the bundled Motorcycle pair
KITTI_CAMERAS = (2, 3)
_JSON_FIELDS = ("fx", "fy", "cx", "cy", "baseline")
_JSON_OPTIONAL = ("doffs", "width", "height")
# The physical range of each field (pixels; the baseline in metres): a focal length of 1 pixel to 10^6
# (a long telephoto on a large sensor), a principal point and doffs within 10^6 pixels, a baseline of
# a micrometre (a stereo microscope) to 1000 km (satellite pairs). Within them f x baseline is in
# [1e-6, 1e12] and every depth fx * baseline / (d + doffs) a finite float.
RANGES: dict[str, tuple[float, float, str]] = {
    "fx": (1.0, 1e6, "pixels"), "fy": (1.0, 1e6, "pixels"),
    "cx": (-1e6, 1e6, "pixels"), "cy": (-1e6, 1e6, "pixels"), "doffs": (-1e6, 1e6, "pixels"),
    "baseline": (1e-6, 1e6, "m"),
}
MAX_SIZE = 1 << 30  # width and height: at most the pixels of an image (bayesmachine.host.images)
MAX_CALIB_BYTES = 1 << 20  # a calibration file is a few hundred bytes; anything past 1 MiB is not one


def _field(source: str, label: str, value: object, field: str, per_unit: float = 1.0,
           unit: str = "") -> float:
    """``value`` of ``field`` (as the file says it: ``label``, in ``unit``, ``per_unit`` of the field's
    own unit each) in the field's physical range, said in the file's unit; returned in the field's."""
    lo, hi, own = RANGES[field]
    try:
        return as_real(label, value, lo / per_unit, hi / per_unit, f" {unit or own}") * per_unit
    except ParameterError as exc:
        raise ParameterError(f"{source}: {exc}" if source else str(exc), field) from None


@dataclass(frozen=True, kw_only=True)
class StereoCalibration:
    """A rectified stereo pair's calibration (keyword arguments only).

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels, in [1, 1e6].
    cx, cy : float
        The left camera's principal point in pixels, in [-1e6, 1e6].
    baseline : float
        Distance between the two camera centres, in metres, in [1e-6, 1e6].
    doffs : float
        x-difference of the principal points, right - left, in pixels (0 when both are the same), in
        [-1e6, 1e6].
    width, height : int or None
        The image size the calibration is for, when the file says; None: not checked.
    source : str
        Where it was read from (for messages and the report).

    Numbers may be any real (NumPy scalars too), sizes any integer (``operator.index``); a wrong type is
    a TypeError, a value outside its physical range (:data:`RANGES`) a ParameterError naming it.

    Attributes
    ----------
    fx, fy, cx, cy, baseline, doffs, width, height, source
        As given, as plain Python numbers (read-only).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    baseline: float
    doffs: float = 0.0
    width: int | None = None
    height: int | None = None
    source: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.source, str):
            raise TypeError(f"source must be a str, not {type_name(self.source)}")
        try:
            for name in RANGES:
                object.__setattr__(self, name, _field("", name, getattr(self, name), name))
            for name in ("width", "height"):
                if getattr(self, name) is not None:
                    object.__setattr__(self, name, as_int(name, getattr(self, name), 1, MAX_SIZE))
        except ParameterError as exc:
            raise ParameterError(f"{self._where()}{exc}", exc.parameter) from None
        except TypeError as exc:
            raise TypeError(f"{self._where()}{exc}") from None

    def _where(self) -> str:
        return f"{self.source}: " if self.source else ""

    def for_input(self, shape: tuple[int, ...], crop: Crop | None = None) -> StereoCalibration:
        """This calibration for an input image of ``shape`` (H, W, ...) cut to ``crop``: the size
        is checked against the calibration's own, the principal point moves with the crop."""
        h, w = int(shape[0]), int(shape[1])
        if (self.width is not None and self.width != w) or (self.height is not None and self.height != h):
            raise ValueError(
                f"{self._where()}the calibration is for {self.width}x{self.height} images, the pair is "
                f"{w}x{h}: give the calibration of images of this size (scaling one is not done silently)")
        if crop is None:
            return self
        return replace(self, cx=self.cx - crop.x, cy=self.cy - crop.y, width=crop.width, height=crop.height)

    def depth(self, disp: np.ndarray) -> np.ndarray:
        """Depth in metres of each disparity: fx * baseline / (d + doffs); NaN where d < 0 (no match)
        or is not finite, +inf where d + doffs <= 0 (a point at infinity) or the depth is past float32's
        range (3.4e38 m: d + doffs within 1e-26 of 0, what depth.npy and the cloud hold as infinity)."""
        d = np.asarray(disp, dtype=np.float64)
        valid = np.isfinite(d) & (d >= 0)
        den = np.where(valid, d + self.doffs, 1.0)
        with np.errstate(divide="ignore", over="ignore"):
            z = np.where(den > 0, self.fx * self.baseline / np.where(den > 0, den, 1.0), np.inf)
        z = np.where(z <= np.finfo(np.float32).max, z, np.inf)
        return np.where(valid, z, np.nan)

    def to_dict(self) -> dict[str, object]:
        return {k: getattr(self, k) for k in ("fx", "fy", "cx", "cy", "baseline", "doffs", "width",
                                               "height", "source")}


def bundled_calibration_path() -> Path:
    """The shipped Middlebury ``calib.txt`` of the bundled Motorcycle pair (741x500, scaled 1/4)."""
    return Path(str(resources.files("bayesmachine.host") / "data" / "motorcycle-calib.txt"))


def _numbers(text: str, what: str, count: int) -> list[float]:
    parts = text.replace(";", " ").replace("[", " ").replace("]", " ").split()
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"{what}: expected {count} numbers, got {text.strip()!r}") from None
    if len(values) != count or not all(np.isfinite(values)):
        raise ValueError(f"{what}: expected {count} finite numbers, got {text.strip()!r}")
    return values


def _fields(text: str, source: str, sep: str) -> dict[str, str]:
    """``key SEP value`` lines (others are skipped); a key given twice is refused (which one holds?)."""
    fields: dict[str, str] = {}
    lines: dict[str, int] = {}
    for number, line in enumerate(text.splitlines(), 1):
        if sep in line:
            key, value = line.split(sep, 1)
            key = key.strip()
            if key in fields:
                raise ValueError(f"{source}: {key} is given twice (lines {lines[key]} and {number}): "
                                 "keep one")
            fields[key], lines[key] = value.strip(), number
    return fields


def _matrix(fields: dict[str, str], source: str, name: str) -> np.ndarray:
    """A Middlebury camera matrix [f 0 cx; 0 f cy; 0 0 1]."""
    m = np.array(_numbers(fields[name], f"{source}: {name}", 9)).reshape(3, 3)
    if m[0, 1] != 0 or m[1, 0] != 0 or list(m[2]) != [0, 0, 1]:
        raise ValueError(f"{source}: {name} must be [f 0 cx; 0 f cy; 0 0 1], got {fields[name]}")
    return m


def _middlebury(text: str, source: str) -> StereoCalibration:
    fields = _fields(text, source, "=")
    missing = [k for k in ("cam0", "doffs", "baseline") if k not in fields]
    if missing:
        raise ValueError(f"{source}: a Middlebury calib.txt needs cam0, doffs and baseline; "
                         f"{', '.join(missing)} missing")
    cam0 = _matrix(fields, source, "cam0")
    doffs = _numbers(fields["doffs"], f"{source}: doffs", 1)[0]
    baseline_mm = _numbers(fields["baseline"], f"{source}: baseline", 1)[0]
    if "cam1" in fields:  # the right camera of a rectified pair: same f and rows, cx moved by doffs
        cam1 = _matrix(fields, source, "cam1")
        for what, (i, j) in (("f", (0, 0)), ("fy", (1, 1)), ("cy", (1, 2))):
            if cam1[i, j] != cam0[i, j]:
                raise ValueError(f"{source}: cam1's {what} {cam1[i, j]:g} differs from cam0's "
                                 f"{cam0[i, j]:g}: a rectified pair has one focal length and the same rows")
        if abs(cam1[0, 2] - cam0[0, 2] - doffs) > 0.01 * max(1.0, abs(doffs)):
            raise ValueError(f"{source}: doffs={doffs:g} and cam1 disagree (cam1 cx - cam0 cx = "
                             f"{cam1[0, 2] - cam0[0, 2]:g})")
    size = {}
    for key in ("width", "height"):
        if key in fields:
            value = _numbers(fields[key], f"{source}: {key}", 1)[0]
            if value != int(value):
                raise ValueError(f"{source}: {key} must be an integer, got {fields[key]}")
            size[key] = int(value)
    checked = {name: _field(source, f"cam0 {label}", cam0[i, j], name)
               for name, label, (i, j) in (("fx", "f", (0, 0)), ("fy", "fy", (1, 1)), ("cx", "cx", (0, 2)),
                                           ("cy", "cy", (1, 2)))}
    baseline = _field(source, "baseline", baseline_mm, "baseline", 1e-3, "mm")  # in mm, at most 1e9
    return StereoCalibration(**checked, baseline=baseline, doffs=_field(source, "doffs", doffs, "doffs"),
                             source=source, **size)


def _kitti(text: str, source: str, cameras: tuple[int, int]) -> StereoCalibration:
    fields = _fields(text, source, ":")
    rect = any(k.startswith("P_rect_") for k in fields)
    names = [f"P_rect_{c:02d}" if rect else f"P{c}" for c in cameras]
    missing = [n for n in names if n not in fields]
    if missing:
        raise ValueError(f"{source}: KITTI calibration without {' and '.join(missing)} (cameras "
                         f"{cameras[0]} and {cameras[1]})")
    p_left, p_right = (np.array(_numbers(fields[n], f"{source}: {n}", 12)).reshape(3, 4) for n in names)
    fx = _field(source, f"{names[0]}[0,0] (fx)", p_left[0, 0], "fx")
    for i, j in ((0, 0), (1, 1), (1, 2)):  # rectified: one focal length, the same rows
        if p_right[i, j] != p_left[i, j]:
            raise ValueError(f"{source}: {names[0]} and {names[1]} must share [{i},{j}] (rectified: one "
                             f"focal length, the same rows), got {p_left[i, j]:g} and {p_right[i, j]:g}")
    shift = p_left[0, 3] - p_right[0, 3]
    if shift <= 0:
        raise ValueError(f"{source}: camera {cameras[1]} is not to the right of camera {cameras[0]} "
                         f"({names[0]}[0,3] - {names[1]}[0,3] = {shift:g})")
    baseline = _field(source, f"baseline ({names[0]}[0,3] - {names[1]}[0,3]) / fx", shift / fx, "baseline")
    size: dict[str, int] = {}
    key = f"S_rect_{cameras[0]:02d}"
    if rect and key in fields:
        w, h = _numbers(fields[key], f"{source}: {key}", 2)
        size = {"width": int(round(w)), "height": int(round(h))}
    own = {name: _field(source, f"{names[0]}[{i},{j}] ({name})", p_left[i, j], name)
           for name, (i, j) in (("fy", (1, 1)), ("cx", (0, 2)), ("cy", (1, 2)))}
    doffs = _field(source, f"doffs ({names[1]}[0,2] - {names[0]}[0,2])", p_right[0, 2] - p_left[0, 2],
                   "doffs")
    return StereoCalibration(fx=fx, **own, baseline=baseline, doffs=doffs, source=source, **size)


def _unique_keys(pairs: list[tuple[str, object]]) -> dict[str, object]:
    seen: dict[str, object] = {}
    for key, value in pairs:
        if key in seen:
            raise ValueError(f"the key {key!r} is given twice: keep one")
        seen[key] = value
    return seen


def _json(text: str, source: str) -> StereoCalibration:
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys)
    except ValueError as exc:  # invalid JSON, a repeated key
        raise ValueError(f"{source}: not a JSON calibration ({exc})") from None
    except RecursionError:
        raise ValueError(f"{source}: not a JSON calibration (nested too deep)") from None
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a JSON object {{fx, fy, cx, cy, baseline}}")
    missing = [k for k in _JSON_FIELDS if k not in data]
    unknown = sorted(set(data) - set(_JSON_FIELDS) - set(_JSON_OPTIONAL))
    if missing or unknown:
        problem = "; ".join(p for p in (f"missing {', '.join(missing)}" if missing else "",
                                        f"unknown {', '.join(unknown)}" if unknown else "") if p)
        raise ValueError(f"{source}: the JSON calibration takes fx, fy, cx, cy, baseline (metres) and "
                         f"optionally doffs, width, height: {problem}")
    try:
        return StereoCalibration(**{k: data[k] for k in (*_JSON_FIELDS, *_JSON_OPTIONAL) if k in data},
                                 source=source)
    except TypeError as exc:
        raise ValueError(str(exc)) from None


_NOT_REGULAR = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a device"),
                (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"))


def _regular(mode: int, source: str) -> None:
    if not stat.S_ISREG(mode):
        what = next((name for test, name in _NOT_REGULAR if test(mode)), "not a regular file")
        raise ValueError(f"{source}: {what}, not a calibration file")


def read_text(path: Path) -> str:
    """The text of the calibration file ``path``: a regular file (checked before it is opened, so that a
    pipe with no writer cannot block) of at most :data:`MAX_CALIB_BYTES`, UTF-8 with or without a
    byte-order mark."""
    source = str(path)
    try:
        _regular(os.stat(path).st_mode, source)
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
        with os.fdopen(fd, "rb") as f:
            _regular(os.fstat(f.fileno()).st_mode, source)  # replaced since: checked again, opened
            data = f.read(MAX_CALIB_BYTES + 1)
    except OSError as exc:
        raise OSError(exc.errno, f"cannot read the calibration: {exc.strerror}", source) from None
    if len(data) > MAX_CALIB_BYTES:
        raise ValueError(f"{source}: larger than {MAX_CALIB_BYTES // 1024} KiB, not a calibration file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{source}: not a text calibration file") from None


def _cameras(cameras: object) -> tuple[int, int] | None:
    """``cameras`` as (left, right): two different KITTI cameras 0..3."""
    if cameras is None:
        return None
    if isinstance(cameras, (str, bytes)) or not isinstance(cameras, (tuple, list)) or len(cameras) != 2:
        raise TypeError(f"cameras must be a pair (left, right) of KITTI camera numbers, e.g. (2, 3), not "
                        f"{type_name(cameras)}")
    left, right = (as_int(f"cameras[{i}]", c, 0, 3) for i, c in enumerate(cameras))
    if left == right:
        raise ParameterError(f"cameras must be two different KITTI cameras, got ({left}, {right})", "cameras")
    return left, right


def read_calibration(path: str | Path, cameras: tuple[int, int] | None = None) -> StereoCalibration:
    """The calibration in ``path`` (Middlebury ``calib.txt``, KITTI ``calib/*.txt`` or
    ``calib_cam_to_cam.txt``, or JSON), ``cameras`` (left, right) naming KITTI's matrices (default
    :data:`KITTI_CAMERAS`); the other formats name no cameras, so ``cameras`` with them is refused."""
    cameras = _cameras(cameras)
    path = Path(path)
    source = str(path)
    text = read_text(path)
    if re.search(r"^\s*P(_rect_)?\d+\s*:", text, re.MULTILINE) and not text.lstrip().startswith("{"):
        return _kitti(text, source, cameras or KITTI_CAMERAS)
    if cameras is not None:
        raise ValueError(f"{source}: cameras {cameras[0]},{cameras[1]} pick a KITTI calibration's matrices; "
                         "this file is not a KITTI calibration")
    if path.suffix.lower() == ".json" or text.lstrip().startswith("{"):
        return _json(text, source)
    if re.search(r"^\s*cam0\s*=", text, re.MULTILINE):
        return _middlebury(text, source)
    raise ValueError(f"{source}: not a calibration this reads: a Middlebury calib.txt (cam0=, doffs=, "
                     "baseline=), a KITTI calibration (P2:/P3: or P_rect_02:/P_rect_03:) or JSON "
                     "{fx, fy, cx, cy, baseline}")
