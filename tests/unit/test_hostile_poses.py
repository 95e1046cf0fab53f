"""Camera poses that jump far after a pause, or come at random (issue 38): the speed check caps
the distance from the last accepted frame however long ago it was (a 100 m jump 25 s later
passed before), follows a camera that really moved once several frames agree, and the workspace
box bounds the first pose, around the origin or the first camera. The learner's map, read back,
holds nothing of a refused pose."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig, LearnerOptions
from gngdt.core.learner.results import Outcome
from gngdt.core.odometry.pose_checks import PoseChecker, PoseLimits

SECOND = 1_000_000_000


def at(x: float, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = (x, y, z)
    return pose


def wall(seed: int = 0, count: int = 3000) -> np.ndarray:
    """(N, 3) float32: a wall 2 m in front of the camera, in its frame."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-1, 1, count), rng.uniform(-0.75, 0.75, count),
                            np.full(count, 2.0)]).astype(np.float32)


def test_a_100_m_jump_25_s_after_the_last_accepted_frame_is_refused() -> None:
    """Before, 100 m in 25 s was 4 m/s, under the 10 m/s limit."""
    checker = PoseChecker()
    assert checker.check(wall(), at(0.0), 0).accepted
    verdict = checker.check(wall(1), at(100.0), 25 * SECOND)
    assert "farther than the 10 m it may move between two frames" in verdict.problem
    assert checker.check(wall(2), at(9.0), 26 * SECOND).accepted  # within the cap: a camera's


def test_a_camera_that_really_moved_while_no_frame_came_is_followed() -> None:
    """The frames after a long pause all agree with one another: the camera is there."""
    from gngdt.core.odometry.pose_checks import REANCHOR_FRAMES

    checker = PoseChecker()
    assert checker.check(wall(), at(0.0), 0).accepted
    verdicts = [checker.check(wall(index), at(100.0 + 0.1 * index), (25 + index) * SECOND // 10
                              + 25 * SECOND)
                for index in range(REANCHOR_FRAMES + 2)]
    assert [v.accepted for v in verdicts] == [False] * (REANCHOR_FRAMES - 1) + [True] * 3


def test_random_poses_are_never_followed() -> None:
    rng = np.random.default_rng(0)
    checker = PoseChecker()
    assert checker.check(wall(), at(0.0), 0).accepted
    verdicts = [checker.check(wall(index), at(*rng.uniform(-50, 50, 3)), index * SECOND // 30)
                for index in range(1, 60)]
    assert not any(v.accepted for v in verdicts)


def test_the_first_pose_is_bounded_by_the_box_around_the_origin() -> None:
    limits = PoseLimits(workspace_m=2.0)
    assert "beyond the workspace of 2 m" in PoseChecker(limits).check(wall(), at(0, 0, 2.5),
                                                                     0).problem
    assert PoseChecker(limits).check(wall(), at(1.9, 1.9, 1.9), 0).accepted  # a box's corner


def test_a_workspace_around_the_first_camera() -> None:
    """A map frame whose origin is far from where the camera works: the box follows the first
    camera (before, a workspace around the origin small enough to matter refused the first)."""
    checker = PoseChecker(PoseLimits(workspace_m=20.0, workspace_around="first-camera"))
    assert checker.check(wall(), at(500.0), 0).accepted
    for step in range(1, 30):  # 1 m a second away from the first camera
        verdict = checker.check(wall(step), at(500.0 + step), step * SECOND)
        assert verdict.accepted == (step <= 20), (step, verdict.problem)


def test_the_learner_learns_nothing_from_a_jump_after_a_pause() -> None:
    """Read the map back: every node near the wall the accepted frames saw."""
    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(
        samples_per_frame=2000, first_frame_steps=5000)))
    for index in range(3):
        result = learner.learn(wall(index), None, "world", at(0.0), index * SECOND // 10)
        assert result.outcome is Outcome.LEARNED
    result = learner.learn(wall(9), None, "world", at(100.0), 25 * SECOND)
    assert result.outcome is Outcome.POSE_REJECTED
    nodes = learner.model.positions_
    assert np.abs(nodes[:, 0]).max() < 1.5 and np.abs(nodes[:, 2] - 2.0).max() < 0.5


@pytest.mark.parametrize("around", ["origin", "first-camera"])
def test_the_workspace_options_reach_the_learner(around: str) -> None:
    options = LearnerOptions(pose_workspace_around=around, pose_workspace_m=5.0)
    assert options.pose_limits() == PoseLimits(workspace_m=5.0, workspace_around=around)
    with pytest.raises(ValueError, match="pose_workspace_around must be one of"):
        LearnerOptions(pose_workspace_around="moon")
