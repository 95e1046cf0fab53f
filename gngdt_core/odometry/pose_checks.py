"""Checks of camera poses: within bounds, moving as a camera can, agreeing with the depth.

A camera pose (a (4, 4) camera-to-world transform) places a frame's points in a fixed frame. A
wrong one (quaternions in another order, a world-to-camera transform, millimetres read as
metres, a forged or absurd value) wrecks a map silently: every pose looks valid on its own. So
each posed frame is checked, in this order, by `PoseChecker`:

1. bounds: the camera within the workspace, a box of half-size ``workspace_m`` around the
   fixed frame's origin (``workspace_around="origin"``: the first pose too) or around the first
   accepted camera (``"first-camera"``: a map frame whose origin is anywhere), its rotation
   orthonormal (within ``rotation_tolerance``) and proper;
2. motion: from the last accepted frame, no faster than ``max_speed_m_s`` and
   ``max_turn_deg_s`` (by the frames' stamps, at least ``MIN_INTERVAL_S`` apart), and however
   long ago it was, no farther than ``max_speed_m_s`` times ``MAX_INTERVAL_S`` (a 100 m jump
   25 s after the last accepted frame is not a camera's move, it is a forged pose). A camera
   that really moved farther while no frame came is followed once ``REANCHOR_FRAMES`` frames
   in a row, refused for their motion alone, move as a camera can from one to the next;
3. depth: the frame's points, placed by its pose, against the surfaces of an earlier accepted
   frame (the reference: its points with normals, in the fixed frame): of the points that
   overlap it (a reference point within ``OVERLAP_DEPTH_SHARE`` of their depth), the median
   point-to-plane distance as a share of the depth must stay within ``max_residual``. The
   reference is renewed when an accepted frame overlaps it by less than ``RENEW_OVERLAP``.

Why an earlier frame and not the learned map: a map follows what it learns, so a pose error
that grows a little every frame (a wrong quaternion order on a slow camera) would move the map
with it and never contradict it; against an earlier frame the error grows with every frame
until it shows. Measured on the virtual walk and on real TUM fr1_xyz frames: right poses give
0.2-0.5 % of the depth (sensor noise), w,x,y,z quaternions 1-3 %, inverted transforms 0.7-2.6 %.
A frame overlapping the reference too little to judge (a new view) is accepted.

`POSE_MISREADINGS` are the usual ways a pose file is misread; a caller that sees its poses
rejected tries them to say which one it probably is. Pure computation on arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from gngdt.core.parameters import Interval, OneOf, Settings, param
from gngdt.core.sensor.geometry import apply_pose, matrix_to_pose, pose_to_matrix, rigid_inverse

__all__ = [
    "POSE_MISREADINGS",
    "PoseAudit",
    "PoseChecker",
    "PoseLimits",
    "PoseVerdict",
    "SurfaceReference",
    "bounds_problem",
    "motion_problem",
    "points_beyond_workspace",
]

#: two frames are taken as at least this far apart in time (stamps jitter; a camera that sends
#: two frames with one stamp still moves between them)
MIN_INTERVAL_S = 0.1
#: and at most this far: the farthest a camera may be from the last accepted frame is its top
#: speed times this, however long ago that frame was
MAX_INTERVAL_S = 1.0
#: frames in a row, refused only for moving too far from the last accepted one but moving as a
#: camera can from one to the next, after which the camera is followed there (a real move
#: while no frame came); their depth is checked against a new reference from then on
REANCHOR_FRAMES = 5
#: where the workspace box is centred
WORKSPACE_AROUND = ("origin", "first-camera")
#: points of a frame kept as a reference, and points of a frame checked against it
REFERENCE_POINTS = 5_000
CHECKED_POINTS = 3_000
#: neighbours whose spread gives a reference point's normal
NORMAL_NEIGHBOURS = 12
#: a checked point overlaps the reference when a reference point lies within this share of its
#: depth (5 cm at 1 m)
OVERLAP_DEPTH_SHARE = 0.05
#: a frame is judged only when at least this share of its points overlaps the reference
MIN_OVERLAP = 0.2
#: a pose that puts at least this share of the reference in view must overlap it by
#: ``MIN_OVERLAP``: else the camera should see surfaces it does not
EXPECTED_OVERLAP = 0.5
#: an accepted frame overlapping the reference by less than this becomes the reference
RENEW_OVERLAP = 0.5
#: fewest points that make a reference or a judgement
MIN_POINTS = 50


@dataclass(frozen=True)
class PoseLimits(Settings):
    """What a camera pose may be (validated); every check of `PoseChecker` uses these."""

    WHAT: ClassVar[str] = "pose limit"

    workspace_m: float = param(1000.0, Interval(float, 0.0, closed="neither"),
                               "a camera farther than this along any axis from the workspace's "
                               "centre (metres; workspace_around) has a wrong pose")
    workspace_around: str = param("origin", OneOf(WORKSPACE_AROUND),
                                  "the workspace box's centre: the fixed frame's origin (which "
                                  "bounds the first pose too), or the first accepted camera")
    rotation_tolerance: float = param(1e-3, Interval(float, 0.0, 0.1, closed="right"),
                                      "largest entry of R R^T - I of a pose's rotation")
    max_speed_m_s: float = param(10.0, Interval(float, 0.0, closed="neither"),
                                 "fastest camera move between two frames, metres per second")
    max_turn_deg_s: float = param(360.0, Interval(float, 0.0, closed="neither"),
                                  "fastest camera turn between two frames, degrees per second")
    max_residual: float = param(0.01, Interval(float, 0.0, 1.0, closed="right"),
                                "a posed frame whose points lie farther than this share of "
                                "their depth from an earlier frame's surfaces (median, point "
                                "to plane; 0.01: 2 cm at 2 m) contradicts its depth")


@dataclass(frozen=True)
class PoseVerdict:
    """One frame's check: ``problem`` is "" when the pose was accepted, else why not;
    ``residual`` the median point-to-plane distance as a share of the depth and ``overlap`` the
    share of points judged (None: not judged against the depth)."""

    problem: str = ""
    residual: float | None = None
    overlap: float | None = None

    @property
    def accepted(self) -> bool:
        return not self.problem


def bounds_problem(pose: np.ndarray, limits: PoseLimits,
                   centre: np.ndarray | None = None) -> str:
    """Why ``pose`` (4, 4) is out of bounds, or "" (see `PoseLimits`); ``centre`` (3,): the
    workspace box's (default the origin)."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4) or not np.isfinite(pose).all():
        return f"the pose is not a finite 4x4 transform (shape {pose.shape})"
    offset = pose[:3, 3] - (np.zeros(3) if centre is None else centre)
    farthest = float(np.abs(offset).max())
    if farthest > limits.workspace_m:
        around = "the fixed frame's origin" if centre is None else "the first camera"
        return (f"the camera is {farthest:.3g} m from {around} along an axis, beyond the "
                f"workspace of {limits.workspace_m:g} m")
    rotation = pose[:3, :3]
    deviation = float(np.abs(rotation @ rotation.T - np.eye(3)).max())
    last_row = float(np.abs(pose[3] - (0.0, 0.0, 0.0, 1.0)).max())
    if max(deviation, last_row) > limits.rotation_tolerance or np.linalg.det(rotation) < 0:
        return (f"the rotation is not orthonormal and proper (R R^T differs from I by "
                f"{deviation:.2g}, tolerance {limits.rotation_tolerance:g})")
    return ""


def turn_angle_deg(first: np.ndarray, second: np.ndarray) -> float:
    """Angle (degrees) of the rotation between two poses' rotations."""
    relative = first[:3, :3].T @ second[:3, :3]
    cosine = (np.trace(relative) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, float(cosine)))))


def motion_problem(previous: np.ndarray, previous_ns: int | None, pose: np.ndarray,
                   stamp_ns: int | None, limits: PoseLimits) -> str:
    """Why the move from ``previous`` to ``pose`` (both (4, 4)) is faster or farther than a
    camera moves, or ""; stamps in nanoseconds (None: ``MIN_INTERVAL_S`` apart)."""
    seconds = MIN_INTERVAL_S
    if previous_ns is not None and stamp_ns is not None:
        seconds = max(abs(stamp_ns - previous_ns) * 1e-9, MIN_INTERVAL_S)
    moved = float(np.linalg.norm(pose[:3, 3] - previous[:3, 3]))
    if moved > limits.max_speed_m_s * seconds:
        return (f"the camera moved {moved:.3g} m in {seconds:.3g} s since the last accepted "
                f"frame, faster than {limits.max_speed_m_s:g} m/s")
    farthest = limits.max_speed_m_s * MAX_INTERVAL_S
    if moved > farthest:
        return (f"the camera moved {moved:.3g} m since the last accepted frame ({seconds:.3g} s "
                f"ago), farther than the {farthest:g} m it may move between two frames "
                f"({limits.max_speed_m_s:g} m/s for at most {MAX_INTERVAL_S:g} s)")
    turned = turn_angle_deg(previous, pose)
    if turned > limits.max_turn_deg_s * seconds:
        return (f"the camera turned {turned:.0f} degrees in {seconds:.3g} s since the last "
                f"accepted frame, faster than {limits.max_turn_deg_s:g} degrees/s")
    return ""


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """About ``count`` of ``points`` (N, 3), evenly spread over the array, as float64."""
    stride = max(1, len(points) // count)
    return np.asarray(points[::stride][:count], dtype=np.float64)


def _in_front(points: np.ndarray) -> np.ndarray:
    """The rows of camera-frame ``points`` that are finite and in front of the camera."""
    keep = np.isfinite(points).all(axis=1) & (points[:, 2] > 1e-6)
    return points[keep]


@dataclass(frozen=True)
class Comparison:
    """A frame against a reference: ``overlap`` the share of its points with a reference point
    within ``OVERLAP_DEPTH_SHARE`` of their depth; ``in_view`` the share of the reference's
    points its pose puts in its field of view; ``residual`` the median point-to-plane distance
    of the overlapping points as a share of their depth (None: too few overlap)."""

    overlap: float
    in_view: float
    residual: float | None


@dataclass
class SurfaceReference:
    """An accepted frame's surfaces in the fixed frame: points (M, 3) float64 metres, their
    unit normals (M, 3) and a k-d tree over the points."""

    points: np.ndarray
    normals: np.ndarray
    tree: object = field(repr=False)

    @classmethod
    def of(cls, camera_points: np.ndarray, pose: np.ndarray) -> SurfaceReference | None:
        """The reference made of a frame (camera-frame points, its pose); None with too few
        points."""
        from scipy.spatial import cKDTree

        points = _in_front(_spread(camera_points, REFERENCE_POINTS))
        if len(points) < MIN_POINTS:
            return None
        placed = apply_pose(points, pose)
        tree = cKDTree(placed)
        _, neighbours = tree.query(placed, k=min(NORMAL_NEIGHBOURS, len(placed)))
        around = placed[neighbours]
        centred = around - around.mean(axis=1, keepdims=True)
        _, vectors = np.linalg.eigh(np.einsum("mki,mkj->mij", centred, centred))
        return cls(placed, vectors[:, :, 0], tree)

    def compare(self, camera_points: np.ndarray, pose: np.ndarray) -> Comparison:
        """How a frame placed by ``pose`` meets this reference (see `Comparison`)."""
        points = _in_front(_spread(camera_points, CHECKED_POINTS))
        if len(points) < MIN_POINTS:
            return Comparison(0.0, 0.0, None)
        depth = points[:, 2]
        placed = apply_pose(points, pose)
        distances, nearest = self.tree.query(placed)
        near = distances < OVERLAP_DEPTH_SHARE * depth
        in_view = self._share_in_view(points, rigid_inverse(pose))
        if near.sum() < MIN_POINTS:
            return Comparison(float(near.mean()), in_view, None)
        rows = nearest[near]
        offsets = placed[near] - self.points[rows]
        planar = np.abs(np.einsum("ij,ij->i", offsets, self.normals[rows])) / depth[near]
        return Comparison(float(near.mean()), in_view, float(np.median(planar)))

    def _share_in_view(self, camera_points: np.ndarray, camera_from_world: np.ndarray
                       ) -> float:
        """The share of the reference's points a camera at ``camera_from_world`` has in its
        field of view: in front of it, within the image-plane bounds of its own points."""
        seen_u = camera_points[:, 0] / camera_points[:, 2]
        seen_v = camera_points[:, 1] / camera_points[:, 2]
        local = apply_pose(self.points, camera_from_world)
        front = local[:, 2] > 1e-6
        u = local[front, 0] / local[front, 2]
        v = local[front, 1] / local[front, 2]
        inside = ((u >= seen_u.min()) & (u <= seen_u.max())
                  & (v >= seen_v.min()) & (v <= seen_v.max()))
        return float(np.count_nonzero(inside) / len(self.points))


class PoseChecker:
    """Checks the posed frames of one stream in order (see the module docstring).

    ``checked``, ``rejected``: frames so far; ``last_problem``: why the last rejected one was.
    """

    def __init__(self, limits: PoseLimits | None = None) -> None:
        self.limits = limits or PoseLimits()
        self.reference: SurfaceReference | None = None
        self._last_pose: np.ndarray | None = None
        self._last_ns: int | None = None
        #: the workspace box's centre (None: the origin; else the first accepted camera's)
        self._centre: np.ndarray | None = None
        #: the frames refused in a row for their motion alone, each moving as a camera can from
        #: the one before: (pose, stamp) of the latest, and how many
        self._moved_run: tuple[np.ndarray, int | None] | None = None
        self._moved_count = 0
        self.checked = 0
        self.rejected = 0
        self.last_problem = ""

    def check(self, camera_points: np.ndarray, pose: np.ndarray,
              stamp_ns: int | None = None) -> PoseVerdict:
        """The verdict on one frame: ``camera_points`` (N, 3) in its camera frame, ``pose``
        (4, 4) camera-to-world, ``stamp_ns`` its capture time. An accepted frame moves the
        checker on (last pose, maybe a new reference); a rejected one leaves it as it was."""
        pose = np.asarray(pose, dtype=np.float64)
        self.checked += 1
        verdict = self._judge(camera_points, pose, stamp_ns)
        if not verdict.accepted:
            self.rejected += 1
            self.last_problem = verdict.problem
            return verdict
        if self.reference is None or verdict.overlap is None or verdict.overlap < RENEW_OVERLAP:
            self.reference = SurfaceReference.of(camera_points, pose) or self.reference
        if self._last_pose is None and self.limits.workspace_around == "first-camera":
            self._centre = pose[:3, 3].copy()
        self._last_pose, self._last_ns = pose, stamp_ns
        self._moved_run, self._moved_count = None, 0
        return verdict

    def _judge(self, camera_points: np.ndarray, pose: np.ndarray,
               stamp_ns: int | None) -> PoseVerdict:
        limits = self.limits
        centre = self._centre
        if centre is None and limits.workspace_around == "first-camera":
            centre = pose[:3, 3]  # the first camera: the box is centred on it
        problem = bounds_problem(pose, limits, centre)
        if problem:
            self._moved_run, self._moved_count = None, 0
        elif self._last_pose is not None:
            problem = motion_problem(self._last_pose, self._last_ns, pose, stamp_ns, limits)
            if problem and self._moved_on(pose, stamp_ns):
                self.reference = None  # a new place: judged against its own surfaces
                return PoseVerdict("")
        if problem or self.reference is None:
            return PoseVerdict(problem)
        seen = self.reference.compare(camera_points, pose)
        overlap, residual = seen.overlap, seen.residual
        if overlap < MIN_OVERLAP and seen.in_view >= EXPECTED_OVERLAP:
            return PoseVerdict(
                f"the pose contradicts the depth: it puts {seen.in_view:.0%} of an earlier "
                f"frame's surfaces in the camera's view, but only {overlap:.0%} of the frame's "
                "points lie on them", residual, overlap)
        if residual is None or overlap < MIN_OVERLAP:
            return PoseVerdict("", None, overlap)
        if residual > limits.max_residual:
            return PoseVerdict(
                f"the pose contradicts the depth: placed by it, the frame's points lie "
                f"{residual:.1%} of their depth from an earlier frame's surfaces (median, point "
                f"to plane; right poses give ~0.3 %, the limit is {limits.max_residual:.1%})",
                residual, overlap)
        return PoseVerdict("", residual, overlap)


    def _moved_on(self, pose: np.ndarray, stamp_ns: int | None) -> bool:
        """Note a frame refused for its motion alone; True when it is the
        ``REANCHOR_FRAMES``-th in a row to move as a camera can from the one before (the
        camera really went there while no frame came)."""
        run = self._moved_run
        if run is not None and not motion_problem(run[0], run[1], pose, stamp_ns, self.limits):
            self._moved_count += 1
        else:
            self._moved_count = 1
        self._moved_run = (pose, stamp_ns)
        return self._moved_count >= REANCHOR_FRAMES


def points_beyond_workspace(points: np.ndarray, limits: PoseLimits,
                            centre: np.ndarray | None = None, scale: float = 1.0) -> int:
    """How many of ``points`` (N, 3) lie outside the box of half-size ``scale`` times
    ``workspace_m`` around ``centre`` (default the origin), or are not finite."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if centre is not None:
        points = points - centre
    inside = np.isfinite(points).all(axis=1)
    inside[inside] = np.abs(points[inside]).max(axis=1) <= scale * limits.workspace_m
    return int(np.count_nonzero(~inside))


def _quaternion_w_first(pose: np.ndarray) -> np.ndarray:
    """``pose`` as it was meant when its quaternion's w x y z were read as x y z w."""
    translation, read = matrix_to_pose(pose)
    return pose_to_matrix(translation, [read[1], read[2], read[3], read[0]])


def _conjugated(pose: np.ndarray) -> np.ndarray:
    """``pose`` as it was meant when its quaternion was the conjugate (inverse rotation)."""
    meant = np.array(pose, dtype=np.float64)
    meant[:3, :3] = meant[:3, :3].T
    return meant


def _scaled(factor: float) -> Callable[[np.ndarray], np.ndarray]:
    def rescale(pose: np.ndarray) -> np.ndarray:
        scaled = np.array(pose, dtype=np.float64)
        scaled[:3, 3] *= factor
        return scaled
    return rescale


#: the usual misreadings of a pose file: what the poses probably are -> the pose meant
POSE_MISREADINGS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "the quaternions are in w x y z order, not x y z w": _quaternion_w_first,
    "the poses are world-to-camera transforms, not camera-to-world (inverted)": rigid_inverse,
    "the quaternions are conjugated (x y z negated: the JPL convention, or the inverse "
    "rotation)": _conjugated,
    "the translations are in millimetres, not metres": _scaled(1e-3),
    "the translations are in centimetres, not metres": _scaled(1e-2),
}


class PoseAudit:
    """A stream's poses checked as given and as each of `POSE_MISREADINGS`, side by side, to
    say which reading the depth agrees with (an importer's hint)."""

    def __init__(self, limits: PoseLimits | None = None) -> None:
        self.given = PoseChecker(limits)
        self.readings = {name: PoseChecker(limits) for name in POSE_MISREADINGS}

    def check(self, camera_points: np.ndarray, pose: np.ndarray,
              stamp_ns: int | None = None) -> PoseVerdict:
        """The verdict on the pose as given (see `PoseChecker.check`); each misreading is
        checked too."""
        for name, checker in self.readings.items():
            checker.check(camera_points, POSE_MISREADINGS[name](pose), stamp_ns)
        return self.given.check(camera_points, pose, stamp_ns)

    def likely_misreading(self) -> str:
        """The misreading under which clearly fewer frames are rejected (at most a tenth of
        them, and at most half as many as given), or "" when none is."""
        checked, rejected = self.given.checked, self.given.rejected
        if rejected == 0:
            return ""
        name, checker = min(self.readings.items(), key=lambda item: item[1].rejected)
        if checker.rejected <= 0.1 * checked and checker.rejected <= rejected / 2:
            return name
        return ""
