"""Poses through the pipeline: capture publishes each cloud with its pose, the learner learns in
the fixed frame, says so, and skips (counts, names) clouds in another frame or with a bad pose."""

from __future__ import annotations

import signal
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.pipeline import Watcher, attachment, points_publisher, pose_at, posed_cloud
from helpers.processes import log_text, wait_exit
from helpers.synthetic import render_walk

from gngdt.schemas.topology import decode_topology
from gngdt.services.plumbing.session import client_config, open_config

FRAMES = 4


@pytest.fixture(scope="module")
def walk_recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    """Four 160x120 frames of the walking camera, with poses; and the rendered frames."""
    return render_walk(tmp_path_factory.mktemp("walk"), FRAMES, 160, 120, fps=2.0)


@pytest.mark.timeout(120)
def test_capture_publishes_each_cloud_with_its_pose(run_capture: Callable, walk_recording):
    path, frames = walk_recording
    output = run_capture(path)
    assert len(output.clouds) == FRAMES
    for (frame_id, pose), frame in zip(output.poses, frames, strict=True):
        assert frame_id == "world"
        np.testing.assert_allclose(pose, frame.pose.matrix, atol=1e-9)
    ignored = run_capture(path, "--fixed-frame", "none")
    assert [frame_id for frame_id, _ in ignored.poses] == ["camera"] * FRAMES
    assert all(np.array_equal(pose, np.eye(4)) for _, pose in ignored.poses)


@pytest.mark.timeout(120)
def test_a_running_learner_skips_bad_poses_and_other_frames(
    router_endpoint: str, spawn: Callable
) -> None:
    learner = spawn("learn", "--samples-per-frame", "2000", "--zenoh-connect", router_endpoint)
    watcher = Watcher(router_endpoint)
    session = open_config(client_config([router_endpoint]))
    try:
        publisher = points_publisher(session)
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        bad = PointCloud.FromString(posed_cloud(pose_at(0.0), "world"))
        bad.pose.orientation.x = 3.0
        sends = [posed_cloud(pose_at(0.0), "world"), bad.SerializeToString(),
                 posed_cloud(None, "camera"), posed_cloud(pose_at(0.4), "world", 1)]
        for sequence, payload in enumerate(sends):
            publisher.put(payload, attachment=attachment(sequence))
            time.sleep(0.3)
        statuses = watcher.wait_for(lambda s: bool(s) and s[-1].frame_sequence == 3, 60)
        last = statuses[-1]
        assert (last.frames_used, last.malformed_messages, last.frames_other_frame) == (2, 1, 1)
        replies = list(session.get("gngdt/camera/topology", timeout=10))
        assert decode_topology(replies[0].ok.payload.to_bytes()).frame_id == "world"
        assert learner.poll() is None, log_text(learner)
    finally:
        watcher.close()
        session.close()
    learner.send_signal(signal.SIGTERM)
    assert wait_exit(learner, 30) == 0
    log = log_text(learner)
    assert "learned in 'world'" in log and "'camera'" in log


