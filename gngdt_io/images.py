"""Import real RGB-D frames from image folders: TUM RGB-D, PCL ImageGrabber TIFFs, Redwood/Open3D.

Layouts (``fmt``):

- ``tum``: ``rgb.txt`` and ``depth.txt`` (``timestamp path`` per line, ``#`` comments), images
  paired by nearest timestamp within ``TUM_MAX_DIFFERENCE_S`` (TUM's ``associate.py``); unpaired
  images are skipped. Depth 5000 units per metre; intrinsics default to TUM freiburg1.
- ``pcl-tiff``: ``frame_<YYYYmmddTHHMMSS.ffffff>_rgb.tiff`` + ``frame_<same>_depth.tiff``, depth in
  millimetres, timestamps from the names (taken as UTC).
- ``redwood``: ``color/NNNNNN.{png,jpg}`` + ``depth/NNNNNN.png`` paired by name, depth in
  millimetres, frames ``1/fps`` apart.

A ``camera.json`` in the folder (``fx, fy, cx, cy, width, height, depth_scale`` and optionally
``distortion_k1_k2_p1_p2_k3``) overrides the format's defaults. Depth is converted to uint16
millimetres; colour is (H, W, 3) uint8 RGB.
"""

from __future__ import annotations

import json
import logging
import math
import re
from bisect import bisect_left
from collections.abc import Iterator
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from gngdt.io.errors import RecordingError
from gngdt.io.frame import CameraIntrinsics, Frame
from gngdt.io.image_files import check_depth_dtype, is_regular_file, read_image

__all__ = ["FORMATS", "CameraParameters", "camera_assumptions", "count_image_frames",
           "iter_image_frames", "load_camera"]

logger = logging.getLogger(__name__)

FORMATS = ("tum", "pcl-tiff", "redwood")
TUM_MAX_DIFFERENCE_S = 0.02
MILLIMETRES_PER_METRE = 1000.0
_PCL_NAME = re.compile(r"^frame_(?P<stamp>\d{8}T\d{6}(?:\.\d+)?)_(?P<kind>rgb|depth)\.tiff?$")


@dataclass(frozen=True)
class CameraParameters:
    """Pinhole intrinsics (pixels) and depth units per metre; width/height None: from the images."""

    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float
    distortion: tuple[float, ...] = ()
    width: int | None = None
    height: int | None = None
    #: the image size fx, fy, cx, cy are for when they are a format's defaults (assumed):
    #: images of another size get them scaled (a 320x240 Kinect image is the 640x480 one halved)
    scaled_from: tuple[int, int] | None = None

    def intrinsics(self, width: int, height: int) -> CameraIntrinsics:
        """The camera's intrinsics for images of ``width`` x ``height``; ValueError saying why
        when they cannot be a camera's (`CameraIntrinsics.problem`: sizes that differ from
        the images', an implausible field of view, a principal point far off the image)."""
        scale_x, scale_y = 1.0, 1.0
        if self.scaled_from is not None:
            scale_x, scale_y = width / self.scaled_from[0], height / self.scaled_from[1]
        intrinsics = CameraIntrinsics(
            width=self.width or width,
            height=self.height or height,
            fx=self.fx * scale_x,
            fy=self.fy * scale_y,
            cx=self.cx * scale_x,
            cy=self.cy * scale_y,
            distortion=self.distortion,
        )
        problem = intrinsics.problem((width, height))
        if problem:
            raise ValueError(problem)
        return intrinsics

    def problem(self) -> str:
        """Why these parameters cannot be a camera's (not finite, not positive; with width and
        height, anything `CameraIntrinsics.problem` refuses), or ""."""
        values = (self.fx, self.fy, self.cx, self.cy, self.depth_scale, *self.distortion)
        if not all(math.isfinite(value) for value in values):
            return "fx, fy, cx, cy, depth_scale and the distortion must be finite numbers"
        if min(self.fx, self.fy, self.depth_scale) <= 0:
            return "fx, fy and depth_scale must be positive"
        if any(size is not None and size <= 0 for size in (self.width, self.height)):
            return "width and height must be positive"
        if self.width is not None and self.height is not None:
            try:
                self.intrinsics(self.width, self.height)
            except ValueError as error:
                return str(error)
        return ""


#: Defaults per format: TUM freiburg1 (the TUM benchmark's published calibration) and the
#: PrimeSense/Kinect v1 defaults used by PCL's OpenNI grabber and by Open3D's Redwood loaders.
#: Both are for 640x480 images, and scaled to images of another size.
DEFAULT_CAMERAS: dict[str, CameraParameters] = {
    "tum": CameraParameters(
        fx=517.3,
        fy=516.5,
        cx=318.6,
        cy=255.3,
        depth_scale=5000.0,
        distortion=(0.2624, -0.9531, -0.0054, 0.0026, 1.1633),
        scaled_from=(640, 480),
    ),
    "pcl-tiff": CameraParameters(fx=525.0, fy=525.0, cx=320.0, cy=240.0, depth_scale=1000.0,
                                 scaled_from=(640, 480)),
    "redwood": CameraParameters(fx=525.0, fy=525.0, cx=319.5, cy=239.5, depth_scale=1000.0,
                                scaled_from=(640, 480)),
}


def detect_format(directory: str | Path) -> str:
    """The layout of an image folder: ``tum`` (rgb.txt + depth.txt), ``pcl-tiff``
    (``frame_*_rgb.tiff`` + ``frame_*_depth.tiff``) or ``redwood`` (color/ + depth/).
    RecordingError naming the folder when it is none of them, or several (``--format`` decides).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordingError(directory, None, "not a directory")
    found = []
    if (directory / "color").is_dir() and (directory / "depth").is_dir():
        found.append("redwood")
    if (directory / "rgb.txt").is_file() and (directory / "depth.txt").is_file():
        found.append("tum")
    if any(_PCL_NAME.match(path.name) for path in directory.iterdir()):
        found.append("pcl-tiff")
    if not found:
        raise RecordingError(
            directory, None, "no known image layout (redwood: color/ + depth/; tum: rgb.txt + "
            "depth.txt; pcl-tiff: frame_*_rgb.tiff + frame_*_depth.tiff)")
    if len(found) > 1:
        raise RecordingError(directory, None, f"the layout is ambiguous ({' and '.join(found)} "
                             "both match); choose one with --format")
    return found[0]


def _check_format(fmt: str) -> None:
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {FORMATS}, got {fmt!r}")


def load_camera(
    directory: str | Path, fmt: str, camera_json: str | Path | None = None
) -> CameraParameters:
    """Camera parameters: ``camera_json`` if given, else ``DIR/camera.json`` if present, else the
    format's defaults (keys missing from the JSON keep the defaults)."""
    _check_format(fmt)
    defaults = DEFAULT_CAMERAS[fmt]
    path = Path(camera_json) if camera_json is not None else Path(directory) / "camera.json"
    if camera_json is None and not path.is_file():
        return defaults
    values = _camera_values(path)
    if {"fx", "fy", "cx", "cy"} & values.keys():  # the file's pixels, not the defaults'
        values["scaled_from"] = None
    return _checked(path, replace(defaults, **values))


#: each layout's own depth units, said beside an assumed depth_scale
_LAYOUT_DEPTH_UNITS = "TUM's frames use 5000, most others 1000: millimetres"


def camera_assumptions(directory: str | Path, fmt: str, camera_json: str | Path | None = None,
                       depth_scale: float | None = None) -> list[str]:
    """The camera parameters a folder of frames is read with that nothing gave (the layout's
    defaults), one sentence each naming the file or option that sets them; [] when
    ``camera_json`` (else ``DIR/camera.json``) and ``depth_scale`` give them all."""
    _check_format(fmt)
    defaults = DEFAULT_CAMERAS[fmt]
    path = Path(camera_json) if camera_json is not None else Path(directory) / "camera.json"
    given = _camera_values(path) if camera_json is not None or path.is_file() else {}
    found = []
    missing = [key for key in ("fx", "fy", "cx", "cy") if key not in given]
    if missing:
        values = " ".join(f"{key}={getattr(defaults, key):g}" for key in missing)
        found.append(f"{values} px assumed, the {fmt} layout's defaults ({path} "
                     f"{'lacks them' if given else 'is missing'}): wrong intrinsics bend every "
                     f"surface; add them to {path.name} or pass --camera-json FILE")
    if "depth_scale" not in given and depth_scale is None:
        found.append(f"depth_scale={defaults.depth_scale:g} units per metre assumed, the {fmt} "
                     f"layout's default ({_LAYOUT_DEPTH_UNITS}): wrong units scale every "
                     f"distance; set depth_scale in {path.name} or pass --depth-scale")
    return found


#: the depth units of a recording's 16-bit depth when nothing says otherwise (millimetres)
RECORDING_DEPTH_SCALE = MILLIMETRES_PER_METRE


def read_camera_json(path: str | Path) -> CameraParameters:
    """Camera parameters for a recording (`--camera-json`): fx, fy, cx, cy required; depth_scale
    (16-bit depth units per metre) defaults to millimetres; width/height, when given, are
    checked against the images. RecordingError naming the file for anything wrong."""
    path = Path(path)
    values = _camera_values(path)
    missing = [key for key in ("fx", "fy", "cx", "cy") if key not in values]
    if missing:
        raise RecordingError(path, None, f"camera parameters lack {', '.join(missing)}")
    return _checked(path, CameraParameters(**{"depth_scale": RECORDING_DEPTH_SCALE, **values}))


def _camera_values(path: Path) -> dict:
    """The camera parameters a JSON file sets (numbers; `_checked` judges the camera)."""
    try:
        values = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise RecordingError(path, None, f"cannot read camera parameters: {error}") from error
    if not isinstance(values, dict):
        raise RecordingError(path, None, "camera parameters must be a JSON object")
    try:
        found = {key: float(values[key]) for key in ("fx", "fy", "cx", "cy", "depth_scale")
                 if key in values}
        found.update({key: int(values[key]) for key in ("width", "height") if key in values})
        if "distortion_k1_k2_p1_p2_k3" in values:
            found["distortion"] = tuple(float(v) for v in values["distortion_k1_k2_p1_p2_k3"])
    except (TypeError, ValueError) as error:
        raise RecordingError(path, None, f"invalid camera parameter: {error}") from error
    return found


def _checked(path: Path, camera: CameraParameters) -> CameraParameters:
    """``camera`` when it can be a camera's, else RecordingError naming ``path`` and why."""
    if camera.problem():
        raise RecordingError(path, None, camera.problem())
    return camera


# ------------------------------------------------------------------------------------ pairing
@dataclass(frozen=True)
class _ImagePair:
    timestamp_ns: int
    color: Path
    depth: Path


def _seconds_to_ns(text: str) -> int:
    """Nanoseconds of a stamp in seconds; InvalidOperation unless finite, >= 0, below 2**63 ns."""
    nanoseconds = Decimal(text) * 1_000_000_000
    if not nanoseconds.is_finite() or not 0 <= nanoseconds < 2**63:
        raise InvalidOperation(f"stamp {text!r} is not a finite time >= 0 in seconds")
    return int(nanoseconds)


def _read_tum_list(path: Path) -> list[tuple[int, Path]]:
    """(timestamp_ns, image path) of a TUM rgb.txt/depth.txt, in file order."""
    if not path.is_file():
        raise RecordingError(path, None, "missing (a TUM folder has rgb.txt and depth.txt)")
    entries = []
    for line_number, line in enumerate(path.read_text().splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        try:
            if len(parts) < 2:
                raise InvalidOperation
            entries.append((_seconds_to_ns(parts[0]), path.parent / parts[1]))
        except InvalidOperation as error:
            raise RecordingError(
                path, None, f"line {line_number}: expected 'timestamp filename', got {line!r}"
            ) from error
    return entries


def associate(first: list[int], second: list[int], max_difference: int) -> list[tuple[int, int]]:
    """Index pairs (i, j) of two stamp lists as TUM's ``associate.py`` pairs them: every pair
    closer than ``max_difference`` is a candidate, the closest pairs are taken first, and each
    stamp is used at most once. Sorted by ``i``.

    first, second: stamps (any integer unit, e.g. ns); ``second`` sorted ascending.
    """
    candidates = []
    for i, stamp in enumerate(first):
        j = bisect_left(second, stamp - max_difference + 1)
        while j < len(second) and second[j] < stamp + max_difference:
            candidates.append((abs(second[j] - stamp), i, j))
            j += 1
    candidates.sort()
    used_first, used_second, pairs = set(), set(), []
    for _, i, j in candidates:
        if i not in used_first and j not in used_second:
            used_first.add(i)
            used_second.add(j)
            pairs.append((i, j))
    return sorted(pairs)


def _pairs_tum(directory: Path) -> list[_ImagePair]:
    """Colour and depth images of a TUM folder paired by `associate`; unpaired colour images
    are dropped (said once, by `iter_image_frames`)."""
    colors = sorted(_read_tum_list(directory / "rgb.txt"))
    depths = sorted(_read_tum_list(directory / "depth.txt"))
    pairs = associate([stamp for stamp, _ in colors], [stamp for stamp, _ in depths],
                      round(TUM_MAX_DIFFERENCE_S * 1e9))
    return [_ImagePair(colors[i][0], colors[i][1], depths[j][1]) for i, j in pairs]


def _unpaired_note(directory: Path, fmt: str, pairs: list[_ImagePair]) -> str:
    """What `_pairs_tum` left out, for people (``""``: nothing)."""
    if fmt != "tum":
        return ""
    colors = len(_read_tum_list(directory / "rgb.txt"))
    depths = len(_read_tum_list(directory / "depth.txt"))
    if len(pairs) == colors:
        return ""
    return (f"{directory}: {colors - len(pairs)} of {colors} colour images have no depth image "
            f"of their own within {TUM_MAX_DIFFERENCE_S * 1e3:.0f} ms ({depths} depth images; "
            "closest pairs first, each image used once, as TUM's associate.py); left out")


def _pairs_pcl_tiff(directory: Path) -> list[_ImagePair]:
    found: dict[str, dict[str, Path]] = {}
    for path in directory.iterdir():
        match = _PCL_NAME.match(path.name)
        if match and is_regular_file(path):
            found.setdefault(match["stamp"], {})[match["kind"]] = path
    pairs = []
    for stamp, kinds in sorted(found.items()):
        for kind, partner in (("rgb", "depth"), ("depth", "rgb")):
            if partner not in kinds:
                raise RecordingError(kinds[kind], None, f"no matching *_{partner}.tiff")
        moment = datetime.strptime(stamp, "%Y%m%dT%H%M%S.%f" if "." in stamp else "%Y%m%dT%H%M%S")
        timestamp_ns = (
            int(moment.replace(microsecond=0, tzinfo=UTC).timestamp()) * 1_000_000_000
            + moment.microsecond * 1000
        )
        pairs.append(_ImagePair(timestamp_ns, kinds["rgb"], kinds["depth"]))
    return pairs


def _pairs_redwood(directory: Path, fps: float) -> list[_ImagePair]:
    color_dir, depth_dir = directory / "color", directory / "depth"
    for folder in (color_dir, depth_dir):
        if not folder.is_dir():
            raise RecordingError(folder, None, "missing (redwood layout: color/ and depth/)")
    colors = {p.stem: p for p in color_dir.iterdir()
              if p.suffix.lower() in (".png", ".jpg", ".jpeg") and is_regular_file(p)}
    depths = {p.stem: p for p in depth_dir.iterdir()
              if p.suffix.lower() == ".png" and is_regular_file(p)}
    for name in sorted(colors.keys() ^ depths.keys()):
        lone = colors.get(name) or depths[name]
        raise RecordingError(
            lone, None, f"no matching {'depth' if name in colors else 'colour'} image"
        )
    period_ns = 1e9 / fps
    return [
        _ImagePair(round(index * period_ns), colors[name], depths[name])
        for index, name in enumerate(sorted(colors))
    ]


# ------------------------------------------------------------------------------------- loading
def _load_color(path: Path, index: int) -> np.ndarray:
    import cv2

    image = read_image(path, index, cv2.IMREAD_COLOR, "colour image")
    return image[..., ::-1].copy()


def _load_depth_mm(path: Path, index: int, depth_scale: float) -> np.ndarray:
    import cv2

    depth = read_image(path, index, cv2.IMREAD_UNCHANGED, "depth image")
    check_depth_dtype(depth, path, index)
    if depth_scale == MILLIMETRES_PER_METRE:
        return depth
    millimetres = np.nan_to_num(depth.astype(np.float64) * (MILLIMETRES_PER_METRE / depth_scale))
    return np.clip(np.rint(millimetres), 0, np.iinfo(np.uint16).max).astype(np.uint16)


def _image_pairs(directory: Path, fmt: str, fps: float) -> list[_ImagePair]:
    if fmt == "tum":
        pairs = _pairs_tum(directory)
    elif fmt == "pcl-tiff":
        pairs = _pairs_pcl_tiff(directory)
    else:
        pairs = _pairs_redwood(directory, fps)
    if not pairs:
        raise RecordingError(directory, None, f"no {fmt} colour/depth image pairs found")
    return pairs


def count_image_frames(directory: str | Path, fmt: str, fps: float = 30.0) -> int:
    """How many frames :func:`iter_image_frames` will yield (pairs the images, reads none)."""
    _check_format(fmt)
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordingError(directory, None, "not a directory")
    return len(_image_pairs(directory, fmt, fps))


def iter_image_frames(
    directory: str | Path,
    fmt: str,
    intrinsics: CameraIntrinsics | None = None,
    depth_scale: float | None = None,
    fps: float = 30.0,
    *,
    camera: CameraParameters | None = None,
) -> Iterator[Frame]:
    """Yield the frames of an image folder in time order.

    intrinsics: overrides the camera (its size must match the images). depth_scale: depth units
    per metre (1000 = millimetres, 5000 = TUM). camera: full parameters, instead of
    :func:`load_camera`'s. fps: frame rate for layouts without timestamps (redwood).
    Raises RecordingError naming the file for missing, unpaired or unreadable images.
    """
    _check_format(fmt)
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordingError(directory, None, "not a directory")
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    camera = camera or load_camera(directory, fmt)
    if depth_scale is not None:
        if depth_scale <= 0:
            raise ValueError(f"depth_scale must be positive, got {depth_scale}")
        camera = replace(camera, depth_scale=float(depth_scale))
    pairs = _image_pairs(directory, fmt, fps)
    note = _unpaired_note(directory, fmt, pairs)
    if note:
        logger.warning("%s", note)
    for index, pair in enumerate(pairs):
        color = _load_color(pair.color, index)
        depth = _load_depth_mm(pair.depth, index, camera.depth_scale)
        height, width = color.shape[:2]
        if depth.shape != (height, width):
            raise RecordingError(
                pair.depth,
                index,
                f"depth {depth.shape[1]}x{depth.shape[0]} does not match colour {width}x{height}",
            )
        problem = ""
        if intrinsics is not None:
            frame_intrinsics, problem = intrinsics, intrinsics.problem((width, height))
        else:
            try:
                frame_intrinsics = camera.intrinsics(width, height)
            except ValueError as error:
                problem = str(error)
        if problem:
            raise RecordingError(pair.color, index, f"camera parameters refused: {problem}")
        yield Frame(
            index=index,
            timestamp_ns=pair.timestamp_ns,
            color=color,
            depth=depth,
            intrinsics=frame_intrinsics,
            color_path=Path(pair.color),
            depth_path=Path(pair.depth),
        )
