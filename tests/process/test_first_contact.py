"""First contact: what a new user meets starting services by hand and `gngdt run` on a wrong
input, from an odd folder, with signals and with a hostile neighbour on loopback."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.processes import (
    alive,
    bound_sockets,
    children,
    command_line,
    log_text,
    wait_for,
    with_default_sighup,
)

from gngdt.services.plumbing.session import ZenohSetupError, client_config, open_config

REPO_ROOT = Path(__file__).resolve().parents[2]
GNGDT = [sys.executable, "-m", "gngdt.services.cli"]


# ------------------------------------------------------------------------ services by hand
@pytest.mark.timeout(150)
def test_services_started_before_their_router_wait_for_it(
    free_port: int, tabletop_recording: Path, spawn: Callable, tmp_path: Path
) -> None:
    from gngdt.schemas.status import decode_status

    endpoint = f"tcp/127.0.0.1:{free_port}"
    connect = ("--zenoh-connect", endpoint)
    checkpoint = tmp_path / "learner.npz"
    learner = spawn("learn", "--samples-per-frame", "1000", "--checkpoint", str(checkpoint),
                    "--checkpoint-every", "1", *connect)
    capture = spawn("capture", str(tabletop_recording), "--fast", *connect)
    wait_for(lambda: "no zenoh router at" in log_text(capture), 60, "capture to wait for it")
    wait_for(lambda: "no zenoh router at" in log_text(learner), 60, "the learner to wait for it")
    assert capture.poll() is None and learner.poll() is None
    router = spawn("router", "--listen", endpoint)
    statuses: list = []
    wait_for(lambda: "listening on" in log_text(router), 30, "the router")
    watcher = open_config(client_config([endpoint]))
    watcher.declare_subscriber("gngdt/camera/learner/status", lambda sample: statuses.append(
        decode_status(sample.payload.to_bytes())))
    try:
        assert capture.wait(90) == 0, log_text(capture)
        learner.send_signal(signal.SIGINT)
        assert learner.wait(30) == 0, log_text(learner)
    finally:
        watcher.close()
    assert "connected to the zenoh router after" in log_text(capture)
    assert "replaying" in log_text(capture) and "frames over" in log_text(capture)
    logged = log_text(learner)
    assert "connected to the zenoh router after" in logged
    assert "preparing the learning kernels" in logged and "kernels ready in" in logged
    assert "INFO gngdt.services.learner: checkpoint" not in logged  # one per frame here: DEBUG only
    assert checkpoint.exists()


@pytest.mark.timeout(60)
def test_a_router_on_a_port_in_use_says_so(free_port: int, spawn: Callable) -> None:
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", free_port))
        taken.listen()
        router = spawn("router", "--listen", f"tcp/127.0.0.1:{free_port}")
        assert router.wait(30) == 1
    logged = log_text(router)
    assert f"cannot open a zenoh router on tcp/127.0.0.1:{free_port}" in logged
    assert "already listens there" in logged and "endpoints []" not in logged


@pytest.mark.timeout(150)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_the_router_stops_on_the_first_signal_even_while_starting(
    signum: int, free_port: int, tmp_path: Path
) -> None:
    command = with_default_sighup([*GNGDT, "router", "--listen", f"tcp/127.0.0.1:{free_port}"])
    started: list[subprocess.Popen] = []  # stopped by pid whatever happens
    try:
        with open(tmp_path / "early.log", "wb") as output:
            early = subprocess.Popen(command, cwd=REPO_ROOT, stdout=output, stderr=output,
                                     start_new_session=True)
            started.append(early)
            time.sleep(0.3)  # still importing: the signal used to be lost here
            early.send_signal(signum)
            # stopped by our handler (0, 130), or by the signal itself when it came before
            # gngdt's first line ran (on a loaded machine Python may still be starting), or by
            # SIGINT: with the signal landing in the imports (seen at 0.3-0.6 s), main() caught the
            # KeyboardInterrupt (no traceback) yet Python exited by killing itself with SIGINT
            # (strace) -- CPython's "unhandled KeyboardInterrupt" flag, which code an extension runs
            # through PyRun_* while importing can set; shells report it as 130 all the same
            try:
                code = early.wait(60)  # a loaded machine may still be starting Python
            except subprocess.TimeoutExpired:
                pytest.fail("still running 60 s after the signal:\n"
                            + (tmp_path / "early.log").read_text())
            assert code in (0, 130, -signum, -signal.SIGINT), \
                (tmp_path / "early.log").read_text()
        # once serving, with zenoh's own log on (RUST_LOG, as zenoh's examples)
        with open(tmp_path / "serving.log", "wb") as output:
            serving = subprocess.Popen(command, cwd=REPO_ROOT, stdout=output, stderr=output,
                                       start_new_session=True,
                                       env={**os.environ, "RUST_LOG": "info"})
            started.append(serving)
            wait_for(lambda: "listening on" in (tmp_path / "serving.log").read_text(), 30,
                     "the router")
            serving.send_signal(signum)
            assert serving.wait(20) == 0
    finally:
        for process in started:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    logged = (tmp_path / "serving.log").read_text()
    assert "Zenoh can be reached at" in logged  # zenoh's own INFO line
    assert f"router stopped ({signal.Signals(signum).name})" in logged


# ------------------------------------------------------------------------------ gngdt run
@pytest.mark.parametrize(("target", "reason"), [
    ("README.md", "is not an MCAP file"),
    ("recordings", "no known image layout (redwood: color/ + depth/; tum: rgb.txt + "
                   "depth.txt; pcl-tiff: frame_*_rgb.tiff + frame_*_depth.tiff); "
                   "recordings inside: data2.mcap"),
    ("empty.mcap", "is empty (0 bytes)"),
    ("missing.mcap", "no such file"),
])
def test_run_refuses_what_is_not_a_recording_on_the_terminal(
    target: str, reason: str, tmp_path: Path
) -> None:
    (tmp_path / "empty.mcap").touch()
    path = REPO_ROOT / target if (REPO_ROOT / target).exists() else tmp_path / target
    completed = subprocess.run([*GNGDT, "run", str(path)], cwd=REPO_ROOT, capture_output=True,
                               text=True, timeout=60)
    assert completed.returncode == 2
    assert reason in completed.stderr


@pytest.mark.timeout(120)
def test_a_damaged_recording_fails_capture_and_run(
    router_endpoint: str, spawn: Callable, tabletop_recording: Path, tmp_path: Path
) -> None:
    damaged = tmp_path / "damaged.mcap"
    magic = tabletop_recording.read_bytes()[:8]
    damaged.write_bytes(magic + os.urandom(4000))
    capture = spawn("capture", str(damaged), "--fast", "--realtime", "--wait-subscribers", "0",
                    "--zenoh-connect", router_endpoint)
    assert capture.wait(60) == 2, log_text(capture)
    assert "damaged.mcap" in log_text(capture) and "Traceback" not in log_text(capture)
    completed = subprocess.run([*GNGDT, "run", str(damaged), "--fast", "--save",
                                str(tmp_path / "run.rrd")], cwd=REPO_ROOT, capture_output=True,
                               text=True, timeout=100)
    assert completed.returncode == 2, completed.stdout + completed.stderr
    assert "capture failed (exit 2)" in completed.stderr and "damaged.mcap" in completed.stderr


def _run_listener_port(pid: int) -> int:
    """The TCP port `gngdt run`'s own router listens on."""
    listeners = [address for protocol, address, state in bound_sockets(pid)
                 if state == "listen" and protocol == "tcp"]
    assert len(listeners) == 1, listeners
    return int(listeners[0].rsplit(":", 1)[1])


@pytest.mark.timeout(150)
def test_run_from_a_folder_shadowing_gngdt_admits_only_its_children_and_leaves_no_orphan(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    # the user's folder holds packages named like gngdt's: they must not be imported
    for package in ("services", "schemas"):
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("raise ImportError('shadowed')\n")
    gngdt = Path(sys.executable).parent / "gngdt"
    assert gngdt.exists(), "the gngdt console script (pip install -e .)"
    log_path = tmp_path / "run.log"
    with open(log_path, "wb") as output:
        # a replay of minutes: it is still running when the signal comes, however long the
        # intruder's refusal takes on a loaded machine
        run = subprocess.Popen(
            with_default_sighup([str(gngdt), "run", str(tabletop_recording), "--rate", "0.001",
                                 "--save", str(tmp_path / "run.rrd")]),
            cwd=tmp_path, stdout=output, stderr=output, start_new_session=True)
    try:
        wait_for(lambda: "replaying" in log_path.read_text(), 90, "the services to come up")
        pids = children(run.pid)
        assert len(pids) == 3, log_path.read_text()  # learner, logger, capture
        # a neighbour without the run's credentials cannot even open a session on its router
        intruder = client_config([f"tcp/127.0.0.1:{_run_listener_port(run.pid)}"])
        intruder.insert_json5("connect/timeout_ms", "2000")
        with pytest.raises(ZenohSetupError):
            open_config(intruder)
        run.send_signal(signal.SIGHUP)  # the terminal closed
        assert run.wait(60) == 130, log_path.read_text()
    finally:
        if run.poll() is None:
            run.kill()
    wait_for(lambda: not any(alive(pid) for pid in pids), 30, "the children to stop")
    text = log_path.read_text()
    assert "ended early:        interrupted (SIGHUP)" in text
    assert "shadowed" not in text


@pytest.mark.timeout(120)
def test_children_of_a_killed_run_stop_too(tabletop_recording: Path, tmp_path: Path) -> None:
    log_path = tmp_path / "run.log"
    with open(log_path, "wb") as output:
        run = subprocess.Popen([*GNGDT, "run", str(tabletop_recording), "--rate", "0.01",
                                "--save", str(tmp_path / "run.rrd")], cwd=REPO_ROOT,
                               stdout=output, stderr=output, start_new_session=True)
    try:
        wait_for(lambda: "replaying" in log_path.read_text(), 90, "the services to come up")
        pids = children(run.pid)
        assert len(pids) == 3
    finally:
        run.kill()  # SIGKILL: run cannot clean up; the kernel tells the children
        run.wait()
    try:
        wait_for(lambda: not any(alive(pid) for pid in pids), 30, "the orphans to stop")
    except AssertionError:
        lingering = {pid: " ".join(command_line(pid)) for pid in pids if alive(pid)}
        raise AssertionError(f"still running 30 s after the run was killed: {lingering}; the "
                             f"run's log:\n{log_path.read_text()}") from None


def test_run_refuses_a_bag_without_calibration_before_starting_anything(tmp_path: Path) -> None:
    from helpers.recordings import make_frames
    from helpers.ros2_bags import write_ros_bag

    bag = tmp_path / "no_info.mcap"
    write_ros_bag(bag, make_frames(2), color_encoding="rgb8", depth_encoding="16UC1",
                  camera_info=False)
    completed = subprocess.run([*GNGDT, "run", str(bag)], cwd=REPO_ROOT, capture_output=True,
                               text=True, timeout=60)
    assert completed.returncode == 2
    assert "no calibration channel" in completed.stderr and "--camera-json FILE" in completed.stderr
    assert "starting the learner" not in completed.stderr  # said before anything started
