"""Camera tracking through the real services: a capture that ignores a walk's poses, a learner
with ``--track`` that publishes the camera's pose on ``gngdt/<cam>/tf`` and learns in ``odom``,
and a logger that draws the camera (and its clouds) where the transforms put it."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.pipeline import Watcher
from helpers.processes import log_text, wait_exit
from helpers.synthetic import render_walk

from gngdt.core.kernels.odometry import motion_size
from gngdt.core.sensor.geometry import rigid_inverse
from gngdt.schemas.clouds import transform_to_pose
from gngdt.schemas.topology import decode_topology
from gngdt.schemas.wire import LOGGER_ALIVE, FrameStamp
from gngdt.services.plumbing.session import client_config, open_config

FRAMES = 20


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    """20 frames 320x240 of the walking camera at 10 fps (2 s), with poses."""
    return render_walk(tmp_path_factory.mktemp("walk"), FRAMES, 320, 240, fps=10.0)


class Transforms:
    """A test-side subscriber of gngdt/camera/tf: sequence -> (parent, child, (4, 4))."""

    def __init__(self, endpoint: str) -> None:
        self.session = open_config(client_config([endpoint]))
        self.received: dict[int, tuple[str, str, np.ndarray]] = {}
        self._lock = threading.Lock()
        self._subscriber = self.session.declare_subscriber("gngdt/camera/tf", self._on_sample)

    def _on_sample(self, sample) -> None:
        stamp = FrameStamp.from_attachment(sample.attachment.to_bytes())
        with self._lock:
            self.received[stamp.sequence] = transform_to_pose(sample.payload.to_bytes())

    def close(self) -> None:
        self._subscriber.undeclare()
        self.session.close()


def rrd_camera_translations(path: Path) -> list[np.ndarray]:
    """The translations logged on world/camera's transform, in the .rrd's order."""
    from rerun.chunk import RrdReader

    translations = []
    for chunk in RrdReader(path).stream().collect().stream():
        if chunk.entity_path != "/world/camera":
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("translation"):
                translations += [np.array(row[0]) for row in batch.column(name).to_pylist()
                                 if row]
    return translations


@pytest.mark.timeout(300)
def test_a_tracked_walk_is_published_learned_in_odom_and_drawn(
    router_endpoint: str, spawn: Callable, walk, tmp_path: Path
) -> None:
    path, frames = walk
    watcher = Watcher(router_endpoint)
    transforms = Transforms(router_endpoint)
    rrd = tmp_path / "tracked.rrd"
    try:
        learner = spawn("learn", "--track", "--exit-on-eos", "--zenoh-connect", router_endpoint)
        logger = spawn("log", "--save", str(rrd), "--zenoh-connect", router_endpoint)
        for key in ("gngdt/camera/learner/alive", f"{LOGGER_ALIVE}/*"):  # both ready
            _wait_alive(watcher.session, key)
        # half speed: frames the learner drops while it learns the map's first frame (200,000
        # steps) are a jump with no motion known yet; later drops are predicted over
        capture = spawn("capture", str(path), "--fixed-frame", "none", "--rate", "0.5",
                        "--zenoh-connect", router_endpoint)
        assert wait_exit(capture, 120) == 0, log_text(capture)
        assert wait_exit(learner, 120) == 0, log_text(learner)
        assert wait_exit(logger, 120) == 0, log_text(logger)
        statuses = watcher.wait_for(lambda s: bool(s) and s[-1].settled, 30)
    finally:
        watcher.close()
        transforms.close()
    last = statuses[-1]
    assert last.tracking == "tracked", last  # dropped frames (a busy machine) do not lose it
    assert last.frames_used >= 2 and last.frame_steps > 0
    assert len(transforms.received) == last.frames_used  # one pose per learned frame
    start = frames[0].pose.matrix
    for sequence, (parent, child, pose) in transforms.received.items():
        assert (parent, child) == ("odom", "camera")
        truth = rigid_inverse(start) @ frames[sequence].pose.matrix
        moved, turned = motion_size(truth, pose)
        assert moved < 0.02 and turned < 1.0, (sequence, moved, turned)
    drawn = rrd_camera_translations(rrd)
    final = transforms.received[max(transforms.received)][2]
    assert any(np.allclose(t, final[:3, 3], atol=1e-5) for t in drawn), drawn[-3:]
    assert "learning in frame 'odom'" in log_text(learner)


def _wait_alive(session, key: str, timeout_s: float = 120.0) -> list:
    """The liveliness tokens on ``key`` once there is one (a service is ready)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        replies = [reply for reply in session.liveliness().get(key, timeout=1.0)
                   if reply.ok is not None]
        if replies:
            return replies
        time.sleep(0.1)
    raise AssertionError(f"no {key} within {timeout_s} s")


@pytest.mark.timeout(120)
def test_without_calibration_a_tracking_learner_reports_and_learns_nothing(
    router_endpoint: str, spawn: Callable, walk
) -> None:
    """Clouds reach a tracking learner that never got the camera's calibration (it started
    after the capture sent it): the first starts the map, the others are reported lost."""
    from helpers.pipeline import points_publisher

    from gngdt.io.deproject import Deprojector
    from gngdt.schemas.clouds import cloud_to_msg

    _, frames = walk
    learner = spawn("learn", "--track", "--zenoh-connect", router_endpoint)
    watcher = Watcher(router_endpoint)
    session = open_config(client_config([router_endpoint]))
    try:
        _wait_alive(session, "gngdt/camera/learner/alive")
        publisher = points_publisher(session)
        deproject = Deprojector(0.3, 6.0)
        for sequence, frame in enumerate(frames[:3]):
            positions, colors = deproject(frame.depth, frame.color, frame.intrinsics)
            message = cloud_to_msg(positions, colors, timestamp_ns=time.time_ns())
            publisher.put(message.SerializeToString(),
                          attachment=FrameStamp(sequence, time.time_ns()).to_attachment())
            watcher.wait_for(lambda s, n=sequence: bool(s) and s[-1].frame_sequence == n, 60)
        last = watcher.statuses[-1]
        assert (last.frames_used, last.frames_lost_tracking) == (1, 2)
        assert last.tracking == "lost: no calibration"
        replies = list(session.get("gngdt/camera/topology", timeout=10))
        assert decode_topology(replies[0].ok.payload.to_bytes()).frame_id == "odom"
    finally:
        watcher.close()
        session.close()
    learner.send_signal(signal.SIGTERM)
    assert wait_exit(learner, 30) == 0
    assert "camera not tracked" in log_text(learner)
