"""What an import of frames checks while it reads them (``gngdt record images``): the depth each
frame holds (its range, said at the end; implausible units warned about) and, with poses, every
posed frame against its own depth, as the learner checks them (`gngdt.core.odometry.pose_checks`).
When poses are rejected, the usual misreadings of a pose file (quaternion order, inverted
transforms, units) are tried on the same frames to name the likely cause.

The pose limits are command-line options shared by ``gngdt learn`` and ``gngdt record images``
(`add_pose_limit_arguments`).
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from gngdt.core.odometry.pose_checks import PoseAudit, PoseLimits
from gngdt.core.sensor.depth import DepthRange
from gngdt.io.deproject import Deprojector
from gngdt.io.frame import Frame

#: command-line option -> the `PoseLimits` field it sets
POSE_LIMIT_OPTIONS = {"workspace_m": "workspace_m", "workspace_around": "workspace_around",
                      "max_speed": "max_speed_m_s", "max_turn_rate": "max_turn_deg_s"}


#: what the pose limits are for, to title their options
POSE_LIMITS_TITLE = ("camera poses (a frame whose pose breaks these, or contradicts its own "
                     "depth, is counted and not learned)")


def add_pose_limit_arguments(group: Any) -> None:
    """``--workspace-m``, ``--workspace-around``, ``--max-speed`` and ``--max-turn-rate``: what
    a camera pose may be (into ``group``, a parser or an argument group)."""
    from gngdt.core.odometry.pose_checks import MAX_INTERVAL_S, MIN_INTERVAL_S, WORKSPACE_AROUND

    defaults = PoseLimits()
    group.add_argument("--workspace-m", type=float, metavar="M",
                       help="a camera farther than this along any axis from the workspace's "
                       "centre (--workspace-around) has a wrong pose, the first one too "
                       f"(default {defaults.workspace_m:g} m)")
    group.add_argument("--workspace-around", choices=WORKSPACE_AROUND,
                       help="the workspace box's centre: the fixed frame's origin, or the "
                       "first accepted camera (a map frame whose origin is far from where the "
                       f"camera works; default {defaults.workspace_around})")
    group.add_argument("--max-speed", type=float, metavar="M_PER_S",
                       help="fastest camera move between two frames (default "
                       f"{defaults.max_speed_m_s:g} m/s; at least {MIN_INTERVAL_S:g} s is "
                       f"assumed between two frames, at most {MAX_INTERVAL_S:g} s: a camera "
                       "is never farther than its top speed times that from the last accepted "
                       "frame)")
    group.add_argument("--max-turn-rate", type=float, metavar="DEG_PER_S",
                       help="fastest camera turn between two frames (default "
                       f"{defaults.max_turn_deg_s:g} degrees/s)")


def pose_limit_values(args: argparse.Namespace) -> dict[str, float]:
    """The `PoseLimits` fields the command line sets (options not given are left out)."""
    return {field: getattr(args, option) for option, field in POSE_LIMIT_OPTIONS.items()
            if getattr(args, option, None) is not None}


#: frames with depth a reader looks at before it judges the depth's units (`depth_warning`)
DEPTH_CHECK_FRAMES = 5


def depth_warning(depth: DepthRange) -> str:
    """The one message for depth an RGB-D camera cannot have measured (`DepthRange.problem`:
    wrong units), naming what sets the units; "" when the depth is plausible. `gngdt record
    images`, `gngdt segment` and `gngdt capture` (so `gngdt run`) say it alike."""
    problem = depth.problem()
    if not problem:
        return ""
    return (f"{problem}: {depth.describe()}; check depth_scale: camera.json's depth_scale or "
            "--depth-scale, the depth units per metre (1000 for millimetres, 5000 for TUM's "
            "frames)")


@dataclass
class PoseReport:
    """What the pose checks of an import found: a line to show, and how many of the posed
    frames were rejected."""

    text: str
    rejected: int
    checked: int

    @property
    def failed(self) -> bool:
        """Most frames rejected: the poses are unusable."""
        return self.rejected > self.checked / 2


class ImportChecks:
    """Watches the frames of an import go by (`watch`), checking depth and poses."""

    def __init__(self, limits: PoseLimits | None = None) -> None:
        self.depth = DepthRange()
        self.poses = PoseAudit(limits)
        self.first_rejection = ""
        # metres, as the learner's clouds hold them (capture's own deprojection range)
        self._deproject = Deprojector()

    def watch(self, frames: Iterable[Frame]) -> Iterator[Frame]:
        """``frames`` unchanged, each checked on its way."""
        for frame in frames:
            self.add(frame)
            yield frame

    def add(self, frame: Frame) -> None:
        self.depth.add(frame.depth)
        if frame.pose is None:
            return
        points, _ = self._deproject(frame.depth, None, frame.intrinsics)
        verdict = self.poses.check(points, frame.pose.matrix, frame.timestamp_ns)
        if not verdict.accepted and not self.first_rejection:
            self.first_rejection = f"frame {frame.index}: {verdict.problem}"

    def pose_report(self) -> PoseReport | None:
        """The poses' verdict (None: no frame had a pose)."""
        given = self.poses.given
        if given.checked == 0:
            return None
        if given.rejected == 0:
            return PoseReport(f"poses: all {given.checked} agree with the depth", 0,
                              given.checked)
        text = (f"poses: {given.rejected} of {given.checked} frames have a pose out of bounds or "
                f"contradicting their depth (first, {self.first_rejection})")
        misreading = self.poses.likely_misreading()
        if misreading:
            rejected = self.poses.readings[misreading].rejected
            text += (f"; likely cause: {misreading} (read so, {rejected} of {given.checked} "
                     "would be rejected): fix the pose file")
        return PoseReport(text, given.rejected, given.checked)
