"""Shared fixtures: free ports, an in-process loopback zenoh router, small synthetic recordings,
and a private rerun config directory (rerun writes its analytics config on first use)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from helpers.synthetic import render_small_recording
from hypothesis import HealthCheck, settings

from gngdt.services.plumbing.session import client_config, free_tcp_port, open_config, router_config

REPO_ROOT = Path(__file__).resolve().parents[1]
# the benchmarks' own helpers (hostile recordings) are the tests' too: tests may import
# benchmarks/, never the other way round
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))

# One Hypothesis profile everywhere: with CI=true Hypothesis would otherwise switch to its "ci"
# profile (derandomised, no database) while developers ran randomised tests whose failures the
# .hypothesis/ database then replayed. Derandomised and database-free, every machine runs the
# same examples; widen the search by hand with `pytest --hypothesis-seed=N`.
settings.register_profile(
    "gngdt",
    derandomize=True,
    database=None,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile("gngdt")


@pytest.fixture(autouse=True, scope="session")
def _private_rerun_config(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    previous = os.environ.get("XDG_CONFIG_HOME")
    os.environ["XDG_CONFIG_HOME"] = str(tmp_path_factory.mktemp("xdg-config"))
    yield
    if previous is None:
        os.environ.pop("XDG_CONFIG_HOME", None)
    else:
        os.environ["XDG_CONFIG_HOME"] = previous


@pytest.fixture
def free_port() -> int:
    return free_tcp_port()


@pytest.fixture
def router_endpoint(free_port: int) -> Iterator[str]:
    """A zenoh router (this process, mode router) on a free loopback port; yields its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port}"
    session = open_config(router_config([endpoint]), what="router")
    yield endpoint
    session.close()


@pytest.fixture(scope="session")
def data2_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8-frame 320x240 recording of the paper's Data2 scene (rendered once per session)."""
    return render_small_recording(tmp_path_factory.mktemp("recordings"), "data2", 8)


@pytest.fixture(scope="session")
def one_frame_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A single 320x240 frame of the tabletop scene without a pose: a static camera."""
    return render_small_recording(tmp_path_factory.mktemp("one_frame"), "tabletop", 1,
                                  poses=False)


@pytest.fixture(scope="session")
def tabletop_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8-frame 320x240 synthetic tabletop recording (rendered once per session)."""
    return render_small_recording(tmp_path_factory.mktemp("recordings"), "tabletop", 8)


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[..., subprocess.Popen]]:
    """Start ``python -m gngdt.services.cli ARGS...`` in its own process group; output to a log file
    in tmp_path (``process.log_path``). Every process is killed at teardown, pass or fail."""
    processes: list[subprocess.Popen] = []

    def start(*arguments: str) -> subprocess.Popen:
        log_path = tmp_path / f"{arguments[0]}-{len(processes)}.log"
        with open(log_path, "wb") as log_file:
            process = subprocess.Popen(
                [sys.executable, "-m", "gngdt.services.cli", *arguments],
                cwd=REPO_ROOT, stdout=log_file, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, start_new_session=True,
            )
        process.log_path = log_path  # type: ignore[attr-defined]
        processes.append(process)
        return process

    yield start
    for process in processes:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


@dataclass
class CaptureOutput:
    """What one capture run published: decoded clouds (and each one's frame_id and pose),
    end-of-stream messages, its log."""

    clouds: list = field(default_factory=list)
    poses: list = field(default_factory=list)
    ends: list = field(default_factory=list)
    log: str = ""


@pytest.fixture
def run_capture(router_endpoint: str, spawn: Callable) -> Callable[..., CaptureOutput]:
    """``run_capture(RECORDING, *OPTIONS)`` runs `gngdt capture RECORDING --fast --realtime
    OPTIONS` to its end against ``router_endpoint`` (expecting exit status ``exit_code``) and
    returns what it published on the default camera (no learner listens: real time)."""
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    from gngdt.schemas.clouds import cloud_pose, msg_to_cloud
    from gngdt.schemas.status import decode_stream_end

    def on_points(output: CaptureOutput, payload: bytes) -> None:
        message = PointCloud.FromString(payload)
        output.clouds.append(msg_to_cloud(message))
        output.poses.append((message.frame_id, cloud_pose(message)))

    def run(recording: Path, *options: str, exit_code: int = 0) -> CaptureOutput:
        output = CaptureOutput()
        session = open_config(client_config([router_endpoint]))
        session.declare_subscriber("gngdt/camera/points", lambda sample: on_points(
            output, sample.payload.to_bytes()))
        session.declare_subscriber("gngdt/camera/eos", lambda sample: output.ends.append(
            decode_stream_end(sample.payload.to_bytes())))
        try:
            capture = spawn("capture", str(recording), "--fast", "--realtime",
                            "--zenoh-connect", router_endpoint, *options)
            assert capture.wait(60) == exit_code, Path(capture.log_path).read_text()
            deadline = time.monotonic() + 10
            while not output.ends and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            session.close()
        output.log = Path(capture.log_path).read_text()
        return output

    return run
