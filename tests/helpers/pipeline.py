"""A test's side of a running pipeline on zenoh: the learner's statuses watched; clouds, images
and ends of stream published to it; the posed clouds and frame stamps they carry."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from gngdt.schemas.clouds import cloud_to_msg
from gngdt.schemas.status import decode_status, encode_stream_end
from gngdt.schemas.wire import ENCODING_POINT_CLOUD, ENCODING_RAW_IMAGE, FrameStamp
from gngdt.services.plumbing.session import client_config, open_config


class Watcher:
    """A test-side zenoh client recording the learner's status messages."""

    def __init__(self, endpoint: str, camera: str = "camera") -> None:
        self.session = open_config(client_config([endpoint]))
        self.statuses: list = []
        self._lock = threading.Lock()
        self._subscriber = self.session.declare_subscriber(
            f"gngdt/{camera}/learner/status", self._on_status)

    def _on_status(self, sample) -> None:
        with self._lock:
            self.statuses.append(decode_status(sample.payload.to_bytes()))

    def wait_for(self, condition: Callable[[list], bool], timeout_s: float) -> list:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                statuses = list(self.statuses)
            if condition(statuses):
                return statuses
            time.sleep(0.05)
        raise AssertionError(f"condition not met within {timeout_s} s; statuses: {statuses[-3:]}")

    def close(self) -> None:
        self._subscriber.undeclare()
        self.session.close()


def points_publisher(session, camera: str = "camera"):
    """A BLOCK publisher on the camera's points, once a subscriber (the learner) matches it."""
    import zenoh

    publisher = session.declare_publisher(
        f"gngdt/{camera}/points", encoding=ENCODING_POINT_CLOUD,
        congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + 60
    while not publisher.matching_status.matching and time.monotonic() < deadline:
        time.sleep(0.05)
    return publisher


class ImageFlood:
    """A camera publishing 320x240 colour images at ~20 Hz, then an end of stream."""

    def __init__(self, endpoint: str) -> None:
        self.session = open_config(client_config([endpoint]))
        self.sent = 0

    def run(self, seconds: float) -> None:
        import zenoh

        from gngdt.schemas.images import image_to_raw

        rng = np.random.default_rng(0)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            image = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)  # incompressible
            now = time.time_ns()
            self.session.put("gngdt/camera/color", image_to_raw(image, timestamp_ns=now)
                             .SerializeToString(), attachment=FrameStamp(self.sent, now)
                             .to_attachment(), encoding=ENCODING_RAW_IMAGE,
                             congestion_control=zenoh.CongestionControl.BLOCK)
            self.sent += 1
            time.sleep(0.05)

    def end(self) -> None:
        _eos_put(self.session, self.sent)
        self.session.close()


def _eos_put(session, frames: int) -> None:
    """Publish the camera's end of stream after ``frames`` frames."""
    import zenoh

    message = encode_stream_end(timestamp_ns=time.time_ns(), frames_sent=frames,
                                last_frame_sequence=max(frames - 1, 0))
    session.put("gngdt/camera/eos", message.SerializeToString(),
                attachment=FrameStamp(max(frames - 1, 0), time.time_ns()).to_attachment(),
                congestion_control=zenoh.CongestionControl.BLOCK)


def posed_cloud(pose: np.ndarray | None, frame_id: str, seed: int = 0) -> bytes:
    """A 2,000-point coloured cloud of a wall 2 m in front of the camera (one wall for every
    pose that only slides the camera along it, as `pose_at`'s do)."""
    rng = np.random.default_rng(seed)
    positions = rng.uniform([-0.5, -0.4, 2.0], [0.5, 0.4, 2.0], (2000, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (2000, 3), dtype=np.uint8)
    return cloud_to_msg(positions, colors, timestamp_ns=1, frame_id=frame_id,
                        pose=pose).SerializeToString()


def pose_at(x: float) -> np.ndarray:
    """(4, 4) camera pose: unrotated, at (``x``, 0, 1) metres in the world."""
    pose = np.eye(4)
    pose[:3, 3] = [x, 0.0, 1.0]
    return pose


def attachment(sequence: int) -> bytes:
    """The frame stamp attachment of frame ``sequence``, stamped now."""
    return FrameStamp(sequence, time.time_ns()).to_attachment()
