"""The learner's map in a fixed frame and its camera tracking (`FrameLearner` with ``track``):
posed or tracked clouds build a map that grows with the world, camera-frame clouds keep the
node budget; a walk without poses is tracked and learned in ``odom``, a frame that cannot be
aligned is reported and never learned, and a checkpoint carries the tracker on."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from gngdt.core import GNGDT
from gngdt.core.kernels.odometry import motion_size
from gngdt.core.learner.frame_learner import (
    LEARNER_MODEL_DEFAULTS,
    FrameLearner,
    LearnerConfig,
    LearnerOptions,
)
from gngdt.core.learner.stream_learner import FrameSchedule
from gngdt.core.odometry.map_odometry import TrackerParams
from gngdt.core.sensor.geometry import rigid_inverse
from gngdt.io.deproject import Deprojector
from gngdt.io.synth.render import render_scene
from gngdt.schemas.status import decode_status
from gngdt.schemas.wire import FrameStamp
from gngdt.services.learner import checkpoints
from gngdt.services.learner.messages import status_message

FRAMES = 10


def rendered_walk(frames: int, fps: float) -> list:
    """The first frames of the virtual Kinect's walk (320x240): (points, colours, frame)."""
    deproject = Deprojector(0.3, 6.0)
    rendered = render_scene("tabletop_walk", frames, width=320, height=240, fps=fps)
    return [(*deproject(frame.depth, frame.color, frame.intrinsics), frame)
            for frame in rendered]


@pytest.fixture(scope="module")
def fast_walk() -> list:
    """20 frames at 10 fps: the walk of tests/process/test_tracking_processes (the camera
    speeds up to 12 cm a frame)."""
    return rendered_walk(20, 10.0)


@pytest.fixture(scope="module")
def walk() -> list:
    """Every third of the first 30 frames at 30 fps (10 frames a second)."""
    return rendered_walk(3 * FRAMES, 30.0)[::3]


def tracking_learner(tracker: TrackerParams | None = None, **options) -> FrameLearner:
    return FrameLearner("camera", LearnerConfig(options=LearnerOptions(track=True, **options),
                                                tracker=tracker or TrackerParams()))


def test_a_map_in_a_fixed_frame_grows_with_the_world_a_camera_frame_map_does_not(walk) -> None:
    points, colors, frame = walk[0]
    posed = FrameLearner("camera", LearnerConfig())
    posed.learn(points, colors, "world", frame.pose.matrix)
    assert (posed.model.resolution_m, posed.model.max_nodes) == (0.1, 20_000)
    assert posed.model.growth_limit_ > 1_000  # the first view alone needs more than 1,000
    static = FrameLearner("camera", LearnerConfig())
    static.learn(points, colors)
    assert static.model.resolution_m is None and static.model.growth_limit_ == 1_000
    for model, expected in (({"max_nodes": 300}, (0.1, 300)),
                            ({"resolution_m": 0}, (None, 20_000))):
        learner = FrameLearner("camera", LearnerConfig(model=model))
        learner.learn(points, colors, "world", frame.pose.matrix)
        checked = learner.model.check_params()  # as the model learns with them: 0 turns it off
        assert (checked["resolution_m"], checked["max_nodes"]) == expected


def test_a_static_camera_is_learned_as_before(walk) -> None:
    """Camera-frame clouds: the paper's node budget and the learner's profile, samples_per_frame
    steps of every frame, the first one too: the very network plain `GNGDT.partial_fit` calls
    with the learner's profile give, node for node."""
    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(
        samples_per_frame=3_000)))
    plain = GNGDT(**LEARNER_MODEL_DEFAULTS, random_state=0)
    for points, colors, _ in walk[:4]:
        learner.learn(points, colors)
        plain.partial_fit(points, colors, n_steps=3_000)
    assert learner.model.max_nodes == 1_000 and learner.model.resolution_m is None
    np.testing.assert_array_equal(learner.model.positions_, plain.positions_)
    np.testing.assert_array_equal(learner.model.edges("pos"), plain.edges("pos"))


def test_the_first_frame_of_a_fixed_frame_map_is_learned_longer(walk) -> None:
    points, colors, frame = walk[0]
    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(
        samples_per_frame=3_000, first_frame_steps=50_000)))
    learner.learn(points, colors, "world", frame.pose.matrix)
    learner.learn(points, colors, "world", frame.pose.matrix)
    assert learner.model.n_steps_ == 53_000 and learner.last_steps == 3_000


def test_a_walk_without_poses_is_tracked_and_learned_in_odom(walk) -> None:
    learner = tracking_learner()
    start = walk[0][2].pose.matrix
    for points, colors, frame in walk:
        assert learner.learn(points, colors, "camera", None, camera=frame.intrinsics)
        truth = rigid_inverse(start) @ frame.pose.matrix
        moved, turned = motion_size(truth, learner.last_pose)
        assert moved < 0.01 and turned < 0.5, (frame.index, moved, turned)
    assert learner.frame_id == "odom" and learner.tracking.problem == ""
    assert learner.counters.frames_used == FRAMES and learner.counters.frames_lost_tracking == 0
    travelled = motion_size(np.eye(4), learner.last_pose)[0]
    assert travelled > 0.2  # the camera did move


def learns_right(learner: FrameLearner, frames: list) -> None:
    """Every frame is tracked and learned, within 2 cm and 1 degree of its true pose."""
    start = frames[0][2].pose.matrix
    for points, colors, frame in frames:
        assert learner.learn(points, colors, "camera", None, frame.timestamp_ns,
                             camera=frame.intrinsics), (frame.index, learner.tracking.problem)
        truth = rigid_inverse(start) @ frame.pose.matrix
        moved, turned = motion_size(truth, learner.last_pose)
        assert moved < 0.02 and turned < 1.0, (frame.index, moved, turned)
    assert learner.counters.frames_lost_tracking == 0


def test_frames_a_busy_learner_dropped_do_not_lose_the_camera(fast_walk) -> None:
    """Frames 10 and 11 never reached the learner (it was busy; the camera sped up to 9 cm a
    frame by then): the motion is continued over the 0.3 s since frame 9, and every later
    frame is tracked from the prediction alone (the search is off here; with one frame's
    motion, frames 12-19 were all lost)."""
    frames = fast_walk[:10] + fast_walk[12:]
    learns_right(tracking_learner(TrackerParams(search_steps=0)), frames)
    learns_right(tracking_learner(), frames)  # the search changes nothing here


def test_a_camera_that_moved_far_while_the_map_began_is_found(fast_walk) -> None:
    """Frames 1-9 were dropped while the map's first frame was learned (no motion known yet;
    the camera moved 47 cm): the search finds frame 10, and the motion goes on from there
    (aligned from the first frame's pose alone, frame 10 slid to 38 cm off and was kept)."""
    learns_right(tracking_learner(), [fast_walk[0], *fast_walk[10:13]])


def test_a_frame_that_cannot_be_aligned_is_reported_and_not_learned(walk) -> None:
    learner = tracking_learner()
    for points, colors, frame in walk[:3]:
        learner.learn(points, colors, "camera", None, camera=frame.intrinsics)
    steps, pose = learner.model.n_steps_, learner.last_pose
    elsewhere = next(iter(render_scene("data2", 1, width=320, height=240)))
    points, colors = Deprojector(0.3, 6.0)(elsewhere.depth, elsewhere.color,
                                          elsewhere.intrinsics)
    assert not learner.learn(points, colors, "camera", None, camera=elsewhere.intrinsics).learned
    assert learner.tracking.problem in ("little overlap", "few inliers", "large residual",
                                        "degenerate", "implausible motion")
    assert learner.model.n_steps_ == steps and learner.last_pose is pose
    assert learner.counters.frames_lost_tracking == 1 and learner.counters.frames_used == 3
    status = decode_status(status_message(learner.figures(), FrameStamp(3, time.time_ns()),
                                          1.0, (1.0, 1.0), None).SerializeToString())
    assert status.tracking == f"lost: {learner.tracking.problem}"
    assert status.frames_lost_tracking == 1 and status.frames_used == 3
    points, colors, frame = walk[3]
    assert not learner.learn(points, colors, "camera", None, camera=None).learned
    assert learner.tracking.problem == "no calibration"
    assert learner.learn(points, colors, "camera", None, camera=frame.intrinsics).learned


def test_tracking_needs_a_profile_without_a_frame_schedule() -> None:
    with pytest.raises(ValueError, match="track"):
        LearnerConfig(options=LearnerOptions(track=True), schedule=FrameSchedule())


def test_a_checkpoint_carries_the_tracker_on(walk, tmp_path: Path) -> None:
    learner = tracking_learner()
    for points, colors, frame in walk[:4]:
        learner.learn(points, colors, "camera", None, camera=frame.intrinsics)
    path = tmp_path / "learner.npz"
    assert checkpoints.save(learner, path)
    resumed = checkpoints.resume(path, "camera", learner.config)
    np.testing.assert_array_equal(resumed.tracking.odometry.pose_,
                                  learner.tracking.odometry.pose_)
    np.testing.assert_array_equal(resumed.tracking.odometry.predict(),
                                  learner.tracking.odometry.predict())
    points, colors, frame = walk[4]
    for each in (learner, resumed):
        assert each.learn(points, colors, "camera", None, camera=frame.intrinsics)
    np.testing.assert_allclose(resumed.last_pose, learner.last_pose, atol=1e-9)
    assert resumed.frame_id == "odom"
