"""Camera tracking without given poses: each frame is aligned to the learned map.

A GNG-DT network learned in a fixed frame is a surface model: node positions, normals (eq. 16)
and colours (`gngdt.core.odometry.map_surface.MapSurface`). `MapOdometry.track` finds the camera
pose of a new depth frame by point-to-plane ICP against it (frame-to-model tracking, as KinectFusion
does against its volume):

- **data association**: each frame point (under the current pose estimate) is paired with its
  nearest node; the residual is the point's distance to the node's plane. Pairs farther than a
  level's gate, or whose normals (the frame's from its pixel neighbours, the node's from the
  map) differ by more than ``normal_angle_deg``, are not used;
- **coarse to fine**: each level takes every ``stride``-th pixel of every ``stride``-th row and
  a tighter gate; residuals are measured in the depth noise of their point (growing with depth
  squared), Huber-weighted;
- **node planes refined by the tracked frames** (`gngdt.core.odometry.node_planes`); each node is
  trusted by how many points its plane averages (young nodes in new territory count little), by
  how well they fit it, and in each frame by a Cauchy weight of its points' mean residual (a
  node whose points all lie off its plane is wrong as a whole);
- **colour as a tie-breaker**: each point's intensity against its node's, continued along the
  node's intensity gradient (Park et al. 2017), with a small weight, each residual in its own
  noise: it matters where geometry leaves a direction free (a textured floor);
- **degeneracy**: the system is solved only along directions it constrains (Zhang et al. 2016);
  others keep the prediction;
- **tracking loss**: a frame is lost (the pose is not updated, the caller must not learn from
  it) when too few points can be used, the map covers too little of the view, too few of the
  covered points agree with it, their residual is large, some direction stays unconstrained
  even with colour, or the estimate jumps implausibly far from the prediction.

The prediction is the last tracked pose moved on by the last motion between tracked frames
(constant velocity), continued over the time since the last tracked frame when frames carry
stamps: frames a busy learner dropped, or frames lost, do not leave it behind (for at most
``coast_s``). When the alignment from the prediction fails it is tried from the last
tracked pose, from a start searched around the prediction, then from starts over the whole map
(`gngdt.core.odometry.relocalise`: the motion continued over the whole gap, the poses the map
was learned from, ``keyframes``). The map's second frame, with no motion to go by (the camera
may have moved far while the first was learned), starts from the searched start. Parameters:
`TrackerParams` (a profile's ``[tracker]`` table). Kernels: `gngdt.core.kernels.odometry`.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from gngdt.core.kernels import odometry as OK
from gngdt.core.odometry.map_surface import MapSurface
from gngdt.core.odometry.node_planes import PlaneMemory
from gngdt.core.odometry.relocalise import retry_starts, searched_start
from gngdt.core.parameters import (
    Flag,
    Interval,
    Numbers,
    Settings,
    param,
)
from gngdt.core.sensor.geometry import rigid_inverse

#: why a frame was not tracked (``TrackingResult.reason``)
LOST_REASONS = ("no map", "too few points", "little overlap", "few inliers", "large residual",
                "degenerate", "implausible motion")

#: poses the map was learned from, kept for relocalisation (the latest, each at least
#: `KEYFRAME_SPACING_M` or `KEYFRAME_SPACING_DEG` from the one before)
KEYFRAMES = 32
KEYFRAME_SPACING_M = 0.1
KEYFRAME_SPACING_DEG = 10.0

_POSITIVE = Interval(float, 0.0, closed="neither")
_NON_NEGATIVE = Interval(float, 0.0)
_SHARE = Interval(float, 0.0, 1.0)


@dataclass(frozen=True)
class TrackerParams(Settings):
    """The camera tracker's settings (a profile's ``[tracker]`` table). Defaults were measured
    on the virtual Kinect's walk (see benchmarks/bench_tracking.py)."""

    WHAT: ClassVar[str] = "tracker parameter"

    strides: tuple[int, ...] = param((8, 4), Numbers(Interval(int, 1)),
                                     "per level, coarse to fine: every this many pixels of "
                                     "every this many rows")
    iterations: tuple[int, ...] = param((8, 6), Numbers(Interval(int, 0)),
                                        "per level: Gauss-Newton steps at most")
    gates_m: tuple[float, ...] = param((0.15, 0.05), Numbers(_POSITIVE),
                                       "per level: largest point-to-node distance of a pair, "
                                       "metres (at least gate_spacing node spacings)")
    gate_spacing: float = param(1.0, _NON_NEGATIVE,
                                "a level's gate is at least this many times the map's median "
                                "node spacing")
    depth_noise_m: float = param(0.0015, _POSITIVE,
                                 "depth noise (1 sigma) at 1 m, growing with depth squared "
                                 "(Kinect v1: 1.5 mm)")
    map_noise_m: float = param(0.002, _NON_NEGATIVE,
                               "the map's own noise, added in quadrature, metres")
    huber_sigma: float = param(1.5, _POSITIVE, "Huber weighting from this many sigmas")
    inlier_sigma: float = param(3.0, _POSITIVE, "a pair within this many sigmas is an inlier")
    normal_angle_deg: float = param(45.0, Interval(float, 0.0, 90.0),
                                    "largest angle between a point's and its node's normal")
    color_weight: float = param(0.1, _NON_NEGATIVE,
                                "weight of the colour residuals against the depth ones, each "
                                "in its own noise (0: geometry only)")
    color_sigma: float = param(0.03, _POSITIVE, "intensity noise (0..1)")
    min_constraint: float = param(0.002, _NON_NEGATIVE,
                                  "a direction is updated when the normalised system's "
                                  "eigenvalue along it reaches this; a frame left with a "
                                  "weaker one is lost (degenerate)")
    min_points: int = param(300, Interval(int, 6), "fewest usable points of a tracked frame")
    min_overlap: float = param(0.3, _SHARE,
                               "a tracked frame has at least this share of its points near "
                               "a node")
    min_inlier_share: float = param(0.6, _SHARE,
                                    "... and at least this share of those agreeing with it")
    max_chi: float = param(2.0, _POSITIVE, "... and its inliers' RMS residual at most this "
                                           "many sigmas")
    max_step_m: float = param(0.3, _POSITIVE,
                              "largest distance between estimate and prediction, metres")
    max_step_deg: float = param(20.0, Interval(float, 0.0, 180.0, closed="right"),
                                "largest rotation between estimate and prediction, degrees")
    converged_m: float = param(1e-4, _NON_NEGATIVE,
                               "a level stops once a step moves the points less than this")
    min_depth_m: float = param(0.3, _NON_NEGATIVE, "nearest depth used, metres")
    max_depth_m: float = param(6.0, _POSITIVE, "farthest depth used, metres")
    motion_model: bool = param(True, Flag(),
                               "predict with the last motion (constant velocity), else the "
                               "last pose")
    search_steps: int = param(3, Interval(int, 0),
                              "a frame with no motion known yet (the map's second), or whose "
                              "alignment from the prediction and the last pose failed, is "
                              "searched for from the prediction moved by 1..this many coarse "
                              "gates along each camera axis; 0: off")
    search_turn_deg: float = param(8.0, Interval(float, 0.0, 60.0),
                                   "... and turned by 1..search_steps times this about the "
                                   "camera's x and y axes, degrees (0: no turns)")
    relocalise: bool = param(True, Flag(),
                             "a frame lost from there too is looked for over the whole map: the "
                             "motion continued over the gap and to a few distances, and the "
                             "poses the map was learned from")
    coast_s: float = param(1.0, _NON_NEGATIVE,
                           "the last motion is continued over the time since the last tracked "
                           "frame (dropped or lost frames between), for at most this long or "
                           "the last motion's own span, seconds (frames without stamps: one "
                           "motion)")
    inverse_variance: bool = param(False, Flag(),
                                   "weight points by 1 / sigma^2 (else all alike)")
    plane_memory: int = param(200, Interval(int, 0),
                              "node planes refined from the tracked frames, a running mean "
                              "over at most this many points (0: off)")
    plane_reset_m: float = param(0.02, _POSITIVE,
                                 "a remembered plane farther than this from its node is "
                                 "forgotten, metres")
    maturity_points: float = param(50.0, _NON_NEGATIVE,
                                   "a node's weight is (points + 1) / (points + this), points "
                                   "averaged into its plane so far (0: off)")
    spread_weighting: bool = param(True, Flag(),
                                   "divide a node's weight by the mean squared normalised "
                                   "residual of its points about its plane")
    node_robust: float = param(3.0, _NON_NEGATIVE,
                               "Cauchy scale (sigmas of a node's mean residual) of a per-node "
                               "robust weight in each frame (0: off)")
    requery_m: float = param(0.002, _NON_NEGATIVE,
                             "nearest nodes are searched again once the points moved this far")

    def check(self) -> None:
        for name in ("strides", "iterations", "gates_m"):  # TOML gives lists
            object.__setattr__(self, name, tuple(getattr(self, name)))
        super().check()
        if not len(self.strides) == len(self.iterations) == len(self.gates_m):
            raise ValueError("tracker strides, iterations and gates_m need one entry per level, "
                             f"got {len(self.strides)}, {len(self.iterations)}, "
                             f"{len(self.gates_m)}")
        if self.max_depth_m <= self.min_depth_m:
            raise ValueError(f"tracker max_depth_m ({self.max_depth_m}) must exceed "
                             f"min_depth_m ({self.min_depth_m})")



@dataclass(frozen=True)
class TrackingResult:
    """One frame's alignment.

    pose: (4, 4) camera-to-map estimate (when lost: the prediction, not to be learned from);
    lost: the alignment failed, ``reason`` says why (one of ``LOST_REASONS``, "" when tracked);
    overlap: share of the final level's usable points with a node within the gate (the part of
    the view the map covers); inlier_share: share of those whose normal agrees with the node's
    and whose residual is within ``inlier_sigma`` sigmas; rms_m: RMS point-to-plane residual of
    the inliers, metres; constraint: smallest eigenvalue of the normalised final system
    (geometry and colour); geometry_constraint: the same for geometry alone; iterations:
    Gauss-Newton steps taken; points: usable points of the final level; seconds: time taken.
    """

    pose: np.ndarray
    lost: bool
    reason: str
    overlap: float
    inlier_share: float
    rms_m: float
    constraint: float
    geometry_constraint: float
    iterations: int
    points: int
    seconds: float

    @property
    def used_color(self) -> bool:
        """Colour constrained a direction geometry alone left (nearly) free."""
        return self.geometry_constraint < self.constraint


class MapOdometry:
    """Frame-to-map camera tracker (see the module docstring).

    ``MapOdometry(params, **overrides)``: `TrackerParams` (default: its defaults) with any of
    its fields overridden by keyword (validated there). Fitted state: ``pose_`` (4, 4) last
    tracked pose (None before `reset`), ``velocity_`` (4, 4) the motion between the last two
    tracked frames, ``motion_span_s_`` the seconds it took (0: unknown), ``stamp_ns_`` the last
    tracked frame's stamp (None: unknown), ``n_tracked_``, ``n_lost_``, ``last_`` (the last
    `TrackingResult`).
    """

    def __init__(self, params: TrackerParams | None = None, **overrides: Any) -> None:
        known = {item.name for item in fields(TrackerParams)}
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ValueError(f"unknown tracker parameter(s) {unknown}")
        self.params = replace(params or TrackerParams(), **overrides)
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self, pose: Any = None, stamp_ns: int | None = None) -> MapOdometry:
        """Start over at ``pose`` (4, 4) camera-to-map (None: not started: `track` then
        starts at the identity), the camera's pose at ``stamp_ns`` (if known)."""
        self.pose_ = None if pose is None else _checked_pose(pose)
        self.velocity_ = np.eye(4)
        self.motion_span_s_ = 0.0
        self.stamp_ns_ = stamp_ns
        self.n_tracked_ = 0
        self.n_lost_ = 0
        self.last_: TrackingResult | None = None
        self.planes = PlaneMemory(self.params.plane_memory, self.params.plane_reset_m)
        #: (4, 4) poses the map was learned from, spread over it (`remember_keyframe`)
        self.keyframes: deque[np.ndarray] = deque(maxlen=KEYFRAMES)
        return self

    def remember_keyframe(self, pose: np.ndarray) -> None:
        """A pose the map was learned from (kept when it is far enough from the last kept)."""
        if self.keyframes:
            moved, turned = OK.motion_size(self.keyframes[-1], pose)
            if moved < KEYFRAME_SPACING_M and turned < KEYFRAME_SPACING_DEG:
                return
        self.keyframes.append(np.array(pose, dtype=np.float64))

    def get_state(self) -> dict[str, np.ndarray]:
        """The fitted state as numpy arrays only (np.savez-safe, beside a model checkpoint)."""
        return {
            "pose": np.full((4, 4), np.nan) if self.pose_ is None else self.pose_.copy(),
            "velocity": self.velocity_.copy(),
            "stamp_ns": np.array([-1 if self.stamp_ns_ is None else self.stamp_ns_],
                                 dtype=np.int64),
            "motion_span_s": np.array([self.motion_span_s_]),
            "counters": np.array([self.n_tracked_, self.n_lost_], dtype=np.int64),
            "keyframes": np.array(list(self.keyframes)).reshape(-1, 4, 4),
            **self.planes.get_state(),
        }

    def set_state(self, state: dict[str, np.ndarray]) -> MapOdometry:
        """Continue from `get_state`'s arrays; ValueError when they do not fit together."""
        try:
            pose = np.asarray(state["pose"], dtype=np.float64)
            counters = np.asarray(state["counters"], dtype=np.int64).reshape(-1)
            if counters.shape != (2,) or np.any(counters < 0):
                raise ValueError("tracker state: counters must be two counts")
            self.planes.set_state(state)
            self.pose_ = None if np.isnan(pose).all() else _checked_pose(pose)
            self.velocity_ = _checked_pose(state["velocity"])
            # absent from older checkpoints: no stamp known, one motion per frame
            stamp = int(np.asarray(state.get("stamp_ns", [-1]), dtype=np.int64).reshape(-1)[0])
            span = float(np.asarray(state.get("motion_span_s", [0.0])).reshape(-1)[0])
            if not math.isfinite(span) or span < 0:
                raise ValueError("tracker state: motion_span_s must be a duration")
            self.stamp_ns_, self.motion_span_s_ = (None if stamp < 0 else stamp), span
            keyframes = np.asarray(state.get("keyframes", np.zeros((0, 4, 4))), dtype=np.float64)
            if keyframes.ndim != 3 or keyframes.shape[1:] != (4, 4):
                raise ValueError("tracker state: keyframes must be (K, 4, 4) poses")
            self.keyframes = deque((_checked_pose(pose) for pose in keyframes[-KEYFRAMES:]),
                                   maxlen=KEYFRAMES)
        except KeyError as error:
            raise ValueError(f"tracker state: no {error.args[0]!r}") from None
        self.n_tracked_, self.n_lost_ = int(counters[0]), int(counters[1])
        self.last_ = None
        return self

    def predict(self, stamp_ns: int | None = None) -> np.ndarray:
        """(4, 4) the pose expected for the next frame (taken at ``stamp_ns``, if known)."""
        pose = np.eye(4) if self.pose_ is None else self.pose_
        if not self.params.motion_model:
            return pose.copy()
        return pose @ OK.scaled_motion(self.velocity_, self._motions_since(stamp_ns))

    def _motions_since(self, stamp_ns: int | None) -> float:
        """How many of the last motion fit between the last tracked frame and ``stamp_ns``
        (one when either stamp is unknown), the time capped by ``coast_s``."""
        if stamp_ns is None or self.stamp_ns_ is None or self.motion_span_s_ <= 0:
            return 1.0
        elapsed = self.seconds_since(stamp_ns)
        return min(elapsed, max(self.params.coast_s, self.motion_span_s_)) / self.motion_span_s_

    def seconds_since(self, stamp_ns: int | None) -> float:
        """Seconds from the last tracked frame's stamp to ``stamp_ns`` (0 when either is
        unknown, or it is not later)."""
        if stamp_ns is None or self.stamp_ns_ is None:
            return 0.0
        return max(0.0, (stamp_ns - self.stamp_ns_) * 1e-9)

    # ------------------------------------------------------------------ tracking

    @property
    def pixel_stride(self) -> int:
        """The finest pixel spacing the levels look at (the strides' greatest common divisor):
        `track` may be given only those pixels (``stride``)."""
        return math.gcd(*self.params.strides)

    def track(self, points: np.ndarray, colors: np.ndarray | None, surface: MapSurface,
              initial_pose: np.ndarray | None = None,
              stamp_ns: int | None = None, stride: int = 1) -> TrackingResult:
        """Align one frame to ``surface`` and, when tracked, make it the current pose.

        points: (H, W, 3) organized cloud, camera frame (x right, y down, z forward), metres,
        NaN where there is no depth; colors: (H, W, 3) RGB 0..255 registered to it, or None;
        initial_pose: (4, 4) start of the search instead of the prediction; stamp_ns: the
        frame's capture time, nanoseconds (the prediction covers the time since the last
        tracked frame); stride: ``points`` and ``colors`` hold only every stride-th row and
        column of the image (a divisor of `pixel_stride`).
        """
        started = time.perf_counter()
        prediction = (self.predict(stamp_ns) if initial_pose is None
                      else _checked_pose(initial_pose))
        if points.ndim != 3 or points.shape[2] != 3:
            raise ValueError(f"points must be an organized (H, W, 3) cloud, got {points.shape}")
        if colors is not None and colors.shape[:2] != points.shape[:2]:
            raise ValueError(f"colors {colors.shape} do not match points {points.shape}")
        if len(surface) < 3:
            return self._finish(prediction, prediction, "no map", started, {}, stamp_ns)
        if self.pixel_stride % stride:
            raise ValueError(f"stride {stride} does not divide the levels' {self.pixel_stride}")
        levels = [self._level_points(points, colors, level, stride)
                  for level in self.params.strides]
        searched = initial_pose is None and self.n_tracked_ == 0 and self.params.search_steps
        start = searched_start(self, levels[0], surface, prediction) if searched else prediction
        pose, reason, stats = self.align(levels, surface, start)
        if reason and reason != "too few points" and initial_pose is None:
            for retry_start in retry_starts(self, levels[0], surface, prediction, searched,
                                            stamp_ns):
                retry = self.align(levels, surface, retry_start)
                if not retry[1]:
                    pose, reason, stats = retry
                    break
        if not reason and self.params.plane_memory and surface.ids is not None:
            self.planes.remember(surface.positions, surface.normals, surface.ids,
                                 stats["planes"], stats["inlier_nodes"],
                                 stats["inlier_residuals"], stats["inlier_sigmas"])
        return self._finish(prediction, pose, reason, started, stats, stamp_ns)

    def align(self, levels: list[tuple], surface: MapSurface, start: np.ndarray,
               max_steps: int | None = None) -> tuple[np.ndarray, str, dict[str, Any]]:
        """Coarse-to-fine ICP from ``start`` (4, 4) over ``levels`` (`_level_points`' each,
        coarse first; fewer than the parameters' levels: the first ones only), each with at
        most ``max_steps`` Gauss-Newton steps (None: its own): the pose found, why it is not to
        be trusted ("" when it is) and its statistics."""
        p = self.params
        planes = self.planes.anchors(surface.positions, surface.normals, surface.ids,
                                     start[:3, 3])
        trust = self._trust(surface, planes)
        pose, stats, iterations = start.copy(), {}, 0
        for frame, steps, gate_m in zip(levels, p.iterations, p.gates_m, strict=False):
            steps = steps if max_steps is None else min(steps, max_steps)
            if len(frame[0]) < p.min_points:
                return pose, "too few points", dict(stats, points=len(frame[0]),
                                                    iterations=iterations)
            gate = max(gate_m, p.gate_spacing * surface.spacing)
            pose, pairing, drift, done = self._level(frame, surface, planes[0], trust, pose,
                                                     gate, steps)
            iterations += done
        _, stats = self._iterate(frame, surface, planes[0], trust, pose, gate, False,
                                 pairing if drift <= p.requery_m else None)
        stats["iterations"], stats["planes"] = iterations, planes
        return pose, self._judge(stats, start, pose), stats

    def _trust(self, surface: MapSurface, planes: tuple[np.ndarray, ...]) -> np.ndarray:
        """(N,) each node's weight: the surface's, times (after two tracked frames) its plane's
        maturity and the inverse of its spread (a node straddling an edge gets points of two
        faces: a wide spread)."""
        p = self.params
        _, counts, spread, _ = planes
        trust = (np.ones(len(surface)) if surface.weights is None
                 else surface.weights.copy())
        if p.plane_memory and self.n_tracked_ > 1:
            if p.maturity_points:
                trust *= (counts + 1.0) / (counts + p.maturity_points)
            if p.spread_weighting:
                trust /= np.maximum(spread, 1.0)
        return trust

    def _level(self, frame: tuple, surface: MapSurface, anchors: np.ndarray,
               trust: np.ndarray, pose: np.ndarray, gate: float, steps: int
               ) -> tuple[np.ndarray, Any, float, int]:
        """Up to ``steps`` Gauss-Newton steps of one level from ``pose``; (the pose, the last
        pairing, how far the points moved since it was searched, steps taken)."""
        pairing, drift, done = None, 0.0, 0
        for _ in range(steps):
            if drift > self.params.requery_m:
                pairing = None  # the points moved: search their nearest nodes again
            step, stats = self._iterate(frame, surface, anchors, trust, pose, gate, True,
                                        pairing)
            if pairing is None:
                pairing, drift = stats["pairing"], 0.0
            pose = step @ pose
            done += 1
            centre = stats["centre"]
            moved = (np.linalg.norm(step[:3, :3] @ centre + step[:3, 3] - centre)
                     + stats["scale"] * math.radians(OK.rotation_angle_deg(step[:3, :3])))
            drift += moved
            if moved < self.params.converged_m:
                break
        return pose, pairing, drift, done

    def _level_points(self, points: np.ndarray, colors: np.ndarray | None, stride: int,
                      given_stride: int = 1
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
        """A level's usable points (M, 3), their normals (M, 3), intensities (M,) or None and
        depth noise (M,) metres: every ``stride``-th pixel (of ``points``, which hold every
        ``given_stride``-th), within the depth range, with a normal."""
        p = self.params
        step = stride // given_stride
        grid = points[::step, ::step]
        normals = OK.organized_normals(grid, max_jump=0.05 * stride)
        z = grid[..., 2]
        with np.errstate(invalid="ignore"):
            usable = ((z >= p.min_depth_m) & (z <= p.max_depth_m)
                      & np.isfinite(normals[..., 0]))
        rows = np.flatnonzero(usable.ravel())
        flat = grid.reshape(-1, 3).astype(np.float64)[rows]
        intensity = None
        if colors is not None and p.color_weight > 0:
            intensity = OK.intensities(colors[::step, ::step].reshape(-1, 3)[rows])
        sigma = np.sqrt((p.depth_noise_m * flat[:, 2] ** 2) ** 2 + p.map_noise_m ** 2)
        return flat, normals.reshape(-1, 3)[rows], intensity, sigma

    def _iterate(self, frame: tuple, surface: MapSurface, anchors: np.ndarray,
                 trust: np.ndarray, pose: np.ndarray, gate: float, solve: bool,
                 pairing: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, dict[str, Any]]:
        """Pair the frame's points with nodes under ``pose`` (or keep ``pairing``: nearest node
        and whether it is within the gate, per point), build the system; with ``solve``, the
        update (4, 4) that moves the frame's map-frame points. Returns it and statistics."""
        p = self.params
        points, normals, intensity, sigma = frame
        rotation, translation = pose[:3, :3], pose[:3, 3]
        if pairing is None:
            node, distance = surface.nearest(points @ rotation.T + translation)
            pairing = (np.maximum(node, 0), (distance <= gate) & (node >= 0))
        node, gated = pairing
        m = len(points)
        world, residual, weight = np.empty((m, 3)), np.empty(m), np.empty(m)
        inliers = np.empty(m, dtype=np.bool_)
        hessian, gradient = np.zeros((6, 6)), np.zeros(6)
        centre, scale, total, _ = OK.point_to_plane(
            points, normals, sigma, np.ascontiguousarray(rotation), translation, node, gated,
            anchors, surface.normals, trust, math.cos(math.radians(p.normal_angle_deg)),
            p.huber_sigma, p.inlier_sigma, p.node_robust, p.map_noise_m, p.inverse_variance,
            world, residual, weight, inliers, hessian, gradient)
        total = max(total, 1e-12)
        geometry = hessian / total
        system, rhs = geometry.copy(), gradient / total
        if (intensity is not None and surface.intensity is not None and p.color_weight > 0
                and inliers.any()):
            color_system, color_rhs = self._color_system(world, intensity, sigma, surface,
                                                         anchors, node, inliers, weight,
                                                         centre)
            system += color_system / total
            rhs += color_rhs / total
        stats: dict[str, Any] = {"centre": centre, "scale": max(scale, 1e-6), "points": m,
                                 "pairing": pairing}
        step = np.eye(4)
        if solve:  # a step on the way: the judgement's statistics are the last pass's alone
            xi, stats["constraint"] = OK.constrained_step(system, rhs, stats["scale"],
                                                          p.min_constraint)
            step = OK.update_about(xi, centre)
        else:
            chi = residual[inliers] / sigma[inliers]
            stats.update({
                "overlap": float(gated.mean()) if m else 0.0,
                "inlier_share": float(inliers.sum() / max(gated.sum(), 1)),
                "rms_m": (float(np.sqrt(np.mean(residual[inliers] ** 2))) if inliers.any()
                          else math.inf),
                "chi": float(np.sqrt(np.mean(chi ** 2))) if inliers.any() else math.inf,
                "inlier_nodes": node[inliers], "inlier_residuals": residual[inliers],
                "inlier_sigmas": sigma[inliers]})
            s = np.array([stats["scale"]] * 3 + [1.0] * 3)
            stats["constraint"] = float(np.linalg.eigvalsh(system / np.outer(s, s))[0])
            stats["geometry_constraint"] = float(
                np.linalg.eigvalsh(geometry / np.outer(s, s))[0])
        return step, stats

    def _color_system(self, world: np.ndarray, intensity: np.ndarray, sigma: np.ndarray,
                      surface: MapSurface, anchors: np.ndarray, node: np.ndarray,
                      inliers: np.ndarray, weight: np.ndarray, centre: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """The colour residuals' system (6, 6) and gradient (6,), scaled so that a residual of
        ``color_sigma`` counts as much as a depth residual of the frame's typical sigma, times
        ``color_weight``."""
        p = self.params
        offsets = surface.intensity[node] - intensity
        offsets -= np.median(offsets[inliers])  # exposure: up to the frame's median offset
        hessian, gradient = np.zeros((6, 6)), np.zeros(6)
        OK.normal_equations(world, node, anchors, surface.gradients, offsets, weight, inliers,
                            centre, p.huber_sigma * p.color_sigma, hessian, gradient)
        factor = p.color_weight * (float(np.median(sigma[inliers])) / p.color_sigma) ** 2
        return factor * hessian, factor * gradient

    def _judge(self, stats: dict[str, Any], prediction: np.ndarray, pose: np.ndarray) -> str:
        """Why the final alignment is not to be trusted ("" when it is)."""
        p = self.params
        if stats["overlap"] < p.min_overlap:
            return "little overlap"
        if stats["inlier_share"] < p.min_inlier_share:
            return "few inliers"
        if stats["chi"] > p.max_chi:
            return "large residual"
        if stats["constraint"] < p.min_constraint:
            return "degenerate"
        moved, turned = OK.motion_size(prediction, pose)
        if moved > p.max_step_m or turned > p.max_step_deg:
            return "implausible motion"
        return ""

    def _finish(self, prediction: np.ndarray, pose: np.ndarray, reason: str, started: float,
                stats: dict[str, Any], stamp_ns: int | None) -> TrackingResult:
        lost = bool(reason)
        if lost:  # the motion is kept: the next frame is predicted over the time since
            self.n_lost_ += 1
        else:
            pose = OK.orthonormalised(pose)
            if self.pose_ is not None:
                self.velocity_ = rigid_inverse(self.pose_) @ pose
                self.motion_span_s_ = self.seconds_since(stamp_ns)
            self.pose_, self.stamp_ns_ = pose, stamp_ns
            self.n_tracked_ += 1
        result = TrackingResult(
            pose=prediction if lost else pose.copy(), lost=lost, reason=reason,
            overlap=float(stats.get("overlap", 0.0)),
            inlier_share=float(stats.get("inlier_share", 0.0)),
            rms_m=float(stats.get("rms_m", math.inf)),
            constraint=float(stats.get("constraint", 0.0)),
            geometry_constraint=float(stats.get("geometry_constraint", 0.0)),
            iterations=int(stats.get("iterations", 0)), points=int(stats.get("points", 0)),
            seconds=time.perf_counter() - started)
        self.last_ = result
        return result


def _checked_pose(pose: Any) -> np.ndarray:
    """(4, 4) float64 rigid transform; ValueError otherwise."""
    matrix = np.asarray(pose, dtype=np.float64)
    if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise ValueError(f"a pose must be a finite (4, 4) matrix, got shape {matrix.shape}")
    rotation = matrix[:3, :3]
    if (np.abs(rotation.T @ rotation - np.eye(3)).max() > 1e-6
            or np.abs(matrix[3] - [0, 0, 0, 1]).max() > 1e-9
            or np.linalg.det(rotation) < 0):
        raise ValueError("a pose must be rigid: an orthonormal rotation with det +1 and last row "
                         "(0, 0, 0, 1)")
    return matrix.copy()
