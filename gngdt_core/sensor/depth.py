"""Depth images: which pixels to trust, whether a stream's depth is plausible at all, and a
deprojected cloud put back on its pixels."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def veil_pixels(depth: np.ndarray, ratio: float) -> np.ndarray:
    """(H, W) bool: pixels whose depth jumps from a 4-neighbour's by more than ``ratio`` of the
    nearer depth — the mixed foreground/background measurements along depth edges ("veil"
    points), which would otherwise bridge an object and what lies behind it.

    depth: (H, W) float or integer depth, any unit; 0 or NaN = no measurement (never a veil).
    """
    from gngdt.core.kernels import segmentation as SK  # numba: loaded when first used

    veil = np.empty(depth.shape, dtype=bool)
    if depth.dtype not in (np.float32, np.float64):
        depth = depth.astype(np.float32)
    SK.veil_pixels(depth, float(ratio), veil)
    return veil


#: depth a real RGB-D frame has for its median valid pixel, metres; outside it, the depth is
#: almost surely in another unit than the one it was read in (metres stored as millimetres
#: give ~0.001 m, millimetres read as metres ~1000 m)
PLAUSIBLE_MEDIAN_DEPTH_M = (0.1, 20.0)


class DepthRange:
    """The depth a stream of frames holds, frame by frame: how many frames had any, the
    nearest and farthest (1st/99th percentiles of each frame) and the median of the frames'
    median depths, metres."""

    def __init__(self) -> None:
        self.frames = 0
        self.frames_with_depth = 0
        self.near_m = math.inf
        self.far_m = 0.0
        self._medians: list[float] = []

    def add(self, depth_mm: np.ndarray) -> None:
        """One frame's depth: (H, W) uint16 millimetres, 0 = no measurement."""
        self.frames += 1
        valid = depth_mm[depth_mm > 0]
        if valid.size == 0:
            return
        self.frames_with_depth += 1
        low, median, high = np.percentile(valid, (1, 50, 99)) * 0.001
        self.near_m = min(self.near_m, float(low))
        self.far_m = max(self.far_m, float(high))
        self._medians.append(float(median))

    @property
    def median_m(self) -> float:
        """The median of the frames' median depths (0 without any depth)."""
        return float(np.median(self._medians)) if self._medians else 0.0

    def describe(self) -> str:
        """``depth 0.52-3.87 m (median 1.41 m) in 3 of 3 frames``."""
        if not self.frames_with_depth:
            return f"no depth in any of {self.frames} frames"
        return (f"depth {self.near_m:.3g}-{self.far_m:.3g} m (median {self.median_m:.3g} m) "
                f"in {self.frames_with_depth} of {self.frames} frames")

    def problem(self) -> str:
        """Why this depth is implausible for an RGB-D camera (wrong units?), or ""."""
        low, high = PLAUSIBLE_MEDIAN_DEPTH_M
        if self.frames and not self.frames_with_depth:
            return "no frame has any depth (every depth pixel is 0)"
        if self.frames_with_depth and not low <= self.median_m <= high:
            return (f"the median depth is {self.median_m:.3g} m, outside the {low:g}-{high:g} m "
                    "an RGB-D camera measures: the depth is probably in another unit than "
                    "depth_scale says")
        return ""


def organize(points: np.ndarray, colors: np.ndarray | None, width: int, height: int,
             fx: float, fy: float, cx: float, cy: float, stride: int = 1
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """An organized cloud back from a deprojected one (e.g. for `gngdt.core.odometry.map_odometry`).

    points: (N, 3) camera frame (x right, y down, z forward), metres, as a depth image's valid
    pixels deprojected with the pinhole ``fx, fy, cx, cy`` (the learner's ``points`` topic with
    its calibration); colors: (N, 3) uint8 or None. Each point goes back to the pixel it came
    from. Returns (height, width, 3) float32 points, NaN where no point lands, and the colours
    there (zero elsewhere) or None. Points behind the camera or off the image are dropped.
    ``stride``: only every stride-th row and column, (ceil(height / stride), ceil(width /
    stride), 3) each, the same as the whole image's ``[::stride, ::stride]`` (for a tracker that
    looks at no finer pixels).
    """
    from gngdt.core.kernels import odometry as OK  # numba: loaded when first used

    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    # views as they come (a decoded cloud's are strided): copying them costs 6x the kernel
    points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    shape = (-(-height // stride), -(-width // stride), 3)
    organized = np.full(shape, np.nan, dtype=np.float32)
    image = np.zeros(shape, dtype=np.uint8)
    pixels = (np.zeros((0, 3), dtype=np.uint8) if colors is None
              else np.asarray(colors, dtype=np.uint8).reshape(-1, 3))
    OK.organize_points(points, pixels, float(fx), float(fy), float(cx), float(cy), int(width),
                       int(height), int(stride), organized, image)
    return organized, None if colors is None else image


#: a cloud starts a tracked map only when its depth image holds smooth surfaces: at least this
#: share of its neighbouring pixels (both with depth) within ``SMOOTH_DEPTH_SHARE`` of each
#: other's depth (measured: real and rendered scenes 0.99, a depth image of noise 0.02-0.36),
#: judged from ``MIN_JUDGED_PAIRS`` such pairs (fewer: a sparse cloud, not judged)
MIN_SMOOTH_SHARE = 0.5
SMOOTH_DEPTH_SHARE = 0.02
MIN_JUDGED_PAIRS = 1000
#: the reason a tracker's loss of such a frame is counted under
NOT_A_SCENE = "no smooth surfaces"


def implausible_start(positions: np.ndarray, camera: Any) -> str:
    """Why a cloud (``positions`` (N, 3) camera frame, its depth image's valid pixels
    deprojected with ``camera``, a `CameraIntrinsics`) cannot start a map: its depth image holds
    no smooth surfaces (see ``MIN_SMOOTH_SHARE``), a sensor's noise and not a scene; "" when it
    can, or when it cannot be judged (no intrinsics, too sparse a cloud)."""
    if camera is None:
        return ""
    organized, _ = organize(positions, None, camera.width, camera.height, camera.fx,
                            camera.fy, camera.cx, camera.cy)
    depth = organized[..., 2]
    pairs = smooth = 0
    for first, second in ((depth[:, 1:], depth[:, :-1]), (depth[1:, :], depth[:-1, :])):
        both = np.isfinite(first) & np.isfinite(second)
        pairs += int(both.sum())
        smooth += int(np.count_nonzero(
            np.abs(first[both] - second[both]) <= SMOOTH_DEPTH_SHARE * first[both]))
    if pairs < MIN_JUDGED_PAIRS or smooth >= MIN_SMOOTH_SHARE * pairs:
        return ""
    return (f"a map is not started from this frame: only {smooth / pairs:.0%} of its "
            f"neighbouring depth pixels lie within {SMOOTH_DEPTH_SHARE:.0%} of each other "
            f"(a scene's surfaces: ~99 %; at least {MIN_SMOOTH_SHARE:.0%} needed): the depth "
            "image holds no smooth surfaces (noise, not a scene)")
