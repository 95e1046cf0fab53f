"""Deployments beyond `gngdt run`: services as zenoh clients of a standalone router, configured
from the files in config/, and several cameras sharing one router and one logger.

Every service is a separate process (the ``spawn`` fixture kills them all at teardown, pass or
fail); the test itself listens as one more zenoh client of the router.
"""

from __future__ import annotations

import re
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.processes import log_text, wait_exit
from helpers.rrd import DESIGN_ENTITIES, rrd_entities_and_scalars

from gngdt.schemas.topology import TopologySnapshot, decode_topology
from gngdt.services.plumbing.session import client_config, open_config

REPO_ROOT = Path(__file__).resolve().parents[2]
CLIENT_CONFIG = REPO_ROOT / "config" / "zenoh-client.json5"
ROUTER_CONFIG = REPO_ROOT / "config" / "zenoh-router.json5"
#: 10 frames, 320x240 (recordings/README.md)
SMALL_RECORDING = REPO_ROOT / "recordings" / "tabletop_small.mcap"
SMALL_RECORDING_FRAMES = 10
CLUSTERINGS = {"pos", "col", "nor", "col+nor", "segments"}
#: learning steps per frame: enough for a few dozen nodes, little enough to keep the tests fast
SAMPLES_PER_FRAME = "3000"


def client_config_file(directory: Path, endpoint: str) -> Path:
    """A copy of config/zenoh-client.json5 whose connect endpoint is ``endpoint``."""
    text = CLIENT_CONFIG.read_text()
    text, count = re.subn(r"(connect:\s*\{\s*endpoints:\s*\[)[^\]]*\]", rf'\g<1>"{endpoint}"]',
                          text)
    assert count == 1, f"{CLIENT_CONFIG} has no single connect/endpoints list to point at the test"
    path = directory / f"client-{endpoint.rsplit(':', 1)[-1]}.json5"
    path.write_text(text)
    return path


def camera_entities(camera: str) -> set[str]:
    """the contract's entity paths as the logger writes them for a non-default camera."""
    return {re.sub(r"^/(world|metrics)/", rf"/\g<1>/{camera}/", path) for path in DESIGN_ENTITIES}


class TopologyWatcher:
    """A test-side zenoh client collecting every camera's topologies (``gngdt/*/topology``)."""

    def __init__(self, endpoint: str) -> None:
        self.session = open_config(client_config([endpoint]))
        self._lock = threading.Lock()
        self._topologies: dict[str, list[TopologySnapshot]] = {}
        self._subscriber = self.session.declare_subscriber("gngdt/*/topology", self._on_topology)

    def _on_topology(self, sample) -> None:
        camera = str(sample.key_expr).split("/")[1]
        snapshot = decode_topology(sample.payload.to_bytes())
        with self._lock:
            self._topologies.setdefault(camera, []).append(snapshot)

    def topologies(self) -> dict[str, list[TopologySnapshot]]:
        with self._lock:
            return {camera: list(snapshots) for camera, snapshots in self._topologies.items()}

    def wait_alive(self, keys: list[str], timeout_s: float) -> None:
        """Wait until a liveliness token matches each of ``keys`` (services are up)."""
        deadline = time.monotonic() + timeout_s
        missing = list(keys)
        while missing and time.monotonic() < deadline:
            missing = [key for key in missing
                       if not list(self.session.liveliness().get(key, timeout=1))]
            if missing:
                time.sleep(0.1)
        assert not missing, f"no liveliness token for {missing} within {timeout_s} s"

    def close(self) -> None:
        self._subscriber.undeclare()
        self.session.close()


def wait_for_log_line(process: subprocess.Popen, text: str, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if text in log_text(process):
            return
        assert process.poll() is None, f"exited with {process.returncode}:\n{log_text(process)}"
        time.sleep(0.05)
    raise AssertionError(f"{text!r} not printed within {timeout_s} s:\n{log_text(process)}")


def assert_learned_to_the_end(snapshots: list[TopologySnapshot], camera: str,
                              last_sequence: int, frame_id: str | None = None) -> None:
    """The camera's topologies grew, were published for its last frame, with every clustering,
    in ``frame_id`` (default: the camera's own frame, a recording without poses)."""
    assert snapshots, f"no topology from the {camera} learner"
    last = snapshots[-1]
    assert last.frame_id == (frame_id or camera)
    assert last.frame_sequence == last_sequence, [s.frame_sequence for s in snapshots]
    assert last.node_count > 10
    assert set(last.clusterings) == CLUSTERINGS
    assert all(len(labels) == last.node_count for labels in last.clusterings.values())
    steps = [snapshot.steps for snapshot in snapshots]
    assert steps == sorted(steps) and steps[-1] > 0, steps


@pytest.fixture
def standalone_router(spawn: Callable, free_port: int) -> str:
    """`gngdt router` from config/zenoh-router.json5 on a free loopback port; its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port}"
    router = spawn("router", "--zenoh-config", str(ROUTER_CONFIG), "--listen", endpoint)
    wait_for_log_line(router, f"listening on {endpoint}", 30)
    return endpoint


@pytest.mark.timeout(180)
def test_services_reach_each_other_only_through_a_standalone_router(
    standalone_router: str, spawn: Callable, tmp_path: Path
) -> None:
    config = ["--zenoh-config", str(client_config_file(tmp_path, standalone_router))]
    rrd_path = tmp_path / "through-router.rrd"
    watcher = TopologyWatcher(standalone_router)
    try:
        learner = spawn("learn", "--exit-on-eos", "--samples-per-frame", SAMPLES_PER_FRAME,
                        *config)
        logger = spawn("log", "--save", str(rrd_path), *config)
        watcher.wait_alive(["gngdt/camera/learner/alive", "gngdt/logger/alive/**"], 60)
        capture = spawn("capture", str(SMALL_RECORDING), "--rate", "0.3", *config)
        assert wait_exit(capture, 60) == 0, log_text(capture)
        assert wait_exit(learner, 60) == 0, log_text(learner)
        assert wait_exit(logger, 60) == 0, log_text(logger)
        topologies = watcher.topologies()
    finally:
        watcher.close()

    assert set(topologies) == {"camera"}
    assert_learned_to_the_end(topologies["camera"], "camera", SMALL_RECORDING_FRAMES - 1)
    entities, scalars = rrd_entities_and_scalars(rrd_path)
    assert entities >= DESIGN_ENTITIES, sorted(DESIGN_ENTITIES - entities)
    logged_nodes = dict(scalars["/metrics/nodes"])
    last = topologies["camera"][-1]
    assert logged_nodes[last.frame_sequence] == last.node_count


@pytest.mark.timeout(60)
def test_a_client_without_its_router_fails_clearly(
    spawn: Callable, free_port: int, tmp_path: Path
) -> None:
    nobody = f"tcp/127.0.0.1:{free_port}"  # free: no router listens there
    learner = spawn("learn", "--zenoh-config", str(client_config_file(tmp_path, nobody)),
                    "--router-wait", "1")
    assert wait_exit(learner, 45) == 1, log_text(learner)
    assert f"no zenoh router at {nobody} yet" in log_text(learner)  # it waited, and said so
    assert nobody in log_text(learner)
    assert "gngdt router" in log_text(learner)


@pytest.mark.timeout(240)
def test_two_cameras_two_learners_one_logger(
    standalone_router: str, data2_recording: Path, spawn: Callable, tmp_path: Path
) -> None:
    # different scenes and lengths per camera, so crossed streams cannot go unnoticed; the
    # rendered recording has camera poses (its capture first reads /tf, so it starts first: the
    # logger stops once every camera it has heard of has ended), the bundled one has none
    recordings = {"right": (data2_recording, 8), "left": (SMALL_RECORDING, SMALL_RECORDING_FRAMES)}
    frame_ids = {"left": "left", "right": "world"}
    config = ["--zenoh-config", str(client_config_file(tmp_path, standalone_router))]
    rrd_path = tmp_path / "two-cameras.rrd"
    watcher = TopologyWatcher(standalone_router)
    try:
        learners = {cam: spawn("learn", "--cam", cam, "--exit-on-eos", "--samples-per-frame",
                               SAMPLES_PER_FRAME, *config) for cam in recordings}
        logger = spawn("log", "--save", str(rrd_path), *config)
        watcher.wait_alive([f"gngdt/{cam}/learner/alive" for cam in recordings]
                           + ["gngdt/logger/alive/**"], 90)
        captures = {cam: spawn("capture", str(path), "--cam", cam, "--rate", "0.3", *config)
                    for cam, (path, _) in recordings.items()}
        for process in [*captures.values(), *learners.values(), logger]:
            assert wait_exit(process, 90) == 0, log_text(process)
        topologies = watcher.topologies()
    finally:
        watcher.close()

    assert set(topologies) == set(recordings)
    for cam, (_, frames) in recordings.items():
        assert_learned_to_the_end(topologies[cam], cam, frames - 1, frame_ids[cam])
    entities, scalars = rrd_entities_and_scalars(rrd_path)
    for cam in recordings:
        expected = camera_entities(cam)
        assert entities >= expected, sorted(expected - entities)
        logged_nodes = dict(scalars[f"/metrics/{cam}/nodes"])
        last = topologies[cam][-1]
        assert logged_nodes[last.frame_sequence] == last.node_count, cam
    assert not any(path.startswith("/world/gng/") for path in entities), "default camera logged"


@pytest.mark.timeout(60)
def test_router_refuses_a_missing_config_file(
    spawn: Callable, free_port: int, tmp_path: Path
) -> None:
    missing = tmp_path / "no-such-router.json5"
    router = spawn("router", "--zenoh-config", str(missing), "--listen",
                   f"tcp/127.0.0.1:{free_port}")
    assert wait_exit(router, 45) == 1, log_text(router)
    assert "no-such-router.json5" in log_text(router)
