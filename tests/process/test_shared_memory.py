"""Large payloads through zenoh shared memory on one host, the network otherwise: real sessions
on a loopback router (``gngdt.services.plumbing.session.SharedMemoryPublisher``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from gngdt.services.plumbing.session import (
    SHARED_MEMORY_MIN_BYTES,
    client_config,
    declare_publisher,
    open_config,
    through_shared_memory,
    wait_for_subscribers,
)

REPO_ROOT = Path(__file__).resolve().parents[2]
KEY = "gngdt/shmtest/points"


class Received:
    """Samples of one key: payload bytes, whether each came through shared memory, and (when
    ``hold``) the samples themselves, which keeps their shared-memory buffers in use."""

    def __init__(self, hold: bool = False) -> None:
        self.hold = hold
        self.payloads: list[bytes] = []
        self.shared: list[bool] = []
        self.held: list[object] = []
        self.lock = threading.Lock()

    def __call__(self, sample) -> None:
        with self.lock:
            self.payloads.append(sample.payload.to_bytes())
            self.shared.append(through_shared_memory(sample))
            if self.hold:
                self.held.append(sample)

    def wait(self, count: int, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while len(self.payloads) < count and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(self.payloads) == count, f"received {len(self.payloads)} of {count}"


@pytest.fixture
def subscriber(router_endpoint: str) -> Iterator[tuple[object, Received]]:
    session = open_config(client_config([router_endpoint]))
    received = Received()
    subscription = session.declare_subscriber(KEY, received)
    yield session, received
    subscription.undeclare()
    session.close()


def payloads(count: int, size: int) -> list[bytes]:
    return [bytes([index % 251]) * size for index in range(count)]


def publish(router_endpoint: str, sent: list[bytes], shared_memory: bool = True,
            latest_wins: bool = True, pool_bytes: int | None = None):
    """Publish ``sent`` from a new client session; the publisher (its counters)."""
    config = client_config([router_endpoint])
    config.insert_json5("transport/shared_memory/enabled", json.dumps(shared_memory))
    session = open_config(config)
    try:
        publisher = declare_publisher(session, KEY, "application/octet-stream", latest_wins,
                                      pool_bytes=pool_bytes)
        assert wait_for_subscribers(publisher, 10.0)
        for payload in sent:
            publisher.put(payload, attachment=b"a")
            time.sleep(0.02)
        time.sleep(0.2)
        publisher.undeclare()
    finally:
        session.close()
    return publisher


@pytest.mark.timeout(60)
def test_large_payloads_go_through_shared_memory_intact(router_endpoint: str,
                                                        subscriber) -> None:
    _, received = subscriber
    sent = payloads(5, 1_000_000)
    publisher = publish(router_endpoint, sent)
    received.wait(5)
    assert received.payloads == sent
    assert received.shared == [True] * 5  # through the router by reference
    assert (publisher.sent_shared, publisher.sent_network) == (5, 0)


@pytest.mark.timeout(60)
def test_small_and_must_arrive_payloads_are_sent_as_they_are(router_endpoint: str,
                                                             subscriber) -> None:
    _, received = subscriber
    small = payloads(3, 1000)  # below zenoh's own 3 kB threshold too
    publisher = publish(router_endpoint, small)
    received.wait(3)
    assert received.payloads == small and received.shared == [False] * 3
    assert (publisher.sent_shared, publisher.sent_network) == (0, 0)
    large = payloads(2, SHARED_MEMORY_MIN_BYTES * 2)
    blocking = publish(router_endpoint, large, latest_wins=False)  # calibration, status, eos
    received.wait(5)
    assert received.payloads[3:] == large
    assert (blocking.sent_shared, blocking.sent_network) == (0, 0)


@pytest.mark.timeout(60)
def test_without_shared_memory_on_the_link_payloads_go_over_the_network(
        router_endpoint: str, subscriber) -> None:
    _, received = subscriber
    sent = payloads(3, 1_000_000)
    publisher = publish(router_endpoint, sent, shared_memory=False)
    received.wait(3)
    assert received.payloads == sent and received.shared == [False] * 3
    assert (publisher.sent_shared, publisher.sent_network) == (0, 3)


@pytest.mark.timeout(60)
def test_a_full_pool_sends_over_the_network_instead(router_endpoint: str) -> None:
    session = open_config(client_config([router_endpoint]))
    received = Received(hold=True)  # holds every sample: their buffers stay in use
    subscription = session.declare_subscriber(KEY, received)
    try:
        sent = payloads(4, 1_000_000)
        publisher = publish(router_endpoint, sent, pool_bytes=int(2.5 * 2**20))  # room for 2
        received.wait(4)
    finally:
        subscription.undeclare()
        session.close()
    assert received.payloads == sent
    assert received.shared[:2] == [True, True]  # (zenoh's own pool may carry the others)
    assert (publisher.sent_shared, publisher.sent_network) == (2, 2)


@pytest.mark.timeout(60)
def test_the_learners_queue_holds_copies_not_the_captures_pool(router_endpoint: str) -> None:
    """The tracker's queue keeps up to 32 clouds while the first map is learned. Holding the
    samples kept the capture's pool (8 clouds) full, and the rest went over the network: 230 of
    300 clouds in one live run. The queue copies each one out as it arrives."""
    from gngdt.services.learner.tracking import FrameQueue

    session = open_config(client_config([router_endpoint]))
    queue = FrameQueue(max_cloud_points=100_000)
    subscription = session.declare_subscriber(KEY, queue.put)
    try:
        sent = payloads(6, 1_000_000)
        publisher = publish(router_endpoint, sent, pool_bytes=int(2.5 * 2**20))  # room for 2
        deadline = time.monotonic() + 10
        while len(queue) < 6 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        subscription.undeclare()
        session.close()
    waiting = [queue.get(0.0) for _ in range(len(queue))]
    assert [received.payload for received in waiting] == sent
    assert all(received.shared for received in waiting)
    assert (publisher.sent_shared, publisher.sent_network) == (6, 0)


@pytest.mark.timeout(60)
def test_pool_size_zero_leaves_payloads_to_zenoh(router_endpoint: str, subscriber) -> None:
    _, received = subscriber
    sent = payloads(2, 1_000_000)
    publisher = publish(router_endpoint, sent, pool_bytes=0)
    received.wait(2)
    assert received.payloads == sent
    assert (publisher.sent_shared, publisher.sent_network) == (0, 0)


_PUBLISHER_SCRIPT = """
import logging, sys, time
logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
from gngdt.services.plumbing.session import (client_config, declare_publisher, open_config,
                                       wait_for_subscribers)
session = open_config(client_config([sys.argv[1]]))
publisher = declare_publisher(session, sys.argv[2], "application/octet-stream", True)
assert wait_for_subscribers(publisher, 10.0)
for index in range(3):
    publisher.put(bytes([index]) * 1_000_000)
    time.sleep(0.05)
time.sleep(0.3)
print("COUNTS", publisher.sent_shared, publisher.sent_network, flush=True)
publisher.undeclare()
session.close()
"""


def run_publisher(router_endpoint: str, wrapper: str, folder: Path
                  ) -> subprocess.CompletedProcess:
    """The publisher script in a shell ``wrapper`` (``{}`` stands for the command)."""
    script = folder / "publisher.py"
    script.write_text(_PUBLISHER_SCRIPT)
    command = wrapper.format(f"{sys.executable} {script} {router_endpoint} {KEY}")
    return subprocess.run(["sh", "-c", command], cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=45, env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})


@pytest.mark.timeout(60)
def test_a_process_that_cannot_lock_its_pool_publishes_over_the_network(
        router_endpoint: str, subscriber, tmp_path: Path) -> None:
    """A publisher limited to 1 MiB of locked memory, as a container is by default: its pool
    cannot be made, it says so once with the remedy, and every payload arrives intact."""
    if os.geteuid() != 0 or shutil.which("capsh") is None:
        pytest.skip("needs root and capsh(1) to drop CAP_IPC_LOCK and lower the memlock limit")
    _, received = subscriber
    result = run_publisher(router_endpoint, "capsh --drop=cap_ipc_lock -- -c 'ulimit -l 1024 "
                           "&& exec {}'", tmp_path)
    assert result.returncode == 0, result.stderr
    received.wait(3)
    assert received.payloads == [bytes([index]) * 1_000_000 for index in range(3)]
    assert "COUNTS 0 3" in result.stdout
    assert result.stderr.count("no shared memory") == 1, result.stderr
    assert "ulimit -l" in result.stderr and "memlock" in result.stderr


@pytest.mark.timeout(60)
def test_a_process_with_its_own_dev_shm_publishes_over_the_network(
        router_endpoint: str, subscriber, tmp_path: Path) -> None:
    """A publisher with a /dev/shm of its own (another container, another host): zenoh finds no
    shared memory on the link; every payload arrives intact over the network, said once."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("needs root and unshare(1) to give a process its own /dev/shm")
    _, received = subscriber
    result = run_publisher(router_endpoint, "unshare -m sh -c 'mount --make-rprivate / && "
                           "mount -t tmpfs -o size=64m tmpfs /dev/shm && exec {}'", tmp_path)
    assert result.returncode == 0, result.stderr
    received.wait(3)
    assert received.payloads == [bytes([index]) * 1_000_000 for index in range(3)]
    assert received.shared == [False] * 3
    assert "COUNTS 0 3" in result.stdout
    assert result.stderr.count("no shared memory on the link") == 1, result.stderr
