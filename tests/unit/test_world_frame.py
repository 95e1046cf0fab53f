"""Poses through the pipeline: capture publishes each cloud with its pose, the learner learns in
the fixed frame, says so, and skips (counts, names) clouds in another frame or with a bad pose."""

from __future__ import annotations

import re
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers.pipeline import attachment, pose_at, posed_cloud

from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig
from gngdt.core.learner.results import Ghosts, Outcome
from gngdt.schemas.messages import MessageError
from gngdt.schemas.wire import FrameStamp
from gngdt.services.learner import checkpoints
from gngdt.services.learner.messages import decode_points, status_message, topology_message


def test_the_learner_learns_in_the_first_clouds_frame_and_skips_others(tmp_path: Path):
    learner = FrameLearner("camera", LearnerConfig(model={"max_nodes": 50, "lambda_": 100}))
    for sequence, x in enumerate((0.0, 0.5, 1.0)):
        message = decode_points(posed_cloud(pose_at(x), "world", sequence), attachment(sequence))
        learner.learn(message.positions, message.colors, message.frame_id, message.pose)
    assert learner.frame_id == "world"
    # the map spans the three camera positions: x from -0.5 to 1.5 in the world
    assert learner.model.positions_[:, 0].min() < -0.3 < 1.3 < learner.model.positions_[:, 0].max()
    # the frame's error is measured where the map is: the cloud placed by its pose
    last = message.positions, message.colors
    assert learner.quantization_error(*last)["pos"] < 0.2
    # settling on the last frame learns it where it was, in the world
    learner.options = replace(learner.options, settle_max_steps=2_000)
    learner.ghosts = Ghosts(seen_nodes=-1)
    learner.settle(*last)
    assert learner.model.positions_[:, 0].max() > 1.3
    # the final status's ghost share is the settled network's, not the last frame's before
    assert len(last[0]) <= learner.options.ghost_sample  # all points: the measure is exact
    assert learner.ghosts == learner.measure_ghosts(last[0], message.pose)
    assert learner.ghosts.seen_nodes > 0
    assert learner.quantization_error(*last)["pos"] < 0.2
    unposed = decode_points(posed_cloud(None, "camera"), attachment(3))
    assert unposed.pose is None and unposed.frame_id == "camera"
    result = learner.learn(unposed.positions, unposed.colors, unposed.frame_id, unposed.pose)
    assert result.outcome is Outcome.OTHER_FRAME
    assert re.search(r"frame 'camera'.*learned in 'world'", result.problem)
    assert learner.counters.frames_other_frame == 1 and learner.counters.frames_used == 3
    stamp = FrameStamp(3, 1)
    published = learner.publication(*last)
    topology = topology_message(published, stamp)
    assert topology.frame_id == "world"
    status = status_message(learner.figures(), stamp, 1.0, (0.0, 0.0), published)
    assert status.frames_other_frame == 1 and status.ghost_distance_m == 0.05
    assert 0 < status.seen_nodes <= status.nodes and 0.0 <= status.ghost_share <= 1.0
    # a checkpoint remembers the frame
    checkpoints.save(learner, tmp_path / "learner.npz")
    resumed = checkpoints.resume(tmp_path / "learner.npz", "camera", LearnerConfig())
    assert resumed.frame_id == "world"


def test_a_cloud_with_a_bad_pose_is_a_message_error_naming_the_frame():
    payload = posed_cloud(pose_at(0.0), "map")
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    message = PointCloud.FromString(payload)
    message.pose.orientation.w = 2.5  # not a rotation
    with pytest.raises(MessageError, match=r"'map'.*norm 2\.5"):
        decode_points(message.SerializeToString(), attachment(0))
    message.pose.position.x = float("nan")
    message.pose.orientation.w = 1.0
    with pytest.raises(MessageError, match="translation"):
        decode_points(message.SerializeToString(), attachment(0))


def test_the_logger_puts_a_posed_cloud_and_the_camera_in_the_world(tmp_path: Path):
    import rerun as rr
    from rerun.chunk import RrdReader

    from gngdt.io.outputs.rerun_blueprint import EntityPaths
    from gngdt.io.outputs.rerun_log import RerunLog

    path = tmp_path / "posed.rrd"
    recording = rr.RecordingStream("gngdt-test")
    recording.set_sinks(rr.FileSink(str(path)))
    rerun_log = RerunLog(recording)
    rerun_log.set_time(FrameStamp(0, time.time_ns()))
    pose = rotation_about_z(np.pi / 2)
    pose[:3, 3] = [1.0, 2.0, 3.0]
    points = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 2.0]], dtype=np.float32)
    rerun_log.points(EntityPaths("camera"), points, np.zeros((2, 3), np.uint8), pose)
    recording.flush()
    recording.disconnect()
    logged = {chunk.entity_path: chunk.to_record_batch()
              for chunk in RrdReader(path).stream().collect().stream()}
    positions = np.array(logged["/world/points"].column("Points3D:positions").to_pylist()[0])
    np.testing.assert_allclose(positions, [[1.0, 3.0, 3.0], [1.0, 2.0, 5.0]], atol=1e-6)
    translation = logged["/world/camera"].column("Transform3D:translation").to_pylist()[0]
    np.testing.assert_allclose(np.ravel(translation), [1.0, 2.0, 3.0])


def rotation_about_z(angle: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    return pose
