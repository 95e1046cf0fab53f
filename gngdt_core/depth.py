"""Depth images: which pixels to trust, and a deprojected cloud put back on its pixels."""

from __future__ import annotations

import numpy as np


def veil_pixels(depth: np.ndarray, ratio: float) -> np.ndarray:
    """(H, W) bool: pixels whose depth jumps from a 4-neighbour's by more than ``ratio`` of the
    nearer depth — the mixed foreground/background measurements along depth edges ("veil"
    points), which would otherwise bridge an object and what lies behind it.

    depth: (H, W) float or integer depth, any unit; 0 or NaN = no measurement (never a veil).
    """
    from gngdt_core.kernels import segmentation as SK  # numba: loaded when first used

    veil = np.empty(depth.shape, dtype=bool)
    if depth.dtype not in (np.float32, np.float64):
        depth = depth.astype(np.float32)
    SK.veil_pixels(depth, float(ratio), veil)
    return veil


def organize(points: np.ndarray, colors: np.ndarray | None, width: int, height: int,
             fx: float, fy: float, cx: float, cy: float
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """An organized cloud back from a deprojected one (e.g. for `gngdt_core.odometry`).

    points: (N, 3) camera frame (x right, y down, z forward), metres, as a depth image's valid
    pixels deprojected with the pinhole ``fx, fy, cx, cy`` (the learner's ``points`` topic with
    its calibration); colors: (N, 3) uint8 or None. Each point goes back to the pixel it came
    from. Returns (height, width, 3) float32 points, NaN where no point lands, and the colours
    there (zero elsewhere) or None. Points behind the camera or off the image are dropped.
    """
    from gngdt_core.kernels import odometry as OK  # numba: loaded when first used

    points = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
    organized = np.full((height, width, 3), np.nan, dtype=np.float32)
    image = np.zeros((height, width, 3), dtype=np.uint8)
    pixels = (np.zeros((0, 3), dtype=np.uint8) if colors is None
              else np.ascontiguousarray(np.asarray(colors, dtype=np.uint8).reshape(-1, 3)))
    OK.organize_points(points, pixels, float(fx), float(fy), float(cx), float(cy), organized,
                       image)
    return organized, None if colors is None else image
