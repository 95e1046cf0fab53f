"""A learner among hostile or confused neighbours: impossible stamps, a second learner on its
camera, a checkpoint shared or made for another camera, debris of a killed checkpoint write."""

from __future__ import annotations

import shutil
import signal
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.checkpoints import trained_checkpoint
from helpers.processes import log_text, wait_for

from gngdt.schemas.clouds import cloud_to_msg
from gngdt.schemas.status import decode_status
from gngdt.services.plumbing.session import client_config, open_config


class Statuses:
    """The learner's status messages, as a neighbour on the router sees them."""

    def __init__(self, endpoint: str) -> None:
        self.session = open_config(client_config([endpoint]))
        self._lock = threading.Lock()
        self.received: list = []
        self.session.declare_subscriber("gngdt/camera/learner/status", self._on_status)

    def _on_status(self, sample) -> None:
        with self._lock:
            self.received.append(decode_status(sample.payload.to_bytes()))

    def of(self, sequence: int):
        with self._lock:
            return next((s for s in self.received if s.frame_sequence == sequence), None)


def _cloud() -> bytes:
    rng = np.random.default_rng(1)
    return cloud_to_msg(rng.random((2000, 3), dtype=np.float32),
                        rng.integers(0, 256, (2000, 3), dtype=np.uint8),
                        timestamp_ns=time.time_ns()).SerializeToString()


@pytest.mark.timeout(150)
def test_impossible_stamps_are_counted_and_neither_kill_nor_poison_the_learner(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    import zenoh

    checkpoint = tmp_path / "learner.npz"
    options = ("--samples-per-frame", "500", "--checkpoint", str(checkpoint),
               "--checkpoint-every", "1", "--zenoh-connect", router_endpoint)
    learner = spawn("learn", *options)
    statuses = Statuses(router_endpoint)
    block = zenoh.CongestionControl.BLOCK
    cloud = _cloud()

    def put(sequence: int, capture_time_ns: int) -> None:
        statuses.session.put("gngdt/camera/points", cloud, congestion_control=block,
                             attachment=struct.pack("<Qq", sequence, capture_time_ns))

    try:
        wait_for(lambda: "learning from" in log_text(learner), 60, "the learner")
        put(0, time.time_ns())
        wait_for(lambda: statuses.of(0) is not None, 30, "frame 0")
        # sequences 2**64-1 (an overflow of every signed counter) and a capture time of
        # INT64_MIN (a latency of 292 years), one at a time so the latest-wins slot keeps each
        hostile = [(2**64 - 1, time.time_ns()), (0, time.time_ns()), (2**64 - 1, time.time_ns()),
                   (1, -(2**63)), (1, 1)]
        skipped = 0
        for sequence, capture_time_ns in hostile:
            learned = len(statuses.received)
            put(sequence, capture_time_ns)
            if sequence == 0:  # a good frame (a new stream): learned
                wait_for(lambda count=learned: len(statuses.received) > count, 30, "frame 0 again")
                continue
            skipped += 1
            wait_for(lambda count=skipped: log_text(learner).count("points message skipped")
                     >= count, 30, "the learner to skip it")
        put(2, time.time_ns())
        wait_for(lambda: statuses.of(2) is not None, 30, "frame 2")
        learner.send_signal(signal.SIGINT)
        assert learner.wait(30) == 0, log_text(learner)
        status = statuses.of(2)
        assert status.malformed_messages == 4
        assert status.latency_p99_ms < 60_000  # not 7.5e12 ms
        assert 0 <= status.frames_dropped < 10
        # the checkpoint it left resumes, and the resumed learner learns
        resumed = spawn("learn", *options)
        wait_for(lambda: "learning from" in log_text(resumed), 60, "the resumed learner")
        put(0, time.time_ns())
        wait_for(lambda: any(s.frames_used > status.frames_used for s in statuses.received), 30,
              "a frame learned after the restart")
        resumed.send_signal(signal.SIGINT)
        assert resumed.wait(30) == 0, log_text(resumed)
    finally:
        statuses.session.close()
    assert "Traceback" not in log_text(learner) + log_text(resumed)


@pytest.mark.timeout(150)
def test_a_second_learner_on_a_camera_or_a_checkpoint_is_refused(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    checkpoint = tmp_path / "camera.npz"
    trained_checkpoint(checkpoint)
    for index in range(3):  # what kill -9 during checkpoint writes leaves behind
        (tmp_path / f".camera.npz.x{index}.tmp").write_bytes(b"half a checkpoint")
    connect = ("--zenoh-connect", router_endpoint)
    first = spawn("learn", "--checkpoint", str(checkpoint), *connect)
    wait_for(lambda: "learning from" in log_text(first), 60, "the first learner")
    assert list(tmp_path.glob("*.tmp")) == []
    assert "removed 3 stale checkpoint temporaries" in log_text(first)

    same_camera = spawn("learn", *connect)
    other_camera_same_file = spawn("learn", "--cam", "left", "--checkpoint", str(checkpoint),
                                   *connect)
    copied = tmp_path / "copy.npz"
    shutil.copy(checkpoint, copied)
    wrong_camera = spawn("learn", "--cam", "left", "--checkpoint", str(copied), *connect)
    for process in (same_camera, other_camera_same_file, wrong_camera):
        assert process.wait(60) == 2, log_text(process)
        assert "Traceback" not in log_text(process)
    assert "already learns camera 'camera'" in log_text(same_camera)
    assert f"is in use by another learner (pid {first.pid})" in log_text(other_camera_same_file)
    assert "holds what camera 'camera' learned, not 'left'" in log_text(wrong_camera)

    assert first.poll() is None, log_text(first)
    first.send_signal(signal.SIGINT)
    assert first.wait(30) == 0, log_text(first)


