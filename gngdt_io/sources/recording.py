"""Recordings as frame sources: gngdt's MCAP layout and ROS 2 bags in MCAP
(`gngdt_io.mcap_reader`). Frame names: the 0-based frame index as 6 digits."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from gngdt_io.frame import Frame
from gngdt_io.mcap_reader import MCAP_MAGIC
from gngdt_io.sources.base import FrameSource, SourceOptions


class McapSource(FrameSource):
    """An MCAP recording (gngdt's layout or a ROS 2 bag)."""

    format = "mcap"

    def __init__(self, path: Path, options: SourceOptions) -> None:
        if options.camera_json is not None:
            raise ValueError("--camera-json applies to image folders; a recording carries its "
                             "calibration")
        super().__init__(path, "recording calibration")
        self.options = options

    @staticmethod
    def accepts(path: Path) -> bool:
        if not path.is_file():
            return False
        with open(path, "rb") as stream:
            return stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC

    def frames(self) -> Iterator[tuple[str, Frame]]:
        from gngdt_io.mcap_reader import read_frames

        options = self.options
        for frame in read_frames(self.path, options.topic_prefix,
                                 max_skew_ns=round(options.max_skew_ms * 1e6),
                                 on_bad_frame=options.on_bad_frame, limits=options.limits,
                                 fixed_frame=options.fixed_frame):
            yield f"{frame.index:06d}", frame

    def describe(self) -> str:
        from gngdt_io.mcap_reader import RecordingError, recording_info

        try:
            info = recording_info(self.path)
        except RecordingError:
            return f"{self.path} (no index: a damaged or unfinished file?)"
        return (f"{self.path}: {info['frames']} frames over {info['duration_s']:.1f} s, "
                f"{info['size_bytes'] / 1e6:.1f} MB")
