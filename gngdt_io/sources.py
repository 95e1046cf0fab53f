"""Frames of an MCAP recording or an RGB-D image folder, each with the name its outputs take.

A source is an MCAP file (gngdt's layout or a ROS 2 bag, :mod:`gngdt_io.mcap_reader`) or a
folder in a layout ``gngdt record images`` reads (:mod:`gngdt_io.images`: ``tum``,
``pcl-tiff``, ``redwood``; other files and folders in it, such as a labelled set's ``label/``,
are ignored). The layout is detected unless given. Frame names: the colour image's file stem for
a folder, the 0-based frame index as 6 digits for a recording.

A folder without ``camera.json`` (and no ``camera_json`` given) is read with its layout's
default intrinsics; that is warned about, naming the values assumed, and the source says so in
``camera_note``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from gngdt_io.errors import RecordingError
from gngdt_io.frame import Frame
from gngdt_io.images import DEFAULT_CAMERAS, FORMATS, iter_image_frames, load_camera
from gngdt_io.mcap_reader import MCAP_MAGIC

__all__ = ["SOURCE_FORMATS", "FrameSource", "detect_format", "open_source"]

logger = logging.getLogger(__name__)

#: source formats: an MCAP recording, or one of the image folder layouts
SOURCE_FORMATS = ("mcap", *FORMATS)


def detect_format(path: str | Path) -> str:
    """``"mcap"`` for an MCAP file, else the image layout of a folder; RecordingError naming the
    path when it is neither, or when several layouts match (then ``--format`` decides)."""
    path = Path(path)
    if path.is_file():
        with open(path, "rb") as stream:
            if stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC:
                return "mcap"
        raise RecordingError(path, None, "not an MCAP recording (no MCAP magic) nor a folder")
    if not path.is_dir():
        raise RecordingError(path, None, "no such file or folder")
    found = []
    if (path / "color").is_dir() or (path / "depth").is_dir():
        found.append("redwood")
    if (path / "rgb.txt").is_file() or (path / "depth.txt").is_file():
        found.append("tum")
    if any(path.glob("frame_*_rgb.tif*")) or any(path.glob("frame_*_depth.tif*")):
        found.append("pcl-tiff")
    if not found:
        raise RecordingError(
            path, None, "no known image layout (redwood: color/ + depth/; tum: rgb.txt + "
            "depth.txt; pcl-tiff: frame_*_rgb.tiff + frame_*_depth.tiff)")
    if len(found) > 1:
        raise RecordingError(
            path, None, f"the layout is ambiguous ({' and '.join(found)} both match); "
            "choose one with --format")
    return found[0]


@dataclass(frozen=True)
class FrameSource:
    """Where frames come from: ``path``, its ``format`` and where the intrinsics come from."""

    path: Path
    format: str
    #: ``"recording calibration"``, ``"<file>"`` or ``"ASSUMED: ..."`` (no camera.json)
    camera_note: str
    camera_json: Path | None = None

    @property
    def intrinsics_assumed(self) -> bool:
        return self.camera_note.startswith("ASSUMED")

    def frames(self) -> Iterator[tuple[str, Frame]]:
        """(name, frame) in order; RecordingError naming the file for a frame that cannot be
        read (after yielding the frames before it)."""
        if self.format == "mcap":
            from gngdt_io.mcap_reader import read_frames

            for frame in read_frames(self.path, fixed_frame=None):
                yield f"{frame.index:06d}", frame
            return
        camera = load_camera(self.path, self.format, self.camera_json)
        names: dict[str, str] = {}
        for frame in iter_image_frames(self.path, self.format, camera=camera):
            color_path = str(frame.extras["color_path"])
            name = Path(color_path).stem
            if name in names:
                raise RecordingError(color_path, frame.index,
                                     f"two colour images have the name {name!r} "
                                     f"(also {names[name]}); outputs would collide")
            names[name] = color_path
            yield name, frame

    def check(self) -> int:
        """Read every frame once (nothing kept) so that bad input fails before any work;
        returns the number of frames. RecordingError naming the file otherwise."""
        count = 0
        for _ in self.frames():
            count += 1
        if count == 0:
            raise RecordingError(self.path, None, "no frames")
        return count


def open_source(path: str | Path, fmt: str | None = None,
                camera_json: str | Path | None = None) -> FrameSource:
    """A `FrameSource` for ``path`` (format detected when ``fmt`` is None). Warns, naming the
    values, when a folder's intrinsics are assumed."""
    path = Path(path)
    fmt = fmt or detect_format(path)
    if fmt not in SOURCE_FORMATS:
        raise ValueError(f"format must be one of {SOURCE_FORMATS}, got {fmt!r}")
    if fmt == "mcap":
        if camera_json is not None:
            raise ValueError("--camera-json applies to image folders; a recording carries its "
                             "calibration")
        return FrameSource(path, fmt, "recording calibration")
    if camera_json is not None:
        load_camera(path, fmt, camera_json)  # fail now on a bad file
        return FrameSource(path, fmt, str(camera_json), Path(camera_json))
    if (path / "camera.json").is_file():
        load_camera(path, fmt)
        return FrameSource(path, fmt, str(path / "camera.json"))
    camera = DEFAULT_CAMERAS[fmt]
    note = (f"ASSUMED: {path / 'camera.json'} is missing, so the {fmt} defaults are used: "
            f"fx={camera.fx} fy={camera.fy} cx={camera.cx} cy={camera.cy} px, "
            f"depth_scale={camera.depth_scale:g} units/m. Wrong intrinsics bend every surface; "
            "add camera.json or pass --camera-json")
    logger.warning("%s", note)
    return FrameSource(path, fmt, note)
