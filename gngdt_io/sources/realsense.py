"""Intel RealSense as a frame source: a live device (``realsense:``, ``realsense:SERIAL``,
``realsense:SERIAL:848x480@30``) or a recording the SDK wrote (``.db3``, legacy ``.bag``), both
through one code path (`gngdt.io.realsense.stream.AlignedStream`): depth aligned to colour, the
colour stream's own intrinsics, the device's depth units turned into millimetres.

Needs the optional extra ``[realsense]`` (pyrealsense2, and on Linux the system library
libusb-1.0); without it, opening the source is a RecordingError saying what to install. A
device that is not there, a wrong serial or a recording that cannot be played fail when the
source is opened, before anything starts; a device lost mid-stream ends `frames` with a
DeviceLostError after the frames it delivered. Frame names: the 0-based index as 6 digits.
"""

from __future__ import annotations

import logging
import re
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt.io.errors import RecordingError
from gngdt.io.frame import Frame
from gngdt.io.realsense.files import convert_legacy_bag, file_kind, inspect_db3
from gngdt.io.realsense.sdk import RealSenseUnavailable, pyrealsense
from gngdt.io.realsense.stream import (
    UNIX_DOMAINS,
    AlignedFrame,
    AlignedStream,
    StreamMode,
    find_device,
)
from gngdt.io.sources.base import FrameSource, SourceOptions

if TYPE_CHECKING:
    from gngdt.core.sensor.depth import DepthRange

log = logging.getLogger(__name__)

SCHEME = "realsense"
_MODE = re.compile(r"^(\d+)x(\d+)(?:@(\d+))?$")


def parse_spec(spec: str) -> tuple[str | None, StreamMode]:
    """``(serial or None, mode)`` of ``realsense:[SERIAL][:WIDTHxHEIGHT[@FPS]]``; ValueError
    naming the spec otherwise."""
    scheme, _, rest = spec.partition(":")
    if scheme != SCHEME:
        raise ValueError(f"{spec}: not a RealSense spec (realsense:[SERIAL][:WxH[@FPS]])")
    serial, _, mode_text = rest.partition(":")
    mode = StreamMode()
    if mode_text:
        match = _MODE.match(mode_text)
        if match is None:
            raise ValueError(f"{spec}: the mode must read WIDTHxHEIGHT[@FPS], e.g. 848x480@30, "
                             f"got {mode_text!r}")
        width, height, fps = match.groups()
        mode = StreamMode(int(width), int(height), int(fps) if fps else mode.fps)
    return serial or None, mode


def live_spec(serial: str | None) -> str:
    """The spec of the device ``serial`` (None or ``""``: the only or first one)."""
    return f"{SCHEME}:{serial or ''}"


class RealSenseSource(FrameSource):
    """A RealSense device or recording (see the module's docstring).

    ``context``: the ``rs.context`` to use (default: a new one); ``frame_timeout_s``: longest
    wait for a frame before a device counts as lost (or a recording as stalled); ``strict``: a
    recording whose playback stops early (an undecodable image) raises, else it is warned
    about; ``convert_timeout_s``: limit of a legacy ``.bag``'s conversion.
    """

    format = "realsense"
    scheme = SCHEME
    suffixes = (".db3", ".bag")

    def __init__(self, source: str | Path, options: SourceOptions | None = None, *,
                 context: Any = None, frame_timeout_s: float = 5.0, strict: bool = True,
                 convert_timeout_s: float | None = None) -> None:
        options = options or SourceOptions()
        if options.camera_json is not None:
            raise ValueError("--camera-json applies to image folders; a RealSense device or "
                             "recording carries its calibration")
        try:
            self.rs = pyrealsense()
        except RealSenseUnavailable as error:
            raise RecordingError(source, None, str(error)) from None
        self.context = context if context is not None else self.rs.context()
        self.frame_timeout_s = frame_timeout_s
        self.strict = strict
        self.convert_timeout_s = convert_timeout_s
        self._kind = ""
        self._info = None
        self._converted: Path | None = None
        self._stream: AlignedStream | None = None
        if isinstance(source, str) and source.startswith(f"{SCHEME}:"):
            self.serial, self.mode = parse_spec(source)
            self.device = find_device(self.rs, self.context, self.serial,
                                      f"realsense {self.serial}" if self.serial else "realsense")
            self.live = True
            super().__init__(source, "the device's own calibration")
            return
        path = Path(source)
        if not path.is_file():
            raise RecordingError(path, None, "no such file")
        self._kind = file_kind(path)
        if not self._kind:
            raise RecordingError(path, None, "not a RealSense recording: neither a rosbag2 "
                                 ".db3 (SQLite) nor a legacy ROS 1 .bag")
        if self._kind == "db3":
            self._info = inspect_db3(path)
        super().__init__(path, "recording calibration")

    def describe(self) -> str:
        if self.live:
            return (f"RealSense {self.device['name']} {self.device['serial']} ({self.mode}, "
                    "depth aligned to colour)")
        if self._info is not None:
            return (f"{self.path} (RealSense recording: {self._info.color_frames} colour and "
                    f"{self._info.depth_frames} depth images)")
        return f"{self.path} (legacy RealSense .bag)"

    def check(self, depth: DepthRange | None = None) -> int:
        if self.live:
            raise RecordingError(self.path, None, "a live camera has no end to check: record "
                                 "it first (gngdt record realsense --out x.mcap --seconds 10)")
        return super().check(depth)

    def frames(self) -> Iterator[tuple[str, Frame]]:
        """The aligned frames; anything the SDK raises is the source's RecordingError (the
        stream names most; this is the net under the SDK calls it does not wrap)."""
        stream = self._open_stream()
        try:
            stream.open()
            for index, aligned in enumerate(stream.frames()):
                yield f"{index:06d}", self._frame(index, aligned)
        except RuntimeError as error:
            raise RecordingError(self.path, None, f"the RealSense SDK failed: {error}"
                                 ) from error
        finally:
            stream.close()
            self._stream = None

    def _open_stream(self) -> AlignedStream:
        if self.live:
            self._stream = AlignedStream(self.rs, self.context, name=str(self.path),
                                         serial=self.device["serial"], mode=self.mode,
                                         frame_timeout_s=self.frame_timeout_s)
            return self._stream
        recording = self.path
        if self._kind == "bag":
            recording = self._converted_bag()
            self._info = inspect_db3(recording)
        self._stream = AlignedStream(self.rs, self.context, name=str(self.path),
                                     recording=recording, info=self._info,
                                     frame_timeout_s=self.frame_timeout_s, strict=self.strict)
        return self._stream

    def _converted_bag(self) -> Path:
        """The legacy ``.bag`` as a ``.db3`` in a temporary folder (converted once)."""
        if self._converted is None:
            folder = Path(tempfile.mkdtemp(prefix="gngdt-realsense-"))
            converted = folder / f"{self.path.stem}.db3"
            try:
                convert_legacy_bag(self.path, converted, self.convert_timeout_s)
            except RecordingError:
                shutil.rmtree(folder, ignore_errors=True)
                raise
            self._converted = converted
        return self._converted

    def _frame(self, index: int, aligned: AlignedFrame) -> Frame:
        timestamp_ns = aligned.timestamp_ns
        if self.live and aligned.timestamp_domain not in UNIX_DOMAINS:
            timestamp_ns = time.time_ns()  # a device clock: the host's time of arrival
        return Frame(index=index, timestamp_ns=timestamp_ns, color=aligned.color,
                     depth=aligned.depth_mm, intrinsics=aligned.intrinsics,
                     extras={"frame_number": aligned.frame_number,
                             "depth_units_m": aligned.depth_units_m,
                             "timestamp_domain": aligned.timestamp_domain,
                             "distortion_model": aligned.distortion_model})

    def close(self) -> None:
        """Stop a running stream (from any thread: `frames` then ends) and remove the
        temporary conversion of a legacy ``.bag``."""
        stream = self._stream
        if stream is not None:
            stream.close()
        if self._converted is not None:
            shutil.rmtree(self._converted.parent, ignore_errors=True)
            self._converted = None
