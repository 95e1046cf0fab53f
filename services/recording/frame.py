"""In-memory RGB-D frame types shared by recording readers, writers and the capture service."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a colour-registered depth camera (pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    #: plumb_bob coefficients k1, k2, p1, p2, k3 (informational; depth is not undistorted)
    distortion: tuple[float, ...] = ()

    def matrix(self) -> np.ndarray:
        """(3, 3) float64 camera matrix K."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )


@dataclass
class Frame:
    """One RGB-D frame as numpy arrays.

    color: (H, W, 3) uint8 RGB. depth: (H, W) uint16 millimetres, 0 = no measurement.
    labels: (H, W) uint16 ground-truth segment ids (synthetic scenes only), 0 = background/none.
    """

    index: int
    timestamp_ns: int
    color: np.ndarray
    depth: np.ndarray
    intrinsics: CameraIntrinsics
    labels: np.ndarray | None = None
    extras: dict[str, object] = field(default_factory=dict)
