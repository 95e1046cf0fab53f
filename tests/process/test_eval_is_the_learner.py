"""What `gngdt eval recording` evaluates is what `gngdt learn` deploys: the same recording, the
same seed, and the two end with the same network, node for node."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.processes import wait_for

from gngdt.io.deproject import CloudOptions, FrameToCloud
from gngdt.io.mcap.reader import read_frames
from gngdt.schemas.topology import decode_topology
from gngdt.schemas.wire import FrameStamp
from gngdt.services.plumbing.session import client_config, open_config

FRAMES = 4


@pytest.mark.timeout(240)
def test_eval_recording_and_the_learner_agree_node_for_node(
    router_endpoint: str, spawn: Callable, tabletop_recording: Path
) -> None:
    from gngdt.eval.recording_eval import RecordingSettings, replay
    from gngdt.services.capture import CapturePublisher

    learner = spawn("learn", "--zenoh-connect", router_endpoint)
    session = open_config(client_config([router_endpoint]))
    topologies: dict[int, bytes] = {}
    arrived = threading.Condition()

    def on_topology(sample) -> None:
        with arrived:
            snapshot = decode_topology(sample.payload.to_bytes())
            topologies[snapshot.frame_sequence] = sample.payload.to_bytes()
            arrived.notify_all()

    session.declare_subscriber("gngdt/camera/topology", on_topology)
    try:
        wait_for(lambda: any(reply.ok is not None for reply in session.liveliness().get(
            "gngdt/camera/learner/alive", timeout=1.0)), 120, "the learner")
        publisher = CapturePublisher(session, "camera")  # capture's own publishing
        to_cloud = FrameToCloud(CloudOptions())  # capture's defaults: every point
        frames = list(read_frames(tabletop_recording, fixed_frame="auto"))[:FRAMES]
        for sequence, frame in enumerate(frames):
            positions, colors = to_cloud(frame)
            # taken when it was recorded, as evaluation replays it
            publisher.publish_frame(frame, FrameStamp(sequence, time.time_ns()), positions,
                                    colors, sensor_time_ns=frame.timestamp_ns)
            with arrived:  # one frame at a time: the learner drops none
                assert arrived.wait_for(lambda s=sequence: s in topologies, timeout=60), \
                    Path(learner.log_path).read_text()
        deployed = decode_topology(topologies[FRAMES - 1])
    finally:
        session.close()
    settings = RecordingSettings(methods=("GNG-DT",), max_frames=FRAMES, max_points=0)
    evaluated = replay(tabletop_recording, "GNG-DT", 0, settings)["model"]
    assert deployed.node_count == evaluated.n_nodes_ > 50  # 2 + 40,000 steps / lambda 500
    np.testing.assert_array_equal(deployed.node_ids, evaluated.node_ids_)
    np.testing.assert_array_equal(deployed.positions, evaluated.positions_.astype(np.float32))
