"""Learning one GNG-DT network from a stream of frames (point sets) and segmenting it.

`StreamLearner` decides, per frame, how much to learn and from which points:

- the first frame, and any frame that shows a new scene (more than ``scene_change_share`` of
  its points lie farther than ``scene_change_distance_m`` — and than three times the network's
  own resolution on the last frame — from every node: a cut, a rearranged table), is learned
  from scratch for ``steps_first_frame`` steps; later frames refine the carried network for
  ``steps_per_frame`` steps;
- attention: the node budget goes to the objects, not to the table. Large flat surfaces (smooth
  patches of the segmentation holding at least ``flat_surface_min_nodes`` of the nodes) are
  learned from only ``flat_surface_share`` of their points. A network learned from scratch
  learns ``warm_up_share`` of its steps from every point first, to find those surfaces.

After learning it segments the network (`gngdt.core.segmentation.network`). Pure computation: points
in, network and segments out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from gngdt.core.gas.model import GNGDT
from gngdt.core.parameters import Interval, Settings, param
from gngdt.core.segmentation.network import Segmentation, SegmentationParams
from gngdt.core.sensor.view import SensorView

#: points of a frame checked for a scene change
SCENE_SAMPLE = 2_000
#: points drawn per learning step before attention thins out the flat surfaces
ATTENTION_DRAW = 3
#: a scene change needs points farther than this many times the distance within which 90 % of
#: the last frame's points lay from the nodes (and than ``scene_change_distance_m``): a coarse
#: network is far from many points of the very scene it learned
SCENE_CHANGE_RESOLUTION = 3.0
#: every this many of a frame's points make the view that judges gaps of missing depth: half
#: the points cost half the time (3 -> 1.5 ms at 640x480) and bridged ycbv's mug as often
GAP_VIEW_STRIDE = 2


@dataclass(frozen=True)
class FrameSchedule(Settings):
    """How frames are turned into learning: steps, points used, attention (validated)."""

    WHAT: ClassVar[str] = "frame schedule key"

    steps_first_frame: int = param(200_000, Interval(int, 1),
                                   "learning steps for a frame learned from scratch "
                                   "(independent, first frame, new scene)")
    steps_per_frame: int = param(10_000, Interval(int, 1),
                                 "learning steps for each later frame of a stream")
    veil_ratio: float = param(0.03, Interval(float, 0.0),
                              "organized frames only: a pixel whose depth differs from a "
                              "4-neighbour's by more than this share of the nearer depth is a "
                              "veil point (a depth edge's mixed measurement), not learned; 0 "
                              "keeps every pixel")
    min_depth_m: float = param(0.0, Interval(float, 0.0),
                               "depth range learned, metres (camera z); pixels outside it are "
                               "still labelled")
    max_depth_m: float = param(10.0, Interval(float, 0.0, closed="neither"),
                               "far end of the depth range learned, metres")
    flat_surface_share: float = param(0.05, Interval(float, 0.0, 1.0, closed="right"),
                                      "share of the points on large flat surfaces (tables, "
                                      "floors) that are learned (1.0: all)")
    flat_surface_min_nodes: float = param(0.1, Interval(float, 0.0, 1.0),
                                          "a smooth patch is a large flat surface when it holds "
                                          "at least this share of the nodes")
    warm_up_share: float = param(0.5, Interval(float, 0.0, 1.0, closed="right"),
                                 "a frame learned from scratch learns this share of its steps "
                                 "from every point first, to find the large flat surfaces")
    scene_change_distance_m: float = param(0.02, Interval(float, 0.0, closed="neither"),
                                           "a frame is a new scene when more than "
                                           "scene_change_share of its points lie farther than "
                                           "this from every node")
    scene_change_share: float = param(0.015, Interval(float, 0.0, 1.0),
                                      "see scene_change_distance_m; 1.0 never cuts")

    def check(self) -> None:
        super().check()
        if self.max_depth_m <= self.min_depth_m:
            raise ValueError(f"max_depth_m ({self.max_depth_m}) must exceed min_depth_m "
                             f"({self.min_depth_m})")



@dataclass(frozen=True)
class FrameOutcome:
    """What `StreamLearner.learn_frame` did with one frame."""

    steps: int
    #: learned from scratch: independent, the first frame, or a new scene
    from_scratch: bool
    segmentation: Segmentation
    #: (n_nodes,) bool: nodes on the large flat surfaces that attention thins out next frame
    on_large_surface: np.ndarray


class StreamLearner:
    """One GNG-DT network learned frame by frame, with attention and scene cuts.

    model_params: `GNGDT` constructor arguments; segmentation: `SegmentationParams`; schedule:
    `FrameSchedule`. Fitted state: ``model_`` (None before the first frame).
    """

    def __init__(self, model_params: dict[str, Any] | None = None,
                 segmentation: SegmentationParams | None = None,
                 schedule: FrameSchedule | None = None, random_state: int | None = 0) -> None:
        self.model_params = dict(model_params or {})
        self.segmentation = segmentation or SegmentationParams()
        self.schedule = schedule or FrameSchedule()
        self.random_state = random_state
        # validate now, not at frame 1
        GNGDT(**self.model_params, random_state=random_state).check_params()
        self._rng = np.random.default_rng(random_state)
        self.model_: GNGDT | None = None
        self._on_large_surface: np.ndarray | None = None
        self._camera_pose: np.ndarray | None = None
        #: distance (metres) within which 90 % of the last frame's points lay from the nodes
        self._resolution = 0.0

    def reset(self) -> None:
        """Forget the network: the next frame is learned from scratch."""
        self.model_ = None
        self._on_large_surface = None

    def learn_frame(self, positions: np.ndarray, colors: np.ndarray | None,
                    independent: bool = False, camera_pose: np.ndarray | None = None,
                    on_large_surface: np.ndarray | None = None,
                    steps: int | None = None) -> FrameOutcome:
        """Learn from one frame and segment the network.

        positions: (N, 3) float metres, N >= 2, finite; colors: (N, 3) uint8 RGB or None.
        independent: learn this frame from scratch. camera_pose: (4, 4) camera-to-world of the
        frame (`GNGDT.partial_fit`): the network is then a map in that fixed frame, and the
        scene-change test and attention compare the frame with it there.
        on_large_surface: (N,) bool, which points lie on a large flat surface as an earlier
        frame showed it (e.g. the previous frame's labels of the same pixels, from
        ``FrameOutcome.on_large_surface``); attention then trusts it instead of searching each
        drawn point's nearest node. Ignored when the frame is learned from scratch.
        steps: the steps of a later frame (default ``steps_per_frame``; a frame learned from
        scratch always takes ``steps_first_frame``).
        """
        if len(positions) < 2:
            raise ValueError(f"a frame needs at least 2 points, got {len(positions)}")
        if on_large_surface is not None and on_large_surface.shape != (len(positions),):
            raise ValueError(f"on_large_surface must have shape ({len(positions)},), got "
                             f"{on_large_surface.shape}")
        self._camera_pose = camera_pose
        placed = self._placed(positions)
        from_scratch = (independent or self.model_ is None or self.model_.n_nodes_ == 0
                        or self._new_scene(placed))
        if from_scratch:
            self.model_ = GNGDT(**self.model_params, random_state=self.random_state)
            self._on_large_surface = None
            steps = self.schedule.steps_first_frame
        else:
            steps = self.schedule.steps_per_frame if steps is None else steps
        self._learn(positions, colors, steps, placed,
                    None if from_scratch else on_large_surface)
        if self.schedule.scene_change_share < 1.0:
            self._resolution = float(np.percentile(self._sample_distances(placed), 90))
        view = (SensorView.of(positions[::GAP_VIEW_STRIDE]) if self.segmentation.bridge_gap_m > 0
                else None)
        segmentation = self.model_.segmentation(self.segmentation, view, camera_pose)
        self._on_large_surface = self._large_surfaces(segmentation.patches)
        return FrameOutcome(steps, from_scratch, segmentation, self._on_large_surface)

    def refine(self, positions: np.ndarray, colors: np.ndarray | None, steps: int,
               camera_pose: np.ndarray | None = None) -> None:
        """Learn ``steps`` more steps from a frame into the current network (with attention),
        without a scene check; e.g. to let a static scene settle. ``camera_pose``: as in
        `learn_frame`."""
        if self.model_ is None:
            raise ValueError("no network yet: learn a frame first")
        self._camera_pose = camera_pose
        self._learn(positions, colors, steps, self._placed(positions))
        self._on_large_surface = None  # the surfaces are found again on the next frame

    def _placed(self, positions: np.ndarray) -> np.ndarray:
        """The frame's points in the network's frame (the camera pose applied, if any)."""
        pose = self._camera_pose
        if pose is None:
            return positions
        return np.asarray(positions, dtype=np.float64) @ pose[:3, :3].T + pose[:3, 3]

    def in_depth_range(self, positions: np.ndarray) -> np.ndarray:
        """(N,) bool: points whose depth (z, metres) is in the schedule's range."""
        depth = positions[:, 2]
        return (depth >= self.schedule.min_depth_m) & (depth <= self.schedule.max_depth_m)

    def _new_scene(self, positions: np.ndarray) -> bool:
        """Whether too many of a sample of the frame's points are far from every node."""
        schedule = self.schedule
        if schedule.scene_change_share >= 1.0:
            return False
        distances = self._sample_distances(positions)
        limit = max(schedule.scene_change_distance_m,
                    SCENE_CHANGE_RESOLUTION * self._resolution)
        return np.count_nonzero(distances > limit) > schedule.scene_change_share * distances.size

    def _sample_distances(self, positions: np.ndarray) -> np.ndarray:
        """Distances (metres) from a random sample of the points to their nearest nodes."""
        # in scan order, as `_attend` draws
        sample = np.sort(self._rng.choice(len(positions), size=min(len(positions), SCENE_SAMPLE),
                                          replace=False))
        return self.model_.predict(positions[sample], return_distance=True)[1]

    def _learn(self, positions: np.ndarray, colors: np.ndarray | None, steps: int,
               placed: np.ndarray, on_large_surface: np.ndarray | None = None) -> None:
        """Learn ``positions`` (camera frame); ``placed``: the same points in the model's frame;
        ``on_large_surface``: the points' attention prior (`learn_frame`), or None."""
        model = self.model_
        pose = self._camera_pose
        share = self.schedule.flat_surface_share
        if share < 1.0 and self._on_large_surface is None:
            warm_up = max(1, int(steps * self.schedule.warm_up_share))
            model.partial_fit(positions, colors, n_steps=warm_up, camera_pose=pose)
            self._on_large_surface = self._large_surfaces(
                model.segmentation(self.segmentation).patches)
            steps -= warm_up
        rows = self._attend(placed, share, steps, on_large_surface) if share < 1.0 else None
        if rows is None:
            model.partial_fit(positions, colors, n_steps=steps, camera_pose=pose)
        else:
            model.partial_fit(positions[rows], None if colors is None else colors[rows],
                              n_steps=steps, camera_pose=pose)

    def _large_surfaces(self, patches: np.ndarray) -> np.ndarray:
        """(n_nodes,) bool: nodes of smooth patches holding a large share of the nodes."""
        sizes = np.bincount(patches)
        return (sizes >= self.schedule.flat_surface_min_nodes * patches.size)[patches]

    def _attend(self, positions: np.ndarray, share: float, steps: int,
                prior: np.ndarray | None) -> np.ndarray | None:
        """Rows to learn from: of a random draw of the frame (enough for ``steps`` after
        thinning), all those off the large flat surfaces and ``share`` of those on them; None
        for every row (no large surface known). A point is on a surface when its nearest node
        is, or, given ``prior`` ((N,) bool per point), when the prior says so."""
        on_surface = self._on_large_surface
        if on_surface is None or not on_surface.any() or on_surface.size != self.model_.n_nodes_:
            return None
        rows = np.arange(len(positions))
        draw = min(len(positions), int(ATTENTION_DRAW * steps))
        if draw < len(positions):
            # in scan order: each nearest-node search starts from the previous row's node
            rows = np.sort(self._rng.choice(len(positions), size=draw, replace=False))
        if prior is None:
            on_large = on_surface[self.model_.predict(positions[rows])]
        else:
            on_large = prior[rows]
        keep = ~on_large | (self._rng.random(rows.size) < share)
        return rows[keep]
