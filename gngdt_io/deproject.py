"""RGB-D frame to coloured point cloud: deprojection, voxel downsampling and a point cap
(`FrameToCloud` does all of it as capture does).

Pure numpy, no I/O. Camera frame: x right, y down, z forward, metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from gngdt.core.parameters import Interval, Settings, param
from gngdt.core.sensor.depth import veil_pixels
from gngdt.io.frame import CameraIntrinsics, Frame
from gngdt.io.pack_points import count_kept, kept_pixels, pack_kept
from gngdt.schemas.clouds import MAX_CLOUD_POINTS, cloud_to_wire, cloud_wire_buffer

#: the point cap of the clouds `gngdt run` learns from (capture's ``--max-points`` under run, and
#: `gngdt eval recording`'s, so both learn the same clouds): a uniform random subset, as the
#: learner's own sampling; the learner samples 10,000 points a frame and the logger shows 50,000,
#: so the cap changes neither, and on 2 cores at 30 fps it cut dropped frames from ~30 % to ~5 %
RUN_POINT_CAP = 50_000


def axis_slopes(intrinsics: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Ray slopes of each column ``(u - cx) / fx``, (W,), and of each row ``(v - cy) / fy``,
    (H,): float32, computed in float64."""
    if intrinsics.fx <= 0 or intrinsics.fy <= 0:
        raise ValueError(f"intrinsics: focal lengths must be positive, got {intrinsics}")
    u = (np.arange(intrinsics.width, dtype=np.float64) - intrinsics.cx) / intrinsics.fx
    v = (np.arange(intrinsics.height, dtype=np.float64) - intrinsics.cy) / intrinsics.fy
    return u.astype(np.float32), v.astype(np.float32)


def ray_map(intrinsics: CameraIntrinsics) -> np.ndarray:
    """Per-pixel ray slopes ``((u - cx) / fx, (v - cy) / fy)``: (H, W, 2) float32.

    A point at depth z (metres) seen at pixel (u, v) is ``(slope_x * z, slope_y * z, z)``.
    """
    slope_u, slope_v = axis_slopes(intrinsics)
    rays = np.empty((intrinsics.height, intrinsics.width, 2), dtype=np.float32)
    rays[..., 0] = slope_u[None, :]
    rays[..., 1] = slope_v[:, None]
    return rays


@dataclass(frozen=True)
class CloudOptions(Settings):
    """How a depth frame becomes the published point cloud (every default declared here, beside
    its constraint; capture's options take theirs from these)."""

    WHAT: ClassVar[str] = "cloud option"

    min_depth_m: float = param(0.1, Interval(float, 0.0), "nearest depth kept, metres")
    max_depth_m: float = param(10.0, Interval(float, 0.0, closed="neither"),
                               "farthest depth kept, metres")
    voxel_size_m: float | None = param(
        None, Interval(float, 0.0, closed="neither", optional=True),
        "voxel-grid downsampling cell size, metres (None: none)")
    max_points: int | None = param(None, Interval(int, 1, optional=True),
                                   "random point cap per frame (None: every point)")
    veil_ratio: float = param(0.0, Interval(float, 0.0),
                              "drop pixels whose depth jumps by more than this share from a "
                              "neighbour's (0: keep all)")

    def check(self) -> None:
        super().check()
        if self.max_depth_m <= self.min_depth_m:
            raise ValueError(f"depth range: max_depth_m ({self.max_depth_m}) must exceed "
                             f"min_depth_m ({self.min_depth_m})")


class Deprojector:
    """Deprojects depth images, reusing the ray map while the intrinsics stay the same."""

    def __init__(self, min_depth_m: float = CloudOptions.min_depth_m,
                 max_depth_m: float = CloudOptions.max_depth_m) -> None:
        if not 0.0 <= min_depth_m < max_depth_m:
            raise ValueError(
                f"depth range: need 0 <= min_depth < max_depth, got {min_depth_m}, {max_depth_m}"
            )
        self.min_depth_m = min_depth_m
        self.max_depth_m = max_depth_m
        self._intrinsics: CameraIntrinsics | None = None
        self._slopes: tuple[np.ndarray, np.ndarray] | None = None
        self._axis_intrinsics: CameraIntrinsics | None = None
        self._axis_slopes: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def depth_range(self) -> tuple[float, float]:
        """The depths kept, metres: [nearest, farthest] (a depth of 0 is never kept)."""
        return max(self.min_depth_m, 1e-6), self.max_depth_m

    def slopes_for(self, intrinsics: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
        """Flat contiguous ray slopes (H*W,) float32 x and y of ``intrinsics`` (cached)."""
        if self._slopes is None or intrinsics != self._intrinsics:
            rays = ray_map(intrinsics)
            self._slopes = (np.ascontiguousarray(rays[..., 0]).reshape(-1),
                            np.ascontiguousarray(rays[..., 1]).reshape(-1))
            self._intrinsics = intrinsics
        return self._slopes

    def axis_slopes_for(self, intrinsics: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
        """`axis_slopes` of ``intrinsics`` (cached): the ray map's (W,) and (H,) float32 axes,
        a few kB where `slopes_for` holds 66 MB at 3840x2160."""
        if self._axis_slopes is None or intrinsics != self._axis_intrinsics:
            self._axis_slopes = axis_slopes(intrinsics)
            self._axis_intrinsics = intrinsics
        return self._axis_slopes

    def __call__(
        self, depth_mm: np.ndarray, color: np.ndarray | None, intrinsics: CameraIntrinsics,
        max_points: int | None = None, rng: np.random.Generator | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Valid pixels of a depth image as points (with ``max_points``: a uniform random
        subset of at most that many of them, drawn with ``rng`` before deprojecting).

        depth_mm: (H, W) uint16 millimetres (or float, NaN allowed); 0, NaN and depths outside
        [min_depth, max_depth] are dropped. color: (H, W, 3) uint8 registered to depth, or None.
        Returns positions (N, 3) float32 metres and colors (N, 3) uint8 (or None), row-major
        pixel order.
        """
        positions, colors, _ = self.with_pixels(depth_mm, color, intrinsics, max_points, rng)
        return positions, colors

    def with_pixels(
        self, depth_mm: np.ndarray, color: np.ndarray | None, intrinsics: CameraIntrinsics,
        max_points: int | None = None, rng: np.random.Generator | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """As calling it, with the (N,) int64 flat indices of the pixels each point comes
        from (to take anything else registered to the image, e.g. ground-truth labels)."""
        z, valid = self._depth_metres(depth_mm, color, intrinsics)
        if max_points is not None and valid.size > max_points:
            valid = valid.take(uniform_subset(valid.size, max_points, rng))
        slope_x, slope_y = self.slopes_for(intrinsics)
        # Flat indices and take() are ~10x faster than boolean indexing of the (H, W, k) arrays.
        z_valid = z.take(valid)
        positions = np.empty((valid.size, 3), dtype=np.float32)
        positions[:, 0] = slope_x.take(valid) * z_valid
        positions[:, 1] = slope_y.take(valid) * z_valid
        positions[:, 2] = z_valid
        if color is None:
            return positions, None, valid
        colors = np.asarray(color, dtype=np.uint8).reshape(-1, 3).take(valid, axis=0)
        return positions, colors, valid

    def organized(self, depth_mm: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
        """Every pixel of a depth image as a point, in image layout: (H, W, 3) float32 metres,
        NaN where the depth is dropped (0, NaN or outside [min_depth, max_depth])."""
        z, valid = self._depth_metres(depth_mm, None, intrinsics)
        slope_x, slope_y = self.slopes_for(intrinsics)
        points = np.full((z.size, 3), np.nan, dtype=np.float32)
        z_valid = z.take(valid)
        points[valid, 0] = slope_x.take(valid) * z_valid
        points[valid, 1] = slope_y.take(valid) * z_valid
        points[valid, 2] = z_valid
        return points.reshape(intrinsics.height, intrinsics.width, 3)

    def _depth_metres(
        self, depth_mm: np.ndarray, color: np.ndarray | None, intrinsics: CameraIntrinsics
    ) -> tuple[np.ndarray, np.ndarray]:
        """Flat (H*W,) float32 depth in metres and the flat indices of the kept pixels; checks
        that depth, colour and calibration sizes agree."""
        depth_mm = self.checked_depth(depth_mm, color, intrinsics)
        # NaN compares False, so it is dropped with the out-of-range depths (one compiled pass)
        return kept_pixels(depth_mm.reshape(-1), *self.depth_range)

    @staticmethod
    def checked_depth(depth_mm: np.ndarray, color: np.ndarray | None,
                      intrinsics: CameraIntrinsics) -> np.ndarray:
        """``depth_mm`` C-contiguous, once its size agrees with the colour's and the
        calibration's (else ValueError)."""
        if depth_mm.shape != (intrinsics.height, intrinsics.width):
            raise ValueError(
                f"depth image {depth_mm.shape[1]}x{depth_mm.shape[0]} does not match "
                f"calibration {intrinsics.width}x{intrinsics.height}"
            )
        if color is not None and color.shape[:2] != depth_mm.shape:
            raise ValueError(
                f"colour image {color.shape[1]}x{color.shape[0]} does not match "
                f"depth {depth_mm.shape[1]}x{depth_mm.shape[0]}"
            )
        return np.ascontiguousarray(depth_mm)


def voxel_keys(positions: np.ndarray, voxel_size_m: float) -> np.ndarray:
    """(N,) int64 key of each point's cubic voxel (cell indices packed row-major), so that one
    1-D ``np.unique`` groups the points. positions: (N, D) metres; voxel_size_m > 0."""
    if not voxel_size_m > 0:
        raise ValueError(f"voxel size must be positive, got {voxel_size_m}")
    cells = np.floor(positions / np.float32(voxel_size_m)).astype(np.int64)
    cells -= cells.min(axis=0)
    extents = cells.max(axis=0) + 1
    if float(np.prod(extents.astype(np.float64))) >= 2.0**62:  # keys would overflow int64
        raise ValueError(f"voxel size {voxel_size_m} m is too small for these positions")
    return np.ravel_multi_index(tuple(cells.T), tuple(int(extent) for extent in extents))


def voxel_downsample(
    positions: np.ndarray, colors: np.ndarray | None, voxel_size_m: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """Mean position (and colour) of the points in each occupied cubic voxel.

    positions: (N, 3) float32 metres (any D works); colors: (N, 3) uint8 or None;
    voxel_size_m > 0. Returns (M, 3) float32 positions and (M, 3) uint8 colours (rounded
    mean), M <= N, voxels in ascending key order.
    """
    if len(positions) == 0:
        return positions, colors
    keys = voxel_keys(positions, voxel_size_m)
    _, voxel_of_point, counts = np.unique(keys, return_inverse=True, return_counts=True)
    n_voxels = counts.size

    def voxel_mean(values: np.ndarray) -> np.ndarray:
        sums = np.empty((n_voxels, values.shape[1]), dtype=np.float64)
        for axis in range(values.shape[1]):
            sums[:, axis] = np.bincount(voxel_of_point, weights=values[:, axis], minlength=n_voxels)
        return sums / counts[:, None]

    mean_positions = voxel_mean(positions).astype(np.float32)
    mean_colors = None
    if colors is not None:
        mean_colors = np.rint(voxel_mean(colors)).clip(0, 255).astype(np.uint8)
    return mean_positions, mean_colors


#: `uniform_subset` draws this many numbers at a time
SUBSET_BLOCK = 1 << 20


def uniform_subset(n: int, k: int, rng: np.random.Generator | None) -> np.ndarray:
    """(k,) int64 sorted indices: a uniform random k-subset of ``range(n)``, 0 < k < n.

    Each index is drawn with a probability a little above k/n and the surplus dropped at
    random: given how many were drawn, the draw is a uniform subset of that size, and so is
    what is left of it (about 3x faster than ``rng.choice(n, k, replace=False)`` and a sort at
    n = 300,000, k = 50,000)."""
    if not 0 < k < n:
        raise ValueError(f"need 0 < k < n, got k={k}, n={n}")
    rng = rng or np.random.default_rng()
    share = np.float32(min(1.0, (k + 4.0 * np.sqrt(k) + 10.0) / n))
    # drawn a block at a time (the same stream as one draw of n): no (n,) arrays
    drawn = np.concatenate([
        np.flatnonzero(rng.random(min(SUBSET_BLOCK, n - start), dtype=np.float32) < share) + start
        for start in range(0, n, SUBSET_BLOCK)])
    if drawn.size < k:  # fewer than expected by over 4 standard deviations
        return np.sort(rng.choice(n, size=k, replace=False))
    return np.delete(drawn, rng.choice(drawn.size, size=drawn.size - k, replace=False))


def cap_points(
    positions: np.ndarray,
    colors: np.ndarray | None,
    max_points: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray | None]:
    """A uniform random subset of at most ``max_points`` points (order kept), drawn with ``rng``."""
    if max_points <= 0:
        raise ValueError(f"max_points must be positive, got {max_points}")
    if len(positions) <= max_points:
        return positions, colors
    keep = uniform_subset(len(positions), max_points, rng)
    return positions.take(keep, axis=0), None if colors is None else colors.take(keep, axis=0)


class FrameToCloud:
    """Deprojection, optional voxel downsampling and point cap, with cached rays."""

    def __init__(self, options: CloudOptions, seed: int = 0) -> None:
        self.options = options
        self._max_points = min(options.max_points or MAX_CLOUD_POINTS, MAX_CLOUD_POINTS)
        self._deproject = Deprojector(options.min_depth_m, options.max_depth_m)
        self._rng = np.random.default_rng(seed)

    def __call__(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """positions (N, 3) float32 metres and colors (N, 3) uint8 of one frame."""
        if self.options.voxel_size_m is None:
            positions, colors, _ = self.with_pixels(frame)
            return positions, colors
        positions, colors = self._deproject(self._depth(frame), frame.color, frame.intrinsics)
        positions, colors = voxel_downsample(positions, colors, self.options.voxel_size_m)
        if len(positions) > self._max_points:
            positions, colors = cap_points(positions, colors, self._max_points, self._rng)
        assert colors is not None
        return positions, colors

    def to_wire(self, frame: Frame, *, timestamp_ns: int, frame_id: str,
                pose: np.ndarray | None) -> tuple[bytearray, int]:
        """The frame's cloud serialised (`gngdt.schemas.clouds.cloud_to_wire` of what calling it
        gives, byte for byte, the same draws of the point cap) and its point count. Without a
        voxel grid the kept pixels are deprojected straight into the buffer
        (`gngdt.io.pack_points`): no arrays of points, nor of the image's size, in between."""
        if self.options.voxel_size_m is not None:
            positions, colors = self(frame)
            return cloud_to_wire(positions, colors, timestamp_ns=timestamp_ns,
                                 frame_id=frame_id, pose=pose), len(positions)
        deproject, intrinsics = self._deproject, frame.intrinsics
        depth = deproject.checked_depth(self._depth(frame), frame.color, intrinsics)
        kept = count_kept(depth, *deproject.depth_range)
        count = min(kept, self._max_points)
        # the ranks among the kept pixels of those deprojected: the same draw as `with_pixels`
        ranks = (uniform_subset(kept, count, self._rng) if kept > count
                 else np.empty(0, dtype=np.int64))
        slope_u, slope_v = deproject.axis_slopes_for(intrinsics)
        wire, start = cloud_wire_buffer(count, True, timestamp_ns=timestamp_ns,
                                        frame_id=frame_id, pose=pose)
        pack_kept(depth, *deproject.depth_range, slope_u, slope_v,
                  np.asarray(frame.color, dtype=np.uint8).reshape(-1, 3), ranks, kept == count,
                  np.frombuffer(wire, dtype=np.uint8, offset=start))
        return wire, count

    @staticmethod
    def warm_up() -> None:
        """Load the compiled deprojection kernels (numba's cache, or compile them) now, not on
        the first frame."""
        kept_pixels(np.zeros(1, np.uint16), 0.1, 10.0)
        depth = np.full((1, 1), 1000, np.uint16)
        count_kept(depth, 0.1, 10.0)
        pack_kept(depth, 0.1, 10.0, np.ones(1, np.float32), np.ones(1, np.float32),
                  np.zeros((1, 3), np.uint8), np.zeros(0, np.int64), True, np.zeros(15, np.uint8))

    def with_pixels(self, frame: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As calling it (the same draws of the point cap), with the (N,) int64 flat pixel
        index of each point; ValueError with a voxel grid (its points stand for many pixels)."""
        if self.options.voxel_size_m is not None:
            raise ValueError("a voxel-downsampled cloud has no pixel per point")
        # cap the pixels: only those kept are deprojected
        positions, colors, pixels = self._deproject.with_pixels(
            self._depth(frame), frame.color, frame.intrinsics, self._max_points, self._rng)
        assert colors is not None
        return positions, colors, pixels

    def _depth(self, frame: Frame) -> np.ndarray:
        """The frame's depth, veil pixels dropped (``veil_ratio``)."""
        if self.options.veil_ratio > 0:
            return np.where(veil_pixels(frame.depth, self.options.veil_ratio), 0, frame.depth)
        return frame.depth
