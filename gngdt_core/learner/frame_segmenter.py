"""Per-pixel segments of RGB-D frames: a GNG-DT network learned from the frames
(`gngdt.core.learner.stream_learner`), segmented by local convexity
(`gngdt.core.segmentation.network`), each pixel labelled by its nearest node.

Online (the default) one network is carried from frame to frame; independent mode learns every
frame from scratch (unrelated snapshots). Pure computation on organized point arrays; reading
images and writing label files is the caller's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gngdt.core.gas.model import GNGDT
from gngdt.core.learner.stream_learner import FrameSchedule, StreamLearner
from gngdt.core.segmentation.network import SegmentationParams
from gngdt.core.sensor.depth import veil_pixels

__all__ = ["FrameResult", "FrameSchedule", "FrameSegmenter", "node_budget", "veil_pixels"]

#: a network learned from a frame gets at most one node per this many learnable pixels (a
#: 640x480 frame keeps a profile's 4,000 nodes; an 8x8 one gets 4, not 4,000 for 64 points)
PIXELS_PER_NODE = 16


#: a scaled-down schedule still learns at least this many steps from scratch, and per frame
MIN_STEPS_FIRST_FRAME, MIN_STEPS_PER_FRAME = 2_000, 200


def node_budget(max_nodes: int, learnable_pixels: int) -> int:
    """The node budget of a network learned from a frame of ``learnable_pixels``."""
    return max(2, min(max_nodes, learnable_pixels // PIXELS_PER_NODE))


def scaled_schedule(schedule: FrameSchedule, share: float) -> FrameSchedule:
    """``schedule`` with its steps scaled by ``share`` (a smaller budget's share of the
    profile's), down to ``MIN_STEPS_FIRST_FRAME`` / ``MIN_STEPS_PER_FRAME`` at least."""
    def steps(value: int, least: int) -> int:
        return max(min(value, least), round(value * share))

    return replace(schedule, steps_first_frame=steps(schedule.steps_first_frame,
                                                     MIN_STEPS_FIRST_FRAME),
                   steps_per_frame=steps(schedule.steps_per_frame, MIN_STEPS_PER_FRAME))


@dataclass
class FrameResult:
    """Labels of one frame and what it cost."""

    #: (H, W) int32: 0 = no segment (no depth), k >= 1 = segment k
    labels: np.ndarray
    n_nodes: int
    n_segments: int
    steps: int
    #: learned from scratch (independent mode, the first frame, or a scene change)
    from_scratch: bool
    milliseconds: dict[str, float] = field(default_factory=dict)


class FrameSegmenter:
    """Segments RGB-D frames with one GNG-DT network (see `StreamLearner` for the schedule).

    model_params: `GNGDT` constructor arguments (a node budget and insertion rate suited to the
    sensor, see ``config/``); segmentation: `SegmentationParams`; schedule: `FrameSchedule`.
    """

    def __init__(self, model_params: dict[str, Any] | None = None,
                 segmentation: SegmentationParams | None = None,
                 schedule: FrameSchedule | None = None, random_state: int | None = 0) -> None:
        self.stream = StreamLearner(model_params, segmentation, schedule, random_state)
        #: the profile's node budget and schedule; a small frame gets a share of them
        self.max_nodes = int(self.stream.model_params.get("max_nodes", GNGDT().max_nodes))
        self.schedule = self.stream.schedule
        #: (H, W) bool: the last frame's pixels on large flat surfaces (attention's prior)
        self._surface_pixels: np.ndarray | None = None

    @property
    def model_(self) -> GNGDT | None:
        return self.stream.model_

    def reset(self) -> None:
        """Forget the network: the next frame is learned from scratch."""
        self.stream.reset()
        self._surface_pixels = None

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
        learnable = self._learnable(points).reshape(-1)
        positions = np.compress(learnable, points.reshape(-1, 3), axis=0)
        clock.lap("prepare")
        if len(positions) < 2:
            model = self.model_
            return FrameResult(np.zeros((height, width), dtype=np.int32),
                               model.n_nodes_ if model else 0, 0, 0, False, clock.laps)
        # a network learned from scratch on this frame gets a budget its pixels can fill, and
        # steps in proportion
        budget = node_budget(self.max_nodes, len(positions))
        self.stream.model_params["max_nodes"] = budget
        self.stream.schedule = scaled_schedule(self.schedule, budget / self.max_nodes)
        surface = self._surface_pixels
        prior = (None if surface is None or surface.shape != (height, width)
                 else np.compress(learnable, surface.reshape(-1)))
        learned = self.stream.learn_frame(
            positions, np.compress(learnable, colors.reshape(-1, 3), axis=0), independent,
            on_large_surface=prior)
        clock.lap("learn")
        # one search labels both: pixel value 2 * (segment + 1) + on a large surface, so a
        # node of no segment (-1) off the surfaces still maps to 0
        both = self.model_.label_pixels(
            points, 2 * learned.segmentation.labels + 1 + learned.on_large_surface)
        labels = both >> 1
        self._surface_pixels = (both & 1).astype(bool)
        clock.lap("label")
        return FrameResult(labels, self.model_.n_nodes_,
                           learned.segmentation.n_segments, learned.steps, learned.from_scratch,
                           clock.laps)

    def _learnable(self, points: np.ndarray) -> np.ndarray:
        """(H, W) bool: the pixels learned: a point in the depth range (so not NaN), not a veil
        point."""
        keep = self.stream.in_depth_range(points.reshape(-1, 3)).reshape(points.shape[:2])
        ratio = self.stream.schedule.veil_ratio
        if ratio > 0:
            keep &= ~veil_pixels(points[..., 2], ratio)
        return keep


class _Clock:
    """Milliseconds per named phase."""

    def __init__(self) -> None:
        self.laps: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = (now - self._last) * 1000.0
        self._last = now
