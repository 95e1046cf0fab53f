"""The frame source interface: where frames come from, one frame at a time.

A source is a recording (gngdt's MCAP, a ROS 2 bag, a RealSense recording), a folder of RGB-D
images, a synthetic scene or a live camera (a RealSense). Capture publishes a source's frames;
``gngdt segment`` and evaluation segment them. Every frame carries its recorded time
(``Frame.timestamp_ns``): a replayed source is paced by capture at that rate, a live one
(``live``) paces itself.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from gngdt.io.errors import RecordingError
from gngdt.io.frame import Frame
from gngdt.io.mcap.limits import ReadLimits

if TYPE_CHECKING:
    from gngdt.core.sensor.depth import DepthRange

#: colour and depth of one frame may differ by this much in a ROS 2 bag (half a 60 Hz period;
#: gngdt's own recordings stamp both identically)
DEFAULT_MAX_SKEW_MS = 8.0
#: what a source does with a frame it cannot read (log it, and the source goes on); None: raise
BadFrameHandler = Callable[[Exception], None]


@dataclass(frozen=True)
class SourceOptions:
    """How to read a source; each source takes the options that apply to it."""

    #: camera parameters (JSON: fx, fy, cx, cy, depth_scale, ...) instead of a folder's
    #: camera.json or a recording's calibration (a bag without CameraInfo)
    camera_json: Path | None = None
    #: units per metre of the 16-bit depth images (1000: millimetres, 5000: TUM, 10000: 0.1 mm)
    #: instead of what the source says
    depth_scale: float | None = None
    #: recordings: read only the topics under this prefix (a bag with several cameras)
    topic_prefix: str | None = None
    #: recordings: largest stamp difference between a frame's colour and depth images
    max_skew_ms: float = DEFAULT_MAX_SKEW_MS
    #: recordings: fixed frame of the camera poses ("auto": world, map or odom; None: ignore)
    fixed_frame: str | None = None
    #: recordings: reading limits (image size, chunk size, pending bytes, transforms)
    limits: ReadLimits = field(default_factory=ReadLimits)
    #: called with a bad frame's error, which is then skipped (None: raise it)
    on_bad_frame: BadFrameHandler | None = None

    def __post_init__(self) -> None:
        scale = self.depth_scale
        if scale is not None and not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"--depth-scale must be a positive number of units per metre, "
                             f"got {scale}")


class FrameSource(ABC):
    """Frames from one place, each with the name its outputs take."""

    #: a short name of the kind of source ("mcap", "redwood", "synth", ...)
    format: str = ""
    #: a live source paces itself (a camera); replayed ones are paced by their stamps
    live: bool = False
    #: a spec ``<scheme>:...`` names this kind of source (synthetic scenes, live cameras)
    scheme: str = ""
    #: a file with one of these suffixes is this kind of source (``.db3``, ``.bag``)
    suffixes: tuple[str, ...] = ()

    def __init__(self, path: Path | str, camera_note: str) -> None:
        self.path = Path(path) if not isinstance(path, Path) else path
        #: where the intrinsics come from (``"ASSUMED: ..."`` when they are guessed)
        self.camera_note = camera_note
        #: camera parameters nothing gave, each a sentence naming the file or option that sets
        #: them (`gngdt run`'s summary and `gngdt segment` warn with them)
        self.assumptions: list[str] = []

    @property
    def intrinsics_assumed(self) -> bool:
        return self.camera_note.startswith("ASSUMED")

    @abstractmethod
    def frames(self) -> Iterator[tuple[str, Frame]]:
        """(name, frame) in order; RecordingError naming the file for a frame that cannot be
        read (after yielding the frames before it)."""

    def describe(self) -> str:
        """One line for people: what is read."""
        return f"{self.path} ({self.format})"

    def check(self, depth: DepthRange | None = None) -> int:
        """Read every frame once (nothing kept; their depth added to ``depth`` when given) so
        that bad input fails before any work; returns the number of frames. RecordingError
        naming the file otherwise."""
        count = 0
        for _, frame in self.frames():
            count += 1
            if depth is not None:
                depth.add(frame.depth)
        if count == 0:
            raise RecordingError(self.path, None, "no frames")
        return count

    def close(self) -> None:
        """Release what the source holds (a device, a file)."""
        return None
