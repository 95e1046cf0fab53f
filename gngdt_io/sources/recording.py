"""Recordings as frame sources: gngdt's MCAP layout and ROS 2 bags in MCAP
(`gngdt.io.mcap.reader`). Frame names: the 0-based frame index as 6 digits."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from gngdt.io.frame import Frame
from gngdt.io.mcap.reader import MCAP_MAGIC
from gngdt.io.sources.base import FrameSource, SourceOptions

#: schemas of the messages that calibrate a recording's camera
CALIBRATION_SCHEMAS = ("foxglove.CameraCalibration", "sensor_msgs/msg/CameraInfo")


class McapSource(FrameSource):
    """An MCAP recording (gngdt's layout or a ROS 2 bag)."""

    format = "mcap"

    def __init__(self, path: Path, options: SourceOptions) -> None:
        from gngdt.io.images import read_camera_json

        self.camera = None
        note = "recording calibration"
        if options.camera_json is not None:
            self.camera = read_camera_json(options.camera_json)  # fail now on a bad file
            note = f"{options.camera_json} (--camera-json, instead of the recording's)"
        super().__init__(path, note)
        self.options = options
        if self.camera is None:
            self._check_calibration()

    def _check_calibration(self) -> None:
        """A recording without a calibration channel cannot be deprojected: say so now, with
        the fix, rather than after its first frames (a damaged index: the reader will tell)."""
        from gngdt.io.errors import RecordingError
        from gngdt.io.mcap.reader import recording_info

        try:
            channels = recording_info(self.path)["channels"]
        except RecordingError:
            return
        if not any(channel["schema"] in CALIBRATION_SCHEMAS for channel in channels.values()):
            raise RecordingError(
                self.path, None, "no calibration channel (foxglove CameraCalibration or ROS "
                "CameraInfo) in the recording; give the camera's parameters with --camera-json "
                "FILE (a JSON object with fx, fy, cx, cy and, for 16-bit depth not in "
                "millimetres, depth_scale in units per metre)")

    @staticmethod
    def accepts(path: Path) -> bool:
        if not path.is_file():
            return False
        with open(path, "rb") as stream:
            return stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC

    def frames(self) -> Iterator[tuple[str, Frame]]:
        from gngdt.io.mcap.reader import read_frames

        options = self.options
        for frame in read_frames(self.path, options.topic_prefix,
                                 max_skew_ns=round(options.max_skew_ms * 1e6),
                                 on_bad_frame=options.on_bad_frame, limits=options.limits,
                                 fixed_frame=options.fixed_frame, camera=self.camera,
                                 depth_scale=options.depth_scale):
            yield f"{frame.index:06d}", frame

    def describe(self) -> str:
        from gngdt.io.mcap.reader import RecordingError, recording_info

        try:
            info = recording_info(self.path)
        except RecordingError:
            return f"{self.path} (no index: a damaged or unfinished file?)"
        return (f"{self.path}: {info['frames']} frames over {info['duration_s']:.1f} s, "
                f"{info['size_bytes'] / 1e6:.1f} MB")
