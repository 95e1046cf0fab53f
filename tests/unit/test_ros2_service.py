"""`gngdt ros2`'s parts that need no socket: its options, its workers (bounded, latest wins, a bad
sample skipped and counted), and the transform window a live /tf is held in."""

from __future__ import annotations

import argparse
import threading
import time

import numpy as np
import pytest

from gngdt.io.tf_tree import TransformTree
from gngdt.services.cli import build_parser
from gngdt.services.plumbing.environment import read_environment
from gngdt.services.ros2 import check_names, domain_id
from gngdt.services.ros2.worker import Worker


def parse(*arguments: str, environ: dict[str, str] | None = None) -> argparse.Namespace:
    """`gngdt ros2`'s arguments, with the environment `gngdt`'s main would read from
    ``environ``."""
    args = build_parser().parse_args(["ros2", *arguments])
    args.environment = read_environment(environ or {})
    return args


def test_domain_from_option_environment_or_zero() -> None:
    assert domain_id(parse()) == 0
    assert domain_id(parse(environ={"ROS_DOMAIN_ID": "7"})) == 7
    assert domain_id(parse("--domain", "3", environ={"ROS_DOMAIN_ID": "7"})) == 3  # option wins
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID='seven'"):
        domain_id(parse(environ={"ROS_DOMAIN_ID": "seven"}))
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID='1e999'"):
        domain_id(parse(environ={"ROS_DOMAIN_ID": "1e999"}))
    with pytest.raises(ValueError, match="--domain"):
        domain_id(parse("--domain", "233"))


def test_names_must_be_ros_names() -> None:
    check_names(parse("--cam", "left_0"))
    with pytest.raises(ValueError, match="--cam 'cam-0'"):
        check_names(parse("--cam", "cam-0"))
    with pytest.raises(ValueError, match="--depth-topic"):
        check_names(parse("--depth-topic", "camera/depth"))  # not fully qualified
    with pytest.raises(ValueError, match="--graph-rate"):
        check_names(parse("--graph-rate", "0"))
    with pytest.raises(ValueError, match="max_held_bytes"):
        check_names(parse("--max-pending-mb", "0"))


class Recorder:
    """A worker's handler: records samples, waits while ``gate`` is closed, fails on demand."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, bytes]] = []
        self.gate = threading.Event()
        self.gate.set()

    def __call__(self, stream: str, payload: bytes, attachment: bytes | None) -> None:
        self.gate.wait(10)
        if payload == b"bad":
            raise ValueError("not a message")
        if payload == b"bug":
            raise RuntimeError("a bug")
        self.seen.append((stream, payload))


def wait_idle(worker: Worker) -> None:
    deadline = time.monotonic() + 10
    while not worker.idle():
        assert time.monotonic() < deadline
        time.sleep(0.01)


def test_worker_skips_bad_samples_and_goes_on() -> None:
    recorder = Recorder()
    worker = Worker("test", recorder).start()
    try:
        for payload in (b"1", b"bad", b"bug", b"2"):
            worker.put("status", payload, None)
        wait_idle(worker)
    finally:
        worker.stop()
    assert recorder.seen == [("status", b"1"), ("status", b"2")]
    counts = worker.counts
    assert (counts.received, counts.handled, counts.malformed, counts.failed) == (4, 2, 1, 1)


def test_worker_bounded_and_latest_wins() -> None:
    recorder = Recorder()
    worker = Worker("test", recorder, capacity=3, latest_only=("points",)).start()
    try:
        recorder.gate.clear()
        worker.put("status", b"first", None)  # taken by the thread, which waits at the gate
        deadline = time.monotonic() + 10
        while worker.idle() or worker._queue:  # the thread holds it
            assert time.monotonic() < deadline
            time.sleep(0.01)
        worker.put("points", b"p1", None)
        worker.put("topology", b"t1", None)
        worker.put("points", b"p2", None)  # replaces p1
        worker.put("topology", b"t2", None)
        worker.put("topology", b"t3", None)  # the queue holds 3: the oldest (t1) goes
        recorder.gate.set()
        wait_idle(worker)
    finally:
        worker.stop()
    assert recorder.seen == [("status", b"first"), ("points", b"p2"), ("topology", b"t2"),
                             ("topology", b"t3")]
    assert worker.counts.dropped == 2 and worker.counts.received == 6


def test_camera_worker_holds_the_newest_image_of_each_role() -> None:
    """A flooded bridge: of the images waiting while a frame is handled only the newest colour
    and depth stay (and CameraInfo); transforms all wait, in order."""
    from gngdt.services.ros2.inbound import camera_worker

    recorder = Recorder()
    worker = camera_worker(recorder).start()
    try:
        recorder.gate.clear()
        worker.put("tf", b"tf0", None)
        deadline = time.monotonic() + 10
        while worker.idle() or worker._queue:  # the thread holds it
            assert time.monotonic() < deadline
            time.sleep(0.01)
        for k in range(5):
            worker.put("camera_info", f"i{k}".encode(), None)
            worker.put("color", f"c{k}".encode(), None)
            worker.put("depth", f"d{k}".encode(), None)
            worker.put("tf", f"tf{k + 1}".encode(), None)
        recorder.gate.set()
        wait_idle(worker)
    finally:
        worker.stop()
    assert recorder.seen == [("tf", b"tf0"), ("tf", b"tf1"), ("tf", b"tf2"), ("tf", b"tf3"),
                             ("tf", b"tf4"), ("camera_info", b"i4"), ("color", b"c4"),
                             ("depth", b"d4"), ("tf", b"tf5")]


def test_transform_window_forgets_old_samples_and_keeps_lookups() -> None:
    tree = TransformTree()
    tree.add("odom", "base", 0, (0, 0, 0), (0, 0, 0, 1), static=True)
    for k in range(100):
        tree.add("base", "camera", k * 10_000_000, (k * 0.01, 0, 0), (0, 0, 0, 1))
    assert tree.samples == 101
    tree.forget_before(900_000_000)
    assert tree.samples == 1 + 10  # the static one and samples from 0.90 s on
    np.testing.assert_allclose(tree.lookup("odom", "camera", 945_000_000)[:3, 3],
                               [0.945, 0, 0])
    tree.forget_before(10**12)  # far ahead: each link keeps its newest sample
    assert tree.samples == 2
    np.testing.assert_allclose(tree.lookup("odom", "camera", 990_000_000)[:3, 3], [0.99, 0, 0])
