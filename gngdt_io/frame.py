"""In-memory RGB-D frame types shared by recording readers, writers and the capture service.

``CameraIntrinsics`` lives in :mod:`gngdt.core.sensor.geometry` and is re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics

__all__ = ["DEFAULT_FIXED_FRAME", "CameraIntrinsics", "CameraPose", "Frame"]


#: the fixed frame poses are given in when nothing names it (pose files, synthetic scenes)
DEFAULT_FIXED_FRAME = "world"


@dataclass(frozen=True)
class CameraPose:
    """Where the camera was when a frame was taken.

    matrix: (4, 4) float64 camera-to-world transform: it maps a point of the camera frame (x
    right, y down, z forward, metres) into the fixed frame ``frame_id`` (``world``, ``map``,
    ``odom``): ``p_world = matrix[:3, :3] @ p_camera + matrix[:3, 3]``.
    """

    matrix: np.ndarray
    frame_id: str = DEFAULT_FIXED_FRAME

    @property
    def position(self) -> np.ndarray:
        """(3,) float64 camera centre in the fixed frame, metres."""
        return self.matrix[:3, 3]


@dataclass
class Frame:
    """One RGB-D frame as numpy arrays.

    color: (H, W, 3) uint8 RGB. depth: (H, W) uint16 millimetres, 0 = no measurement.
    labels: (H, W) uint16 ground-truth segment ids (synthetic scenes only), 0 = background/none.
    pose: the camera's pose in a fixed frame, when the recording has one. pose_error: why a
    recording that has poses has none for this frame ("": it has one, or the recording none).
    color_path, depth_path: the image files of a frame read from a folder.
    extras: a source's own metadata, for people and evaluation (a RealSense's frame numbers, a
    synthetic scene's segment names); the pipeline never reads it.
    """

    index: int
    timestamp_ns: int
    color: np.ndarray
    depth: np.ndarray
    intrinsics: CameraIntrinsics
    labels: np.ndarray | None = None
    pose: CameraPose | None = None
    pose_error: str = ""
    color_path: Path | None = None
    depth_path: Path | None = None
    extras: dict[str, object] = field(default_factory=dict)
