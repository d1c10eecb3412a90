"""Stereo calibration: what turns a disparity into a depth in metres.

:func:`read_calibration` reads the three formats ``--calib`` takes, each into one
:class:`StereoCalibration` (focal lengths and principal point in pixels, baseline in metres,
``doffs`` in pixels):

* Middlebury 2014/2021 ``calib.txt``: ``cam0=[f 0 cx; 0 f cy; 0 0 1]``, ``cam1=[...]``,
  ``doffs`` (the x-difference of the principal points, cam1 - cam0), ``baseline`` in **mm**
  (converted to metres), ``width``, ``height``;
* KITTI: a stereo ``calib/*.txt`` (``P0:`` .. ``P3:``, 3x4 projection matrices) or a raw-data
  ``calib_cam_to_cam.txt`` (``P_rect_00:`` .. ``P_rect_03:``, ``S_rect_0i:`` the image size): the
  left and right cameras' matrices (2 and 3 by default, the colour pair; 0 and 1 for the gray
  pair), baseline = (P_left[0,3] - P_right[0,3]) / fx, doffs = P_right[0,2] - P_left[0,2];
* a JSON object ``{"fx", "fy", "cx", "cy", "baseline"}`` (baseline in **metres**) with optional
  ``"doffs"`` (pixels, default 0), ``"width"`` and ``"height"`` (the image size it is for).

Depth is ``Z = fx * baseline / (d + doffs)``; a point at image pixel (u, v) is
``X = (u - cx) Z / fx``, ``Y = (v - cy) Z / fy`` (x right, y down, z forward: the left camera's
frame). A missing, malformed or inconsistent field is a ValueError naming it, and a calibration
whose image size differs from the pair's is refused: a cloud is never silently scaled.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from .images import Crop

__all__ = ["StereoCalibration", "read_calibration", "BUNDLED_CALIB", "bundled_calibration_path",
           "KITTI_CAMERAS"]

BUNDLED_CALIB = "bundled"  # --calib bundled: the shipped calibration of the bundled Motorcycle pair
KITTI_CAMERAS = (2, 3)
_JSON_FIELDS = ("fx", "fy", "cx", "cy", "baseline")
_JSON_OPTIONAL = ("doffs", "width", "height")


@dataclass(frozen=True, kw_only=True)
class StereoCalibration:
    """A rectified stereo pair's calibration.

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        The left camera's principal point in pixels.
    baseline : float
        Distance between the two camera centres, in metres (> 0).
    doffs : float
        x-difference of the principal points, right - left, in pixels (0 when both are the same).
    width, height : int or None
        The image size the calibration is for, when the file says; None: not checked.
    source : str
        Where it was read from (for messages and the report).

    Attributes
    ----------
    fx, fy, cx, cy, baseline, doffs, width, height, source
        As given (read-only).
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
        for name in ("fx", "fy", "cx", "cy", "baseline", "doffs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise TypeError(f"{self._where()}{name} must be a number, not {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"{self._where()}{name} must be finite, got {value}")
            object.__setattr__(self, name, float(value))
        for name in ("fx", "fy", "baseline"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{self._where()}{name} must be > 0, got {getattr(self, name):g}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))):
                raise TypeError(f"{self._where()}{name} must be an integer, not {value!r}")
            if value is not None and value <= 0:
                raise ValueError(f"{self._where()}{name} must be > 0, got {value}")

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
        or is not finite, +inf where d + doffs <= 0 (a point at infinity)."""
        d = np.asarray(disp, dtype=np.float64)
        valid = np.isfinite(d) & (d >= 0)
        den = np.where(valid, d + self.doffs, 1.0)
        with np.errstate(divide="ignore"):
            z = np.where(den > 0, self.fx * self.baseline / np.where(den > 0, den, 1.0), np.inf)
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
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what}: expected {count} finite numbers, got {text.strip()!r}")
    return values


def _middlebury(text: str, source: str) -> StereoCalibration:
    fields = {}
    for line in text.splitlines():
        if "=" in line:
            key, value = line.split("=", 1)
            fields[key.strip()] = value.strip()
    missing = [k for k in ("cam0", "doffs", "baseline") if k not in fields]
    if missing:
        raise ValueError(f"{source}: a Middlebury calib.txt needs cam0, doffs and baseline; "
                         f"{', '.join(missing)} missing")
    cam0 = np.array(_numbers(fields["cam0"], f"{source}: cam0", 9)).reshape(3, 3)
    doffs = _numbers(fields["doffs"], f"{source}: doffs", 1)[0]
    baseline_mm = _numbers(fields["baseline"], f"{source}: baseline", 1)[0]
    if cam0[0, 1] != 0 or cam0[1, 0] != 0 or list(cam0[2]) != [0, 0, 1]:
        raise ValueError(f"{source}: cam0 must be [f 0 cx; 0 f cy; 0 0 1], got {fields['cam0']}")
    if "cam1" in fields:  # a file scaled by hand must stay consistent: doffs = cx1 - cx0, same f
        cam1 = np.array(_numbers(fields["cam1"], f"{source}: cam1", 9)).reshape(3, 3)
        if abs(cam1[0, 2] - cam0[0, 2] - doffs) > 0.01 * max(1.0, abs(doffs)) or cam1[0, 0] != cam0[0, 0]:
            raise ValueError(f"{source}: doffs={doffs:g} and cam1 disagree (cam1 cx - cam0 cx = "
                             f"{cam1[0, 2] - cam0[0, 2]:g}, focal {cam1[0, 0]:g} vs {cam0[0, 0]:g})")
    size = {}
    for key in ("width", "height"):
        if key in fields:
            value = _numbers(fields[key], f"{source}: {key}", 1)[0]
            if value != int(value):
                raise ValueError(f"{source}: {key} must be an integer, got {fields[key]}")
            size[key] = int(value)
    return StereoCalibration(fx=cam0[0, 0], fy=cam0[1, 1], cx=cam0[0, 2], cy=cam0[1, 2],
                             baseline=baseline_mm / 1000.0, doffs=doffs, source=source, **size)


def _kitti(text: str, source: str, cameras: tuple[int, int]) -> StereoCalibration:
    fields = {}
    for line in text.splitlines():
        if ":" in line:
            key, value = line.split(":", 1)
            fields[key.strip()] = value
    rect = any(k.startswith("P_rect_") for k in fields)
    names = [f"P_rect_{c:02d}" if rect else f"P{c}" for c in cameras]
    missing = [n for n in names if n not in fields]
    if missing:
        raise ValueError(f"{source}: KITTI calibration without {' and '.join(missing)} (cameras "
                         f"{cameras[0]} and {cameras[1]})")
    p_left, p_right = (np.array(_numbers(fields[n], f"{source}: {n}", 12)).reshape(3, 4) for n in names)
    fx = p_left[0, 0]
    if fx <= 0 or p_right[0, 0] != fx:
        raise ValueError(f"{source}: {names[0]} and {names[1]} must share one focal length > 0 (rectified), "
                         f"got {fx:g} and {p_right[0, 0]:g}")
    baseline = (p_left[0, 3] - p_right[0, 3]) / fx
    if baseline <= 0:
        raise ValueError(f"{source}: camera {cameras[1]} is not to the right of camera {cameras[0]} "
                         f"({names[0]}[0,3] - {names[1]}[0,3] = {p_left[0, 3] - p_right[0, 3]:g})")
    size: dict[str, int] = {}
    key = f"S_rect_{cameras[0]:02d}"
    if rect and key in fields:
        w, h = _numbers(fields[key], f"{source}: {key}", 2)
        size = {"width": int(round(w)), "height": int(round(h))}
    return StereoCalibration(fx=fx, fy=p_left[1, 1], cx=p_left[0, 2], cy=p_left[1, 2], baseline=baseline,
                             doffs=p_right[0, 2] - p_left[0, 2], source=source, **size)


def _json(text: str, source: str) -> StereoCalibration:
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise ValueError(f"{source}: not valid JSON ({exc})") from None
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


def read_calibration(path: str | Path, cameras: tuple[int, int] | None = None) -> StereoCalibration:
    """The calibration in ``path`` (Middlebury ``calib.txt``, KITTI ``calib/*.txt`` or
    ``calib_cam_to_cam.txt``, or JSON), ``cameras`` (left, right) naming KITTI's matrices (default
    :data:`KITTI_CAMERAS`); the other formats name no cameras, so ``cameras`` with them is refused."""
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{source}: not a text calibration file") from None
    except OSError as exc:
        raise OSError(exc.errno, f"cannot read the calibration: {exc.strerror}", source) from None
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
