"""Metrics over time for a moving camera and a changing scene, per replayed frame.

- **ghost share**: of the nodes the sensor could have seen in the frame (in view, not behind the
  measured surface; `gngdt.core.sensor.view`), the share farther than ``ghost_distance_m`` from
  every point of the frame (`gngdt.core.metrics.ghost_nodes`): places the sensor looked at and found
  empty. **stale share**: of all nodes, the share farther than that from the frame's points
  (the issue's measure; in a world-frame map, out-of-view nodes count as stale although they are
  right).
- **the world so far** (recordings with poses): a sample of every frame's points in the fixed
  frame, thinned to ``world_sample`` points (each frame adds the same number, old points are
  dropped at random) and emptied wherever a later frame sees through a point (its pixel measured
  a surface more than ``FREE_SPACE_MARGIN`` of the depth farther). On it: the position error
  (eq. 17) against k-means with as many centres as nodes, every ``reference_every`` frames;
  k-means is fitted on half of the sample and both errors are measured on the other half, since
  with ~20 points a centre k-means fitted and scored on the same points would be scored on
  points it has overfitted, which the network never saw. Also the position error of the nodes
  on its points out of the current
  view (off the image or occluded) beside that on its points in view, and the **out-of-view
  nodes**: nodes the sensor could not see in the frame that lie within ``ghost_distance_m`` of
  the world sample, the map kept where the camera is not looking.
- **changes** (synthetic recordings, from their ``gngdt.scene`` metadata): for each object that
  vanishes or moves, its former place is its points in the frame before the change; once it has
  vanished, or finished moving, the **old-place nodes** are the nodes within
  ``ghost_distance_m`` of it and farther than that from the current frame's points; **frames
  until gone** counts frames from then to the first frame without any.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gngdt.core.clustering import POS
from gngdt.core.gas.model import GNGDT
from gngdt.core.learner.frame_learner import LearnerOptions

#: a point of the world sample is seen through (and dropped) when the current frame measures a
#: surface this fraction of the depth behind it (5 %: 10 cm at 2 m, well above Kinect noise)
FREE_SPACE_MARGIN = 0.05


@dataclass
class CameraView:
    """One frame as the camera saw it: depth (H, W) metres (0 = none), intrinsics, and the
    camera-to-world pose (4, 4)."""

    depth_m: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    world_from_camera: np.ndarray

    def project(self, world_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(measured depth at each point's pixel (0 = off the image or none), the point's own
        depth), both (N,) metres."""
        pose = self.world_from_camera
        camera = (world_points - pose[:3, 3]) @ pose[:3, :3]
        z = camera[:, 2]
        height, width = self.depth_m.shape
        measured = np.zeros(len(world_points))
        ahead = z > 1e-6
        u = np.full(len(z), -1)
        v = np.full(len(z), -1)
        u[ahead] = np.floor(self.fx * camera[ahead, 0] / z[ahead] + self.cx + 0.5).astype(int)
        v[ahead] = np.floor(self.fy * camera[ahead, 1] / z[ahead] + self.cy + 0.5).astype(int)
        inside = ahead & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        measured[inside] = self.depth_m[v[inside], u[inside]]
        return measured, z

    def in_view(self, world_points: np.ndarray) -> np.ndarray:
        """(N,) bool: on the image, on a measured pixel, and not behind the surface measured."""
        measured, z = self.project(world_points)
        return (measured > 0) & (z <= measured * (1.0 + FREE_SPACE_MARGIN))

    def seen_through(self, world_points: np.ndarray) -> np.ndarray:
        """(N,) bool: points in front of the measured surface by more than the margin."""
        measured, z = self.project(world_points)
        return (measured > 0) & (z < measured * (1.0 - FREE_SPACE_MARGIN))


class WorldSample:
    """A bounded random sample of the points seen so far, in the fixed frame, kept current."""

    def __init__(self, size: int, seed: int = 0) -> None:
        self.size = size
        self.points = np.zeros((0, 3))
        self._rng = np.random.default_rng(seed)

    def update(self, world_points: np.ndarray, view: CameraView, frames_seen: int) -> None:
        """Drop points the view sees through, add a share of this frame's points, thin."""
        if len(self.points):
            self.points = self.points[~view.seen_through(self.points)]
        # every frame contributes about size / frames so far points: the sample stays uniform
        # over time until it is full, then new frames replace random old points
        count = min(len(world_points), max(self.size // max(frames_seen, 1), 1))
        chosen = world_points[self._rng.choice(len(world_points), size=count, replace=False)]
        self.points = np.concatenate([self.points, chosen])
        if len(self.points) > self.size:
            keep = self._rng.choice(len(self.points), size=self.size, replace=False)
            self.points = self.points[np.sort(keep)]


@dataclass
class Change:
    """One object that vanishes or moves (from the recording's scene metadata)."""

    primitive: str
    kind: str
    start_frame: int
    #: the first frame the object is wholly elsewhere (the start for a vanish, the end of a move)
    settled_frame: int
    segment_ids: list[int]
    old_place: np.ndarray | None = None
    #: frame index -> old-place nodes
    counts: dict[int, int] = field(default_factory=dict)

    def frames_until_gone(self) -> int | None:
        """Frames from ``settled_frame`` to the first frame with no old-place node (None:
        not within the run)."""
        for frame in sorted(self.counts):
            if self.counts[frame] == 0:
                return frame - self.settled_frame
        return None


def scene_changes(metadata: dict[str, dict[str, str]]) -> list[Change]:
    """The changes a synthetic recording's ``gngdt.scene`` metadata describes (none if absent)."""
    from gngdt.io.synth.render import SCENE_METADATA

    scene = metadata.get(SCENE_METADATA)
    if not scene:
        return []
    segments = {int(key): name for key, name in json.loads(scene["segments"]).items()}
    return [
        Change(
            primitive=motion["primitive"],
            kind=motion["kind"],
            start_frame=int(motion["start_frame"]),
            settled_frame=int(motion["end_frame"] if motion["kind"] == "move"
                              else motion["start_frame"]),
            segment_ids=[i for i, name in segments.items()
                         if name.split("/")[0] == motion["primitive"]],
        )
        for motion in json.loads(scene["motions"])
    ]


@dataclass(frozen=True)
class DynamicsSettings:
    """What the metrics over time measure with."""

    #: a node this far (metres) from every point of a frame is a ghost / stale, as the learner's
    #: status measures it
    ghost_distance_m: float = LearnerOptions.ghost_distance_m
    #: depth tolerance of "could have seen", as the model's default
    view_depth_margin: float = GNGDT.view_depth_margin
    #: points kept in the world sample (half fit k-means, half score both)
    world_sample: int = 40_000
    #: k-means on the world sample every this many frames (and on the last)
    reference_every: int = 10


class DynamicsTracker:
    """The metrics over time of one replay (see the module docstring)."""

    def __init__(self, settings: DynamicsSettings, changes: list[Change], posed: bool) -> None:
        self.settings = settings
        self.changes = changes
        self.world = WorldSample(settings.world_sample) if posed else None
        self.frames_seen = 0

    def before_learning(self, index: int, world_points: np.ndarray,
                        labels: np.ndarray | None) -> None:
        """Remember each changing object's place in the frame before its change."""
        for change in self.changes:
            if labels is not None and index < change.start_frame:
                mine = np.isin(labels, change.segment_ids)
                if mine.any():
                    change.old_place = world_points[mine]

    def after_learning(self, model: Any, index: int, camera_points: np.ndarray,
                       world_points: np.ndarray, pose: np.ndarray | None,
                       view: CameraView | None) -> dict[str, Any]:
        """The frame's metrics once ``model`` has learned it."""
        from scipy.spatial import cKDTree

        from gngdt.core.metrics import ghost_nodes

        s = self.settings
        self.frames_seen += 1
        nodes = np.asarray(model.positions_)
        seen, ghost = ghost_nodes(nodes, camera_points, pose, s.ghost_distance_m,
                                  s.view_depth_margin)
        nearest, _ = cKDTree(world_points).query(nodes, k=1)
        stale = nearest > s.ghost_distance_m
        record: dict[str, Any] = {
            "seen_nodes": int(seen.sum()),
            "ghost_nodes": int(ghost.sum()),
            "ghost_share": float(ghost.sum() / seen.sum()) if seen.any() else 0.0,
            "stale_share": float(stale.mean()) if len(nodes) else 0.0,
            "forgotten": int(getattr(model, "n_forgotten_", 0)),
        }
        for change in self.changes:
            if index >= change.settled_frame and change.old_place is not None:
                near_old = cKDTree(change.old_place).query(nodes, k=1)[0] <= s.ghost_distance_m
                change.counts[index] = int(np.sum(near_old & stale))
                record[f"old_place_nodes/{change.primitive}"] = change.counts[index]
        if self.world is not None and view is not None and len(nodes):
            self.world.update(world_points, view, self.frames_seen)
            sample = self.world.points
            to_node = cKDTree(nodes).query(sample, k=1)[0]
            outside = ~view.in_view(sample)
            for name, chosen in (("out_of_view", outside), ("in_view", ~outside)):
                if chosen.any():
                    record[f"{name}_qe_pos"] = float(np.sqrt(np.mean(to_node[chosen] ** 2)))
            on_surface = cKDTree(sample).query(nodes, k=1)[0] <= s.ghost_distance_m
            record["out_of_view_nodes"] = int(np.sum(on_surface & ~seen))
        return record

    def world_reference(self, model: Any) -> dict[str, float]:
        """Position error (eq. 17) of the nodes and of k-means with as many centres on the
        world sample, k-means fitted on the other half of it; empty without poses."""
        from gngdt.eval.baselines import kmeans_reference, quantization_error

        nodes = np.asarray(model.positions_)
        sample = self.world.points if self.world is not None else np.zeros((0, 3))
        if len(sample) < 4 * len(nodes) or len(nodes) == 0:
            return {}
        order = np.random.default_rng(len(sample)).permutation(len(sample))
        fit, held_out = sample[order[::2]], sample[order[1::2]]
        kmeans = kmeans_reference(fit, None, len(nodes), fit_points=len(fit))
        theirs = quantization_error(held_out, None, kmeans.positions, None)[POS]
        ours = quantization_error(held_out, None, nodes, None)[POS]
        return {
            "world_qe_pos": ours,
            "world_kmeans_qe_pos": theirs,
            "world_ratio_to_kmeans": ours / theirs,
        }

    def summary(self) -> dict[str, Any]:
        """Per change: frames until its old-place nodes were gone (None: not within the run)."""
        return {
            change.primitive: {
                "kind": change.kind,
                "start_frame": change.start_frame,
                "settled_frame": change.settled_frame,
                "frames_until_gone": change.frames_until_gone(),
                "old_place_nodes_at_change": change.counts.get(change.settled_frame),
            }
            for change in self.changes
        }
