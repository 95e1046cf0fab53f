"""The pipeline as separate processes on a loopback zenoh router: run, late joiner, resume."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.pipeline import Watcher, points_publisher
from helpers.processes import log_text, wait_exit
from helpers.rrd import DESIGN_ENTITIES, rrd_entities_and_scalars

from gngdt.schemas.clouds import cloud_to_msg
from gngdt.schemas.topology import decode_topology
from gngdt.schemas.wire import FrameStamp
from gngdt.services.plumbing.session import client_config, open_config

REPO_ROOT = Path(__file__).resolve().parents[2]


#: stated tolerance of the learned cluster counts against the scene's ground truth: colour
#: regions are well separated (+-1); normal clusters of a young network split the curved
#: cylinder or merge across the prism's edges (+-2)
CLUSTER_TOLERANCE = {"col": 1, "nor": 2}


@pytest.mark.timeout(240)
def test_run_learns_the_scene_and_writes_the_rrd(data2_recording: Path, tmp_path: Path) -> None:
    from gngdt.io.synth.render import SCENE_GROUND_TRUTH

    rrd_path = tmp_path / "run.rrd"
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(data2_recording), "--save",
         str(rrd_path), "--rate", "0.2", "--samples-per-frame", "40000"],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=200,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert re.search(r"frames sent:\s+8", completed.stdout), completed.stdout
    learned = int(re.search(r"frames learned:\s+(\d+)", completed.stdout).group(1))
    assert learned >= 4, completed.stdout
    # a static scene: the learner's forgetting leaves next to no ghosts
    ghosts = re.search(r"forgetting:\s+(\d+) nodes forgotten; ghost share ([\d.]+)% \(seen nodes "
                       r"> 5 cm from the last frame\)", completed.stdout)
    assert ghosts is not None and float(ghosts.group(2)) < 2.0, completed.stdout
    assert str(rrd_path) in completed.stdout

    entities, scalars = rrd_entities_and_scalars(rrd_path)
    assert entities >= DESIGN_ENTITIES, sorted(DESIGN_ENTITIES - entities)
    truth = SCENE_GROUND_TRUTH["data2"]
    final = {name: max(scalars[f"/metrics/clusters/{name}"])[1] for name in CLUSTER_TOLERANCE}
    for name, tolerance in CLUSTER_TOLERANCE.items():
        assert abs(final[name] - truth[name]) <= tolerance, (name, final, truth)
    assert max(scalars["/metrics/nodes"])[1] > 100


@pytest.mark.timeout(180)
def test_a_one_frame_recording_settles_for_one_frame_and_says_why_it_stayed_small(
        one_frame_recording: Path, tmp_path: Path) -> None:
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(one_frame_recording), "--save",
         str(tmp_path / "one.rrd"), "--max-nodes", "200"],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=150,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    # one frame is 10,000 steps; settling on it adds at most one frame's steps (the last view
    # must not outweigh the stream), so 200 nodes at one per 500 steps are out of reach ...
    steps = int(re.search(r"learning steps:\s+(\d+)", completed.stdout).group(1))
    nodes = int(re.search(r"nodes:\s+(\d+)", completed.stdout).group(1))
    assert 10_000 < steps <= 20_000 and nodes <= 2 + steps // 500, completed.stdout
    assert re.search(r"last frame:\s+stopped after 10,000 more steps on the last frame \(at most "
                     r"a frame's\)", completed.stdout), completed.stdout
    # ... and the summary says why the network stayed small, and what grows it
    assert f"WARNING: the network has {nodes} of its 200 nodes" in completed.stdout
    assert "frames learned:     1 of 1 sent (100%)" in completed.stdout


@pytest.mark.timeout(180)
def test_late_joiner_gets_the_current_topology(
    router_endpoint: str, tabletop_recording: Path, spawn: Callable
) -> None:
    connect = ["--zenoh-connect", router_endpoint]
    learner = spawn("learn", "--samples-per-frame", "5000", *connect)
    watcher = Watcher(router_endpoint)
    try:
        capture = spawn("capture", str(tabletop_recording), "--rate", "0.5", *connect)
        assert wait_exit(capture, 90) == 0, log_text(capture)
        # the learner settles on the last frame after the end of stream: its final topology
        statuses = watcher.wait_for(lambda s: bool(s) and s[-1].settled, 60)
        last = statuses[-1]
        assert last.frame_sequence == 7
    finally:
        watcher.close()

    late = open_config(client_config([router_endpoint]))
    try:
        replies = list(late.get("gngdt/camera/topology", timeout=10))
    finally:
        late.close()
    assert len(replies) == 1 and replies[0].ok is not None
    snapshot = decode_topology(replies[0].ok.payload.to_bytes())
    assert snapshot.frame_sequence == 7
    assert snapshot.steps == last.steps
    assert snapshot.node_count == last.nodes > 2
    assert set(snapshot.clusterings) == {"pos", "col", "nor", "col+nor", "segments"}
    assert FrameStamp.from_attachment(replies[0].ok.attachment.to_bytes()).sequence == 7

    learner.send_signal(signal.SIGINT)
    assert wait_exit(learner, 30) == 0, log_text(learner)


@pytest.mark.timeout(240)
def test_killed_learner_resumes_from_its_checkpoint(
    router_endpoint: str, tabletop_recording: Path, spawn: Callable, tmp_path: Path
) -> None:
    from gngdt.io.checkpoints import load_checkpoint

    checkpoint = tmp_path / "learner.npz"
    connect = ["--zenoh-connect", router_endpoint]
    learner_args = ("learn", "--samples-per-frame", "5000", "--checkpoint", str(checkpoint),
                    "--checkpoint-every", "1", *connect)
    learner = spawn(*learner_args)
    watcher = Watcher(router_endpoint)
    try:
        capture = spawn("capture", str(tabletop_recording), "--rate", "0.5", "--loop", *connect)
        watcher.wait_for(lambda s: len(s) >= 4, 90)
        learner.send_signal(signal.SIGKILL)  # no chance to save: the periodic checkpoint counts
        learner.wait(10)
        _, metadata = load_checkpoint(checkpoint)
        # the map's first frame (in the world frame: the recording has poses) is learned
        # longer, every later one 5,000 steps
        saved_steps = metadata["counters"]["learning_steps"]
        assert saved_steps >= 5000

        with watcher._lock:
            watcher.statuses.clear()
        spawn(*learner_args)
        statuses = watcher.wait_for(lambda s: bool(s), 90)
        first = statuses[0]
        assert first.steps == saved_steps + 5000, (first.steps, saved_steps)
        assert first.nodes > 2
        assert first.frames_used == metadata["counters"]["frames_used"] + 1
        capture.send_signal(signal.SIGINT)
        assert wait_exit(capture, 30) == 0
    finally:
        watcher.close()


@pytest.mark.timeout(120)
def test_learner_counts_and_skips_malformed_messages(
    router_endpoint: str, spawn: Callable
) -> None:

    learner = spawn("learn", "--samples-per-frame", "500", "--zenoh-connect", router_endpoint)
    watcher = Watcher(router_endpoint)
    session = open_config(client_config([router_endpoint]))
    try:
        publisher = points_publisher(session)
        rng = np.random.default_rng(0)
        cloud = cloud_to_msg(rng.random((2000, 3), dtype=np.float32),
                             rng.integers(0, 256, (2000, 3), dtype=np.uint8), timestamp_ns=1)
        stamp = FrameStamp(0, time.time_ns()).to_attachment()
        publisher.put(b"\x00garbage\xff", attachment=stamp)          # not a PointCloud
        time.sleep(0.3)
        publisher.put(cloud.SerializeToString())                     # no frame attachment
        time.sleep(0.3)
        publisher.put(cloud.SerializeToString(), attachment=FrameStamp(1, time.time_ns())
                      .to_attachment())
        statuses = watcher.wait_for(lambda s: bool(s), 60)
        assert statuses[-1].malformed_messages == 2
        assert statuses[-1].frames_used == 1
        # a cloud without colours after coloured ones: the model refuses it, the learner goes on
        colourless = cloud_to_msg(rng.random((500, 3), dtype=np.float32), timestamp_ns=2)
        publisher.put(colourless.SerializeToString(),
                      attachment=FrameStamp(2, time.time_ns()).to_attachment())
        time.sleep(0.3)
        # NaN points are dropped, the rest is learned
        positions = rng.random((2000, 3), dtype=np.float32)
        positions[::2] = np.nan
        with_nan = cloud_to_msg(positions, rng.integers(0, 256, (2000, 3), dtype=np.uint8),
                                timestamp_ns=3)
        publisher.put(with_nan.SerializeToString(),
                      attachment=FrameStamp(3, time.time_ns()).to_attachment())
        statuses = watcher.wait_for(lambda s: s[-1].frame_sequence == 3, 60)
        assert statuses[-1].malformed_messages == 3
        assert statuses[-1].frames_used == 2
        assert np.isfinite(statuses[-1].quantization_error["pos"])
        assert learner.poll() is None, log_text(learner)
    finally:
        watcher.close()
        session.close()
    learner.send_signal(signal.SIGTERM)
    assert wait_exit(learner, 30) == 0


@pytest.mark.timeout(60)
def test_learner_refuses_a_corrupt_checkpoint(spawn: Callable, tmp_path: Path) -> None:
    checkpoint = tmp_path / "broken.npz"
    checkpoint.write_bytes(b"PK\x03\x04 this is not a checkpoint")
    learner = spawn("learn", "--checkpoint", str(checkpoint))
    assert wait_exit(learner, 30) == 2
    assert "broken.npz" in log_text(learner)


@pytest.mark.timeout(60)
def test_run_fails_clearly_on_a_missing_recording(tmp_path: Path) -> None:
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(tmp_path / "absent.mcap")],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=50,
    )
    assert completed.returncode != 0
    assert "absent.mcap" in completed.stderr


@pytest.mark.timeout(120)
def test_run_reports_a_failed_service_with_its_error(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    checkpoint = tmp_path / "broken.npz"
    checkpoint.write_bytes(b"not a checkpoint")  # only the learner, once started, reads it
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(tabletop_recording), "--save",
         str(tmp_path / "x.rrd"), "--checkpoint", str(checkpoint)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=100,
    )
    assert completed.returncode == 1, completed.stdout + completed.stderr
    assert "learn failed" in completed.stderr
    assert "broken.npz: not a zip (.npz) archive" in completed.stderr


@pytest.mark.parametrize(("content", "reason"), [
    ("max_nodez = 10\n", "unknown key 'max_nodez'"),
    ("max_nodes = 1\n", "max_nodes must be in [2, 10000000], got 1"),  # a value, not a key
])
def test_run_refuses_a_wrong_params_file_before_starting(
    tabletop_recording: Path, tmp_path: Path, content: str, reason: str
) -> None:
    params = tmp_path / "bad.toml"
    params.write_text(content)
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(tabletop_recording), "--save",
         str(tmp_path / "x.rrd"), "--params", str(params)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=100,
    )
    assert completed.returncode == 2, completed.stdout + completed.stderr
    assert reason in completed.stderr
    assert "learn failed" not in completed.stderr  # nothing was started


def _blueprint_only_rrd_bytes(path: Path) -> int:
    """Size of an .rrd holding only the logger's blueprint (what it writes before any frame)."""
    import rerun as rr

    from gngdt.io.outputs.rerun_blueprint import blueprint

    recording = rr.RecordingStream("gngdt")
    recording.save(str(path), default_blueprint=blueprint(["camera"]))
    recording.flush()
    recording.disconnect()
    return path.stat().st_size


@pytest.mark.timeout(180)
def test_interrupted_run_stops_cleanly_and_leaves_a_readable_rrd(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    rrd_path = tmp_path / "interrupted.rrd"
    flowing_bytes = _blueprint_only_rrd_bytes(tmp_path / "blueprint.rrd") + 100_000
    process = subprocess.Popen(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(tabletop_recording), "--save",
         str(rrd_path), "--rate", "0.05", "--samples-per-frame", "2000"],
        cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:
            if rrd_path.exists() and rrd_path.stat().st_size > flowing_bytes:
                break  # frames are flowing
            time.sleep(0.2)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 130, stdout + stderr
    assert "frames learned" in stdout
    entities, _ = rrd_entities_and_scalars(rrd_path)
    assert "/world/camera/image/rgb" in entities


@pytest.mark.timeout(120)
def test_logger_skips_malformed_messages_and_stops_after_eos(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    import zenoh

    from gngdt.io.frame import CameraIntrinsics
    from gngdt.schemas.images import intrinsics_to_calibration
    from gngdt.schemas.status import encode_stream_end

    rrd_path = tmp_path / "logger.rrd"
    logger = spawn("log", "--save", str(rrd_path), "--eos-drain", "1",
                   "--zenoh-connect", router_endpoint)
    session = open_config(client_config([router_endpoint]))
    try:
        liveliness = session.liveliness()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not list(
                liveliness.get("gngdt/logger/alive/**", timeout=1)):
            time.sleep(0.1)
        block = zenoh.CongestionControl.BLOCK
        stamp = FrameStamp(0, time.time_ns()).to_attachment()
        session.put("gngdt/camera/topology", b"\x01not a topology", attachment=stamp,
                    congestion_control=block)
        session.put("gngdt/camera/learner/status", b"\xff\xff", attachment=stamp,
                    congestion_control=block)
        calibration = intrinsics_to_calibration(
            CameraIntrinsics(640, 480, 525.0, 525.0, 319.5, 239.5), timestamp_ns=1)
        session.put("gngdt/camera/calibration", calibration.SerializeToString(),
                    attachment=stamp, congestion_control=block)
        end = encode_stream_end(timestamp_ns=2, frames_sent=1, last_frame_sequence=0)
        session.put("gngdt/camera/eos", end.SerializeToString(), attachment=stamp,
                    congestion_control=block)
        assert wait_exit(logger, 60) == 0, log_text(logger)
    finally:
        session.close()
    assert "2 malformed" in log_text(logger)
    entities, _ = rrd_entities_and_scalars(rrd_path)
    assert "/world/camera" in entities


@pytest.mark.timeout(120)
def test_capture_sends_the_good_frames_of_a_damaged_recording(
    router_endpoint: str, tabletop_recording: Path, spawn: Callable, tmp_path: Path
) -> None:
    from gngdt.schemas.status import decode_stream_end

    damaged = tmp_path / "damaged.mcap"
    data = tabletop_recording.read_bytes()
    damaged.write_bytes(data[: len(data) * 2 // 3])
    session = open_config(client_config([router_endpoint]))
    ends: list = []
    subscriber = session.declare_subscriber(
        "gngdt/camera/eos",
        lambda sample: ends.append(decode_stream_end(sample.payload.to_bytes())))
    try:
        capture = spawn("capture", str(damaged), "--fast", "--realtime", "--wait-subscribers", "0",
                        "--zenoh-connect", router_endpoint)
        assert wait_exit(capture, 60) == 0, log_text(capture)
        deadline = time.monotonic() + 10
        while not ends and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        subscriber.undeclare()
        session.close()
    assert "damaged.mcap" in log_text(capture)
    assert len(ends) == 1 and 0 < ends[0].frames_sent < 8
