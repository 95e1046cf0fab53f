"""Camera tracking after a gap: a camera that went on, unseen, for seconds is found again by
relocalising against the whole map (the motion continued over the gap and to a few distances,
the poses the map was learned from), not only near its last pose; and a live learner learns the
frame that adds most to the map."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gngdt.core.kernels.odometry import motion_size
from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig, LearnerOptions
from gngdt.core.learner.keyframes import choose_keyframe
from gngdt.core.odometry.map_odometry import TrackerParams
from gngdt.core.sensor.geometry import rigid_inverse
from gngdt.io.deproject import Deprojector
from gngdt.io.synth.render import render_scene

#: frames of the walk learned before the gap, and how far on the camera is after it
BEFORE = 12
GAP_M = 0.8
#: the walk replayed at a tenth of its pace (stamps ten times as far apart): a slow camera,
#: and a gap of seconds, as a hand-held camera put down and picked up again gives
SLOWER = 10


@pytest.fixture(scope="module")
def walk() -> list:
    """The virtual Kinect's walk at 30 fps (320x240): (points, colours, frame)."""
    deproject = Deprojector(0.3, 6.0)
    return [(*deproject(frame.depth, frame.color, frame.intrinsics), frame)
            for frame in render_scene("tabletop_walk", 60, width=320, height=240, fps=30.0)]


def tracked_after_a_gap(walk: list, relocalise: bool = True
                        ) -> tuple[FrameLearner, np.ndarray, np.ndarray]:
    """A learner that tracked the walk's first frames, then its frame ``GAP_M`` on (all at a
    tenth of the walk's pace): where it put it, and where it was (both in ``odom``)."""
    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(track=True),
                                                   tracker=TrackerParams(relocalise=relocalise)))
    start_ns = walk[0][2].timestamp_ns
    for points, colors, frame in walk[:BEFORE]:
        stamp = start_ns + SLOWER * (frame.timestamp_ns - start_ns)
        assert learner.learn(points, colors, "camera", None, stamp,
                             camera=frame.intrinsics).learned
    origin = walk[0][2].pose.matrix
    last = walk[BEFORE - 1][2]
    after = next(item for item in walk[BEFORE:]
                 if motion_size(last.pose.matrix, item[2].pose.matrix)[0] >= GAP_M)
    points, colors, frame = after
    stamp = start_ns + SLOWER * (frame.timestamp_ns - start_ns)
    result = learner.learn(points, colors, "camera", None, stamp, camera=frame.intrinsics)
    truth = rigid_inverse(origin) @ frame.pose.matrix
    return learner, result, truth


def test_a_camera_that_went_on_unseen_is_found_again(walk) -> None:
    _, result, truth = tracked_after_a_gap(walk)
    assert result.learned, result.problem
    moved, turned = motion_size(truth, result.pose)
    assert moved < 0.05 and turned < 3.0, (moved, turned)


def test_without_relocalising_it_is_lost_or_misplaced(walk) -> None:
    _, result, truth = tracked_after_a_gap(walk, relocalise=False)
    assert not result.learned or motion_size(truth, result.pose)[0] > 0.05


def test_the_map_keeps_the_poses_it_was_learned_from(walk) -> None:
    learner, _, _ = tracked_after_a_gap(walk)
    keyframes = list(learner.tracking.odometry.keyframes)
    assert len(keyframes) >= 2
    assert all(motion_size(a, b)[0] >= 0.1 or motion_size(a, b)[1] >= 10.0
               for a, b in itertools.pairwise(keyframes))


def test_the_keyframe_is_the_frame_that_adds_most() -> None:
    here = np.eye(4)
    on = np.eye(4)
    on[0, 3] = 0.3
    turned = np.eye(4)
    turned[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    assert choose_keyframe([here, on, here], [0.0, 0.0, 0.0], here) == 1
    assert choose_keyframe([on, turned], [0.0, 0.0], here) == 1  # 90 degrees beat 30 cm
    assert choose_keyframe([here, here], [0.5, 0.0], here) == 0  # half the view is new
    assert choose_keyframe([here, here], [0.0, 0.0], here) == 1  # a tie: the latest
    assert choose_keyframe([None, None], [0.0, 0.0], here) is None
