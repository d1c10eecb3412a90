"""Stereo datasets on disk: each layout resolved to pairs of paths, each pair loaded where it runs.

:func:`resolve_dataset` turns what a user points ``bayesmachine sweep --dataset`` at into a
:class:`Dataset`: a list of :class:`PairSpec` (paths only, small and picklable: a Dask worker
loads its own pair with :func:`load_pair`, no image goes through the scheduler) and the notes
about pairs found incomplete. Layouts read (a directory is searched recursively, each scene
directory found is one pair, named by its path under the root):

* Middlebury 2001 (``im2.ppm``, ``im6.ppm``, ``disp2.pgm``: disparity x 8, x 16 for Tsukuba),
  2003 (``im2.png``, ``im6.png``, ``disp2.png``: quarter size, disparity x 4), 2005/2006
  (``view1.png``, ``view5.png``, ``disp1.png``: at face value; ``--gt-scale`` for a copy stored
  scaled); 0 = unknown;
* Middlebury 2014/2021 and MiddEval3 (``im0.png``, ``im1.png``, ``disp0.pfm`` or
  ``disp0GT.pfm``: floats, inf = unknown; ``calib.txt``'s ``ndisp`` gives the Dmax hint and
  the pair's calibration):
  full, half or quarter size is whichever directory you point at (``trainingQ/``...);
* KITTI 2012 (``image_0``/``image_1``, ``disp_noc``/``disp_occ``, calibration ``calib/*.txt``'s
  P0/P1) and 2015 (``image_2``/``image_3``, ``disp_noc_0``/``disp_occ_0``, calibration
  ``calib_cam_to_cam/*.txt``'s P_rect_02/P_rect_03): the ``*_10.png`` frames, ground truth 16-bit
  PNG / 256, 0 = unknown (``noc``, non-occluded pixels, by default);
* a list file: one pair per line, ``left right [gt [gt_scale]]`` separated by commas or
  white space, paths relative to the file, ``#`` comments;
* sequences without ground truth: a directory with ``left/`` and ``right/`` frame
  directories, two frame directories, or two video files (frame i with frame i).

Colour images become luminance as everywhere in the host (:func:`~.images.load_image`).
Problems are reported per pair, never skipped silently: a pair without ground truth runs
(against the reference only) with a note; a pair whose files are missing, unreadable or of
different sizes fails when it is loaded, and the sweep reports that pair's tasks as failed.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bayesmachine.extras import optional

from .calib import StereoCalibration, bundled_calibration_path, read_calibration
from .images import Crop, bundled_pair, check_readable, crop_image, load_gt, load_image, opencv_quiet, to_gray

cv2 = optional("cv2", "OpenCV")

__all__ = [
    "PairSpec",
    "Dataset",
    "LAYOUTS",
    "VIDEO_SUFFIXES",
    "resolve_dataset",
    "bundled_spec",
    "files_spec",
    "load_pair",
    "load_calibration",
    "write_pfm",
    "write_png16",
]

LAYOUTS = ("middlebury", "middlebury2014", "kitti", "list", "frames", "video")
VIDEO_SUFFIXES = (".avi", ".mp4", ".mkv", ".mov", ".m4v", ".webm")
_IMAGE_SUFFIXES = (".png", ".ppm", ".pgm", ".pfm", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
BUNDLED = "bundled"


@dataclass(frozen=True)
class PairSpec:
    """One stereo pair by its paths (what a worker needs to load it).

    ``gt_scale``: the ground-truth file stores disparity x scale (None: as stored). ``frame``:
    left and right are video files and this is the frame index. ``dmax_hint``: the largest
    disparity the dataset says to expect (Middlebury ``ndisp`` - 1), if it says. ``calib``: the
    pair's calibration file (:func:`~.calib.read_calibration`; ``"bundled"``: the bundled pair's),
    ``calib_cameras`` the KITTI cameras it is for. ``gt_bits``: the depth the layout's ground-truth
    images have (KITTI: 16); another is refused when loading. ``error``: why the pair cannot be
    loaded (a directory that cannot be listed), raised by :func:`load_pair`, so that its tasks fail
    with it.
    """

    name: str
    left: str
    right: str
    gt: str | None = None
    gt_scale: float | None = None
    dmax_hint: int | None = None
    frame: int | None = None
    note: str | None = None
    calib: str | None = None
    calib_cameras: tuple[int, int] | None = None
    gt_bits: int | None = None
    error: str | None = None

    def to_dict(self) -> dict[str, object]:
        d: dict[str, object] = {"name": self.name, "left": self.left, "right": self.right, "gt": self.gt}
        for key in ("gt_scale", "dmax_hint", "frame", "note", "calib", "calib_cameras", "gt_bits", "error"):
            if getattr(self, key) is not None:
                d[key] = getattr(self, key)
        return d


@dataclass
class Dataset:
    """What :func:`resolve_dataset` found: the layout, the pairs in order, notes per pair, and the
    directories not searched (``skipped``: a link back to a directory searched already), each named."""

    path: str
    layout: str
    pairs: list[PairSpec] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    @property
    def notes(self) -> list[str]:
        return [f"{p.name}: {p.note}" for p in self.pairs if p.note]


def bundled_spec() -> PairSpec:
    """The bundled Middlebury 2014 Motorcycle pair (scikit-image), as a pair spec."""
    return PairSpec(name="motorcycle", left=BUNDLED, right=BUNDLED, gt=BUNDLED, calib=BUNDLED)


def files_spec(left: str, right: str, gt: str | None = None, gt_scale: float | None = None) -> PairSpec:
    """One pair given as files (``bayesmachine sweep LEFT RIGHT [--gt GT]``)."""
    return PairSpec(name=Path(left).stem, left=str(left), right=str(right), gt=gt, gt_scale=gt_scale)


# --- loading (on the worker) ------------------------------------------------------------------


def _open_video(path: Path | str) -> cv2.VideoCapture:
    """An opened capture of ``path``, or one clear error (not found, permission denied, not a video)."""
    check_readable(Path(path), "video file")
    with opencv_quiet():
        cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        cap.release()
        raise ValueError(f"cannot open {path} as a video")
    return cap


def _video_frame(path: str, index: int) -> np.ndarray:
    cap = _open_video(path)
    try:
        # Seek (OpenCV's FFmpeg back end decodes forward from the key frame before it); a back end
        # that cannot says so through the position, and then the frames are read up to it.
        skip = index
        if index and cap.set(cv2.CAP_PROP_POS_FRAMES, index) \
                and int(cap.get(cv2.CAP_PROP_POS_FRAMES)) == index:
            skip = 0
        elif index:
            cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
        frame = None
        for _ in range(skip + 1):
            ok, frame = cap.read()
            if not ok:
                raise ValueError(f"{path}: no frame {index} (the video ends earlier)")
    finally:
        cap.release()
    return to_gray(frame)


def load_pair(spec: PairSpec, crop: Crop | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Gray left, right and ground truth (float32, inf = unknown; None without) of ``spec``, cropped.

    Raises (ValueError / OSError naming the file) for a missing or unreadable file, left and
    right of different sizes, or ground truth of another size."""
    gt = None
    if spec.error is not None:
        raise ValueError(spec.error)
    if spec.left == BUNDLED:
        left, right, gt = bundled_pair()
    elif spec.frame is not None:
        left, right = _video_frame(spec.left, spec.frame), _video_frame(spec.right, spec.frame)
    else:
        left, right = load_image(spec.left), load_image(spec.right)
        if spec.gt is not None:
            gt = load_gt(spec.gt, scale=spec.gt_scale, bits=spec.gt_bits)
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in size: {left.shape[1]}x{left.shape[0]} vs "
                         f"{right.shape[1]}x{right.shape[0]}")
    if gt is not None and gt.shape != left.shape:
        raise ValueError(f"ground truth {gt.shape[1]}x{gt.shape[0]} differs in size from the images' "
                         f"{left.shape[1]}x{left.shape[0]}")
    left, right = crop_image(left, crop), crop_image(right, crop)
    if gt is not None:
        gt = crop_image(gt, crop)
    return np.ascontiguousarray(left), np.ascontiguousarray(right), gt


def load_calibration(spec: PairSpec) -> StereoCalibration | None:
    """The calibration of ``spec`` (None without one), checked against its images' size."""
    if spec.calib is None:
        return None
    path = bundled_calibration_path() if spec.calib == BUNDLED else spec.calib
    calib = read_calibration(path, spec.calib_cameras)
    left = load_pair(spec)[0]
    return calib.for_input(left.shape)


# --- writers (tests and users building small datasets) ---------------------------------------


def write_pfm(path: str | Path, disparity: np.ndarray) -> None:
    """Write a one-channel float32 PFM (Middlebury 2014's ``disp0.pfm``; inf = unknown)."""
    d = np.asarray(disparity, dtype="<f4")
    if d.ndim != 2:
        raise ValueError(f"a PFM disparity map is 2-D, got shape {d.shape}")
    h, w = d.shape
    with open(path, "wb") as f:
        f.write(f"Pf\n{w} {h}\n-1.0\n".encode("ascii"))  # negative scale: little-endian
        f.write(np.ascontiguousarray(d[::-1]).tobytes())  # PFM rows run bottom to top


def write_png16(path: str | Path, disparity: np.ndarray, scale: float = 256.0) -> None:
    """Write disparities as a 16-bit PNG storing round(d x ``scale``), 0 = unknown (KITTI's format)."""
    d = np.asarray(disparity, dtype=np.float64)
    known = np.isfinite(d)
    raw = np.where(known, np.round(np.where(known, d, 0.0) * scale), 0.0)
    if raw.max(initial=0) > 65535 or (raw < 0).any():
        raise ValueError("disparity x scale must fit 16 bits (0..65535)")
    if not cv2.imwrite(str(path), raw.astype(np.uint16)):
        raise OSError(f"cannot write {path}")


# --- resolving (on the client) ----------------------------------------------------------------


def _first(directory: Path, names: tuple[str, ...]) -> Path | None:
    for n in names:
        if (directory / n).is_file():
            return directory / n
    return None


def _ndisp(calib: Path) -> int | None:
    """``ndisp`` from a Middlebury ``calib.txt`` (None if absent or unreadable)."""
    try:
        text = calib.read_text(errors="replace")
    except OSError:
        return None
    m = re.search(r"^\s*ndisp\s*=\s*([0-9]+)", text, re.MULTILINE)
    return int(m.group(1)) if m else None


def _scene_pair(directory: Path, name: str, gt_scale: float | None) -> PairSpec | None:
    """The pair of a Middlebury scene directory, or None if it is not one."""
    # 2014/2021, MiddEval3
    left = _first(directory, ("im0.png",))
    right = directory / "im1.png"
    if left is not None:
        gt = _first(directory, ("disp0.pfm", "disp0GT.pfm"))
        ndisp = _ndisp(directory / "calib.txt")
        note = None if gt is not None else "no ground truth (disp0.pfm / disp0GT.pfm missing)"
        calib = directory / "calib.txt"
        return PairSpec(name, str(left), str(right), str(gt) if gt else None, gt_scale,
                        dmax_hint=ndisp - 1 if ndisp else None, note=note,
                        calib=str(calib) if calib.is_file() else None)
    # 2005/2006: view1/view5, disp1
    left = _first(directory, ("view1.png", "view1.ppm"))
    if left is not None:
        right = _first(directory, ("view5.png", "view5.ppm")) or directory / "view5.png"
        gt = _first(directory, ("disp1.png", "disp1.pgm"))
        note = None if gt is not None else "no ground truth (disp1.png missing)"
        return PairSpec(name, str(left), str(right), str(gt) if gt else None, gt_scale, note=note)
    # 2001 (.ppm/.pgm, x 8, Tsukuba x 16) and 2003 (.png, quarter size, x 4): im2/im6, disp2
    left = _first(directory, ("im2.png", "im2.ppm"))
    if left is not None:
        right = _first(directory, ("im6.png", "im6.ppm")) or directory / "im6.png"
        gt = _first(directory, ("disp2.png", "disp2.pgm"))
        default = 4.0 if left.suffix == ".png" else (16.0 if directory.name.lower() == "tsukuba" else 8.0)
        note = None if gt is not None else "no ground truth (disp2.png missing)"
        return PairSpec(name, str(left), str(right), str(gt) if gt else None,
                        gt_scale if gt_scale is not None else default, note=note)
    return None


_KITTI = (  # (left dir, right dir, ground-truth dirs: noc first, calibration dirs, their cameras)
    ("image_0", "image_1", ("disp_noc", "disp_occ"), ("calib",), (0, 1)),
    ("image_2", "image_3", ("disp_noc_0", "disp_occ_0"), ("calib_cam_to_cam", "calib"), (2, 3)),
)


def _kitti_pairs(directory: Path, prefix: str, gt_scale: float | None, occluded: bool) -> list[PairSpec]:
    found = [k for k in _KITTI if (directory / k[0]).is_dir() and (directory / k[1]).is_dir()]
    if not found:
        return []
    left_dir, right_dir, gt_dirs, calib_dirs, cameras = found[0]
    gt_dir = directory / gt_dirs[1 if occluded else 0]
    pairs = []
    for left in sorted((directory / left_dir).glob("*_10.png")):
        gt = gt_dir / left.name
        note = None if gt.is_file() else f"no ground truth ({gt_dir.name}/{left.name} missing)"
        frame = left.stem[: -len("_10")]  # calib files are named by the frame: 000000.txt
        calib = next((c for c in (directory / d / f"{frame}.txt" for d in calib_dirs) if c.is_file()), None)
        # 16-bit PNGs of disparity x 256; --gt-scale reads another file as the user says.
        pairs.append(PairSpec(f"{prefix}{left.stem}", str(left), str(directory / right_dir / left.name),
                              str(gt) if gt.is_file() else None, gt_scale if gt_scale is not None else 256.0,
                              note=note, calib=str(calib) if calib else None,
                              calib_cameras=cameras if calib else None,
                              gt_bits=16 if gt_scale is None else None))
    return pairs


def _frames(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.is_file() and p.suffix.lower() in _IMAGE_SUFFIXES)


def _frame_pairs(left_dir: Path, right_dir: Path, prefix: str = "") -> list[PairSpec]:
    """Frame i of one directory with frame i of the other (name order); an unmatched frame is a
    pair whose missing side is reported when it loads."""
    lefts, rights = _frames(left_dir), _frames(right_dir)
    n = max(len(lefts), len(rights))
    width = max(4, len(str(n)))
    pairs = []
    for i in range(n):
        left = str(lefts[i]) if i < len(lefts) else str(left_dir / f"(no frame {i}: {len(lefts)} frames)")
        right = (str(rights[i]) if i < len(rights)
                 else str(right_dir / f"(no frame {i}: {len(rights)} frames)"))
        pairs.append(PairSpec(f"{prefix}frame{i:0{width}d}", left, right,
                              note="sequence frame, no ground truth"))
    return pairs


def _video_frames(path: Path) -> int:
    try:
        cap = _open_video(path)
    except ValueError as exc:
        raise ValueError(f"--dataset: {exc}") from None
    try:
        n = 0
        while cap.grab():  # count by reading: a container's frame count may be missing or wrong
            n += 1
    finally:
        cap.release()
    return n


def _video_pairs(left: Path, right: Path) -> list[PairSpec]:
    nl, nr = _video_frames(left), _video_frames(right)
    n = max(nl, nr)
    width = max(4, len(str(n)))
    pairs = []
    for i in range(n):
        note = "video frame, no ground truth"
        if i >= min(nl, nr):
            note += f"; the {'right' if i >= nr else 'left'} video has only {min(nl, nr)} frames"
        pairs.append(PairSpec(f"frame{i:0{width}d}", str(left), str(right), frame=i, note=note))
    return pairs


def _strip_comment(line: str) -> str:
    """``line`` up to its first ``#`` outside double quotes (a quoted path may hold one)."""
    quoted = False
    for i, c in enumerate(line):
        if c == '"':
            quoted = not quoted
        elif c == "#" and not quoted:
            return line[:i]
    return line


def _split_line(line: str) -> list[str]:
    """The fields of a list line: comma-separated (CSV: an empty field stays in its place) or
    separated by white space; either way a field may be double-quoted."""
    if "," in line:
        return [c.strip() for c in next(csv.reader([line], skipinitialspace=True))]
    return [q if q else w for q, w in re.findall(r'"([^"]*)"|(\S+)', line)]


def _list_pairs(path: Path, gt_scale: float | None) -> list[PairSpec]:
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"--dataset {path}: not a text list of pairs (nor a directory, nor two "
                         "videos)") from None
    base = path.parent
    pairs: list[PairSpec] = []
    names: dict[str, int] = {}
    for number, raw in enumerate(lines, 1):
        line = _strip_comment(raw).strip()
        if not line:
            continue
        cols = _split_line(line)
        while len(cols) > 2 and cols[-1] == "":  # trailing empty fields: 'l,r,' or 'l,r,,'
            cols.pop()
        if number == 1 and cols and cols[0].lower() == "left":
            continue  # a CSV header
        if not 2 <= len(cols) <= 4 or not (cols[0] and cols[1]):
            raise ValueError(f"--dataset {path}, line {number}: expected 'left right [gt [gt_scale]]', "
                             f"got {len(cols)} fields" + ("" if len(cols) < 2 else f": {line!r}"))
        left, right = (str(base / c) for c in cols[:2])
        gt = str(base / cols[2]) if len(cols) > 2 and cols[2] else None
        scale = gt_scale
        if len(cols) == 4:
            try:
                scale = float(cols[3])
            except ValueError:
                scale = math.nan
            if not (math.isfinite(scale) and scale > 0):
                raise ValueError(f"--dataset {path}, line {number}: gt_scale must be a number > 0, "
                                 f"got {cols[3]!r}")
        stem = Path(cols[0]).stem
        names[stem] = names.get(stem, 0) + 1
        name = stem if names[stem] == 1 else f"{stem}~{names[stem]}"
        note = None if gt else "no ground truth given" + (f" (its gt_scale {cols[3]} scales nothing)"
                                                          if len(cols) == 4 else "")
        pairs.append(PairSpec(name, left, right, gt, scale if gt else None, note=note))
    if not pairs:
        raise ValueError(f"--dataset {path}: the list names no pair")
    return pairs


def resolve_dataset(paths: list[str] | tuple[str, ...], gt_scale: float | None = None,
                    occluded: bool = False) -> Dataset:
    """The pairs of the dataset at ``paths`` (one directory or list file; or two frame directories
    or two video files). ``gt_scale`` replaces the layout's ground-truth scale; ``occluded``: KITTI's
    ``disp_occ`` ground truth instead of ``disp_noc``. ValueError when nothing usable is found."""
    if not 1 <= len(paths) <= 2:
        raise ValueError(f"--dataset takes one path (a directory or a list file) or two (frame directories "
                         f"or videos), got {len(paths)}")
    ps = [Path(p) for p in paths]
    for p in ps:
        if not p.exists():
            raise FileNotFoundError(f"--dataset: {p} does not exist")
    shown = " ".join(paths)
    if len(ps) == 2:
        if all(p.is_dir() for p in ps):
            pairs = _frame_pairs(*ps)
            if not pairs:
                raise ValueError(f"--dataset {shown}: neither directory holds a frame (an image file: "
                                 f"{' '.join(_IMAGE_SUFFIXES)})")
            return Dataset(shown, "frames", pairs)
        if all(p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES for p in ps):
            pairs = _video_pairs(*ps)
            if not pairs:
                raise ValueError(f"--dataset {shown}: neither video holds a frame")
            return Dataset(shown, "video", pairs)
        raise ValueError(f"--dataset {shown}: two paths must be two frame directories or two video files "
                         f"({', '.join(VIDEO_SUFFIXES)})")
    root = ps[0]
    if root.is_file():
        return Dataset(shown, "list", _list_pairs(root, gt_scale))
    pairs: list[PairSpec] = []
    layouts: set[str] = set()
    skipped: list[str] = []
    for d, rel, subdirs, unlisted in _walk(root, skipped):
        prefix = "" if rel == "." else f"{rel}/"
        kitti = _kitti_pairs(d, prefix, gt_scale, occluded)
        if kitti:
            pairs += kitti
            layouts.add("kitti")
            subdirs.clear()  # its image_*/disp_* directories are not scenes
            continue
        if (d / "left").is_dir() and (d / "right").is_dir():
            pairs += _frame_pairs(d / "left", d / "right", prefix)
            layouts.add("frames")
            subdirs.clear()
            continue
        scene = _scene_pair(d, rel, gt_scale)
        if scene is not None:
            pairs.append(scene)
            layouts.add("middlebury2014" if Path(scene.left).name == "im0.png" else "middlebury")
            subdirs.clear()
        elif unlisted:  # not a scene by its file names, and what it holds cannot be seen: a failed pair
            pairs.append(PairSpec(rel, str(d), str(d), error=f"{d}: cannot list this directory ({unlisted}); "
                                  "it may hold a scene"))
    if not pairs:
        raise ValueError(
            f"--dataset {root}: no stereo pair found (looked for Middlebury scenes: im0/im1, view1/view5, "
            f"im2/im6; KITTI image_0/image_1 or image_2/image_3; left/ and right/ frame directories)"
        )
    if pairs[0].name == "." and len(pairs) == 1:
        pairs[0] = PairSpec(**{**pairs[0].__dict__, "name": root.resolve().name or "pair"})
    return Dataset(shown, "+".join(sorted(layouts)), pairs, skipped)


def _walk(root: Path, skipped: list[str]) -> Iterator[tuple[Path, str, list[str], str | None]]:
    """Every directory under ``root``, depth first in name order, as (path, name under root,
    subdirectory names: clear them to not descend, why it could not be listed or None). Symbolic
    links to directories are followed; a directory met again (a link back up: a loop, or a second
    link to one) is not searched twice and is named in ``skipped``."""
    seen: dict[str, str] = {}  # real path -> the name it was searched under
    stack = [(root, ".")]
    while stack:
        d, rel = stack.pop()
        real = os.path.realpath(d)
        if real in seen:
            first = seen[real]
            if first == "." or rel.startswith(f"{first}/"):
                where = "the dataset directory" if first == "." else first
                skipped.append(f"{rel}: a link back to {where} (a loop), not followed")
            else:
                skipped.append(f"{rel}: the same directory as {first}, searched once")
            continue
        seen[real] = rel
        try:
            with os.scandir(d) as entries:
                subdirs, unlisted = sorted(e.name for e in entries if e.is_dir()), None
        except OSError as exc:
            if rel == ".":
                raise OSError(exc.errno, f"cannot list the dataset directory ({exc.strerror})",
                              str(d)) from None
            subdirs, unlisted = [], exc.strerror or str(exc)
        yield d, rel, subdirs, unlisted
        stack.extend((d / n, n if rel == "." else f"{rel}/{n}") for n in reversed(subdirs))
