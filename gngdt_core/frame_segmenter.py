"""Per-pixel segments of RGB-D frames: a GNG-DT network learned from the frames, segmented by
local convexity (`gngdt_core.segmentation`), each pixel labelled by its nearest node.

Online (the default) one network is carried from frame to frame and learns a step budget per
frame; independent mode learns every frame from scratch (unrelated snapshots). Pure
computation on organized point arrays; reading images and writing label files is the caller's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from gngdt_core.model import GNGDT
from gngdt_core.parameters import check_integer, check_real
from gngdt_core.segmentation import SegmentationParams


@dataclass(frozen=True)
class FrameSchedule:
    """How frames are turned into learning: steps, pixels used, attention (validated)."""

    #: learning steps for a frame learned from scratch (independent mode, or the first frame)
    steps_first_frame: int = 300_000
    #: learning steps for each later frame of a stream (online mode)
    steps_per_frame: int = 20_000
    #: a pixel is a veil point (a depth edge's mixed measurement) and not learned when its
    #: depth differs from a 4-neighbour's by more than this share of its depth
    veil_ratio: float = 0.03
    #: depth range learned, metres (pixels outside it are still labelled)
    min_depth_m: float = 0.0
    max_depth_m: float = 10.0
    #: share of the points on large flat surfaces (tables, floors) that are learned; the node
    #: budget goes to the objects instead (1.0: every point)
    flat_surface_share: float = 1.0
    #: a smooth patch is a large flat surface when it holds at least this share of the nodes
    flat_surface_min_nodes: float = 0.1

    def __post_init__(self) -> None:
        check_integer("steps_first_frame", self.steps_first_frame, 1)
        check_integer("steps_per_frame", self.steps_per_frame, 1)
        check_real("veil_ratio", self.veil_ratio, 0.0)
        check_real("min_depth_m", self.min_depth_m, 0.0)
        check_real("max_depth_m", self.max_depth_m, self.min_depth_m, low_open=True)
        check_real("flat_surface_share", self.flat_surface_share, 0.0, 1.0, low_open=True)
        check_real("flat_surface_min_nodes", self.flat_surface_min_nodes, 0.0, 1.0)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> FrameSchedule:
        known = {item.name for item in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown frame schedule key(s) {unknown}; known: {sorted(known)}")
        return cls(**values)


@dataclass
class FrameResult:
    """Labels of one frame and what it cost."""

    #: (H, W) int32: 0 = no segment (no depth), k >= 1 = segment k
    labels: np.ndarray
    n_nodes: int
    n_segments: int
    steps: int
    milliseconds: dict[str, float] = field(default_factory=dict)


def veil_points(points: np.ndarray, ratio: float) -> np.ndarray:
    """(H, W) bool: pixels whose depth jumps from a 4-neighbour's by more than ``ratio`` of the
    nearer depth — the mixed foreground/background measurements along depth edges, which would
    otherwise bridge an object and what lies behind it. points: (H, W, 3) metres, NaN = none."""
    depth = points[..., 2]
    veil = np.zeros(depth.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            first = np.take(depth, range(depth.shape[axis] - 1), axis=axis)
            second = np.take(depth, range(1, depth.shape[axis]), axis=axis)
            jump = np.abs(second - first) > ratio * np.fmin(first, second)
            if axis == 0:
                veil[:-1] |= jump
                veil[1:] |= jump
            else:
                veil[:, :-1] |= jump
                veil[:, 1:] |= jump
    return veil


class FrameSegmenter:
    """Segments RGB-D frames with one GNG-DT network.

    model_params: `GNGDT` constructor arguments (a node budget and insertion rate suited to the
    sensor, see ``config/``); segmentation: `SegmentationParams`; schedule: `FrameSchedule`.
    """

    def __init__(self, model_params: dict[str, Any] | None = None,
                 segmentation: SegmentationParams | None = None,
                 schedule: FrameSchedule | None = None, random_state: int | None = 0) -> None:
        self.model_params = dict(model_params or {})
        self.segmentation = segmentation or SegmentationParams()
        self.schedule = schedule or FrameSchedule()
        self.random_state = random_state
        GNGDT(**self.model_params, random_state=random_state)  # validate now, not at frame 1
        self._rng = np.random.default_rng(random_state)
        self.model_: GNGDT | None = None
        self._on_large_surface: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the network: the next frame is learned from scratch."""
        self.model_ = None
        self._on_large_surface = None

    def segment_frame(self, points: np.ndarray, colors: np.ndarray,
                      independent: bool = False) -> FrameResult:
        """Learn from one frame and label its pixels.

        points: (H, W, 3) float32 metres in the camera frame, NaN where there is no depth;
        colors: (H, W, 3) uint8 RGB. independent: learn this frame from scratch.
        """
        if points.ndim != 3 or points.shape[2] != 3:
            raise ValueError(f"points must be (H, W, 3), got {points.shape}")
        if colors.shape != points.shape:
            raise ValueError(f"colors {colors.shape} do not match points {points.shape}")
        clock = _Clock()
        height, width, _ = points.shape
        flat_points = points.reshape(-1, 3)
        valid = np.flatnonzero(np.isfinite(flat_points).all(axis=1))
        learnable = self._learnable(points, valid)
        clock.lap("prepare")
        if independent or self.model_ is None:
            self.model_ = GNGDT(**self.model_params, random_state=self.random_state)
            self._on_large_surface = None
            steps = self.schedule.steps_first_frame
        else:
            steps = self.schedule.steps_per_frame
        labels = np.zeros(height * width, dtype=np.int32)
        if learnable.size < 2:
            return FrameResult(labels.reshape(height, width), self.model_.n_nodes_, 0, 0,
                               clock.laps)
        self._learn(flat_points, colors.reshape(-1, 3), learnable, steps)
        clock.lap("learn")
        segmentation = self.model_.segmentation(self.segmentation)
        node_labels = segmentation.labels
        self._on_large_surface = self._large_surfaces(segmentation.patches)
        clock.lap("segment")
        winners = self.model_.predict(flat_points[valid])
        labels[valid] = node_labels[winners] + 1
        clock.lap("label")
        return FrameResult(labels.reshape(height, width), self.model_.n_nodes_,
                           int(node_labels.max()) + 1, steps, clock.laps)

    def _learnable(self, points: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Flat indices of the valid pixels learned: in the depth range and not veil points."""
        schedule = self.schedule
        depth = points.reshape(-1, 3)[valid, 2]
        keep = (depth >= schedule.min_depth_m) & (depth <= schedule.max_depth_m)
        if schedule.veil_ratio > 0:
            keep &= ~veil_points(points, schedule.veil_ratio).reshape(-1)[valid]
        return valid[keep]

    def _learn(self, flat_points: np.ndarray, flat_colors: np.ndarray, learnable: np.ndarray,
               steps: int) -> None:
        model = self.model_
        share = self.schedule.flat_surface_share
        if share < 1.0 and self._on_large_surface is None:
            # learn a first share of the steps on everything, to know where the surfaces are
            warm_up = steps // 3
            model.partial_fit(flat_points[learnable], flat_colors[learnable], n_steps=warm_up)
            self._on_large_surface = self._large_surfaces(
                model.segmentation(self.segmentation).patches)
            steps -= warm_up
        if share < 1.0:
            learnable = self._attend(flat_points, learnable, share)
        model.partial_fit(flat_points[learnable], flat_colors[learnable], n_steps=steps)

    def _large_surfaces(self, patches: np.ndarray) -> np.ndarray:
        """(n_nodes,) bool: nodes of smooth patches holding a large share of the nodes."""
        sizes = np.bincount(patches)
        return (sizes >= self.schedule.flat_surface_min_nodes * patches.size)[patches]

    def _attend(self, flat_points: np.ndarray, learnable: np.ndarray,
                share: float) -> np.ndarray:
        """Keep ``share`` of the points whose nearest node is on a large flat surface."""
        on_surface = self._on_large_surface
        if on_surface is None or not on_surface.any() or on_surface.size != self.model_.n_nodes_:
            return learnable
        on_large = on_surface[self.model_.predict(flat_points[learnable])]
        keep = ~on_large | (self._rng.random(learnable.size) < share)
        return learnable[keep]


class _Clock:
    """Milliseconds per named phase."""

    def __init__(self) -> None:
        self.laps: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = (now - self._last) * 1000.0
        self._last = now
