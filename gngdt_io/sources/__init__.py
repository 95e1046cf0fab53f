"""Where frames come from, behind one interface (`base.FrameSource`): recordings (gngdt's MCAP
and ROS 2 bags; RealSense ``.db3``/``.bag``), folders of RGB-D images, synthetic scenes and live
RealSense cameras.

`open_source` picks the kind from the spec: a ``<scheme>:`` prefix names one (``synth:``,
``realsense:``), else a file whose suffix a kind claims (``.db3``), an MCAP file or a folder of
images (its layout detected, or ``fmt``). A new kind of source is one module with a
`FrameSource` subclass and one line in `SOURCE_TYPES`.
"""

from __future__ import annotations

from pathlib import Path

from gngdt.io.errors import RecordingError
from gngdt.io.images import FORMATS, detect_format
from gngdt.io.mcap.reader import check_recording
from gngdt.io.sources.base import FrameSource, SourceOptions
from gngdt.io.sources.folder import ImageFolderSource
from gngdt.io.sources.realsense import RealSenseSource
from gngdt.io.sources.recording import McapSource
from gngdt.io.sources.synthetic import SyntheticSource

__all__ = ["SOURCE_FORMATS", "SOURCE_TYPES", "FrameSource", "SourceOptions", "open_source"]

#: every kind of source: a scheme (``synth:``) or a detector of paths, and its constructor
SOURCE_TYPES: tuple[type[FrameSource], ...] = (SyntheticSource, RealSenseSource, McapSource,
                                               ImageFolderSource)
#: the names ``--format`` takes: a recording (MCAP, RealSense) or an image layout
SOURCE_FORMATS = ("mcap", "realsense", *FORMATS)


def open_source(spec: str | Path, fmt: str | None = None,
                options: SourceOptions | None = None) -> FrameSource:
    """The frame source ``spec`` names (kind detected unless ``fmt`` says). RecordingError
    naming the path when it is none of them; ValueError for options that do not apply."""
    options = options or SourceOptions()
    text = str(spec)
    if fmt is not None and fmt not in SOURCE_FORMATS:
        raise ValueError(f"format must be one of {SOURCE_FORMATS}, got {fmt!r}")
    scheme = text.split(":", 1)[0] if ":" in text else ""
    for kind in SOURCE_TYPES:
        if kind.scheme and kind.scheme == scheme:
            return kind(text)
    path = Path(spec)
    if not path.exists():
        raise RecordingError(path, None, "no such file or folder")
    if fmt in FORMATS or (fmt is None and path.is_dir()):
        return ImageFolderSource(path, fmt or _folder_layout(path), options)
    for kind in SOURCE_TYPES:
        if kind.suffixes and (fmt == kind.format
                              or (fmt is None and path.suffix.lower() in kind.suffixes)):
            return kind(path, options)
    check_recording(path)  # says why it is no recording: missing, empty, another kind of file
    return McapSource(path, options)


def _folder_layout(path: Path) -> str:
    """The image layout of a folder, or a RecordingError that also names recordings in it."""
    try:
        return detect_format(path)
    except RecordingError as error:
        inside = sorted(item.name for item in path.glob("*.mcap"))[:5]
        if not inside:
            raise
        raise RecordingError(path, None, f"{error.reason}; recordings inside: "
                             f"{', '.join(inside)}") from None
