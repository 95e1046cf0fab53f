"""Hostile and odd inputs, replayed against running services: peak RSS per process, exit codes,
and whether every refusal was counted (issue 15's inputs, each small on the wire).

    python benchmarks/bench_hostile.py

Services: ``gngdt router``, ``learn`` and ``log`` (a .rrd capped at 200 MB) on loopback, fed by
this script's own zenoh client:
  - 2 MB samples on ``gngdt/<cam>/calibration`` (300 of them: 600 MB);
  - topologies at the logger's node limit (25,000 nodes, 8 edges a node in 4 edge sets, 5
    clusterings: what a learner with --max-nodes 25000 sends), 10 of them, one of 100,000 nodes
    (over the limit) and one of 20,000 clusterings;
  - a 200 MB sample on ``gngdt/camera/points``, and on a topic nobody reads;
  - garbage on 1,000 made-up camera names (valid attachments);
  - clouds stamped with sequence 2**64-1 and capture time INT64_MIN;
  - 3 s of 640x480 colour images at 30 Hz into the capped .rrd.
Then ``gngdt capture`` replays small hostile recordings (one 4000x4000 frame in 8 kB, 64
uncalibrated 2000x2000 frames, a zstd chunk inflating to 256 MB, an lz4 chunk hiding its 256 MB,
16 chunks of 40 MB overlapping in time, 1.5 million transforms): capture refuses each of the
first five (exit 2, naming file and frame: issue 15.11) and reads the first million transforms
of the last (exit 0, warned), within its limits. Target: no process above 1 GB, no service
exits non-zero, every refusal counted in the learner's status or the logger's log.

Then issue 24's attacks (``hostile_trust.py``; ``--only issue24`` runs them alone): misread and
absurd camera poses, crafted checkpoints, forgeries with another role's credentials inside
``gngdt run``, a scene flood, 100,000 camera names and a full disk against ``--mcap``, runs on a
busy port, one MCAP path or in the same second, odd files (a 10-million-line pose file, stamps
of Infinity, images claiming 10^10 pixels, a FIFO, NaN camera parameters, 8x8 frames) and depth
in the wrong unit. Per attack: exit codes, peak RSS, whether a traceback reached the user, and
what was recorded that a role may not publish. Target: no process above 1 GB, no traceback,
nothing recorded that a role may not publish.

Then issue 38's attacks on the new doors (``hostile_doors.py``, ``hostile_inputs.py``; ``--only
issue38``): calibrations with absurd finite values (a recording's, camera.json, --camera-json),
/tf stamped 2038, a 100 m jump 25 s later, noise frames with --track, a checkpoint's colours at
1e300, GNGDT_SHM_POOL_MB=inf, a run killed with SIGKILL, odd RealSense files, 40 Foxglove
clients that never read then 50 that do (the logger's peak and memory after), a ROS 2 image
flood (the bridge's). Same targets.
"""

from __future__ import annotations

import re
import signal
import struct
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]

from hostile_doors import door_attacks  # noqa: E402  (benchmarks/, beside this script)
from hostile_recordings import (  # noqa: E402  (benchmarks/, beside this script)
    lz4_chunk_hiding_its_size,
    overlapping_chunks,
    zstd_bomb,
)
from hostile_trust import print_trust, trust_attacks  # noqa: E402  (benchmarks/, beside this)
from procstat import gngdt, status_mb, wait_until  # noqa: E402  (benchmarks/, beside this script)

from gngdt.core.clustering import BY_COLOUR_AND_NORMAL, COL, CONVEXITY, NOR, POS, SEGMENTS  # noqa: E402
from gngdt.schemas.clouds import cloud_to_msg  # noqa: E402
from gngdt.schemas.images import image_to_raw  # noqa: E402
from gngdt.schemas.status import decode_status  # noqa: E402
from gngdt.schemas.topology import encode_topology  # noqa: E402
from gngdt.schemas.wire import FrameStamp  # noqa: E402
from gngdt.services.plumbing.session import client_config, free_tcp_port, open_config  # noqa: E402

MB = 1024 * 1024


class Peaks:
    """Polls VmHWM of the given processes (a peak resident set is kept by the kernel: polling
    only has to see the process alive)."""

    def __init__(self) -> None:
        self.peaks: dict[str, float] = {}
        self.watched: dict[str, int] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def watch(self, name: str, pid: int) -> None:
        self.watched[name] = pid

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            for name, pid in list(self.watched.items()):
                self.peaks[name] = max(self.peaks.get(name, 0.0), status_mb(pid, "VmHWM"))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def stamp(sequence: int = 1) -> bytes:
    return FrameStamp(sequence, time.time_ns()).to_attachment()


def big_topology(nodes: int, rng: np.random.Generator) -> bytes:
    pairs = {prop: rng.integers(0, nodes, (8 * nodes, 2)) for prop in (POS, COL, NOR, CONVEXITY)}
    labels = {name: rng.integers(-1, 50, nodes).astype(np.int32)
              for name in (POS, COL, NOR, BY_COLOUR_AND_NORMAL.name, SEGMENTS.name)}
    return encode_topology(
        positions=rng.random((nodes, 3), dtype=np.float32),
        colors=rng.integers(0, 256, (nodes, 3)), normals=rng.random((nodes, 3)),
        errors=rng.random(nodes), edges=pairs, clusterings=labels, steps=1, frame_sequence=1,
        timestamp_ns=time.time_ns(), frame_id="camera").SerializeToString()


def feed(session, rng: np.random.Generator) -> dict[str, int]:
    """Every hostile input through ``session``; what each service should have refused."""
    import zenoh

    block = zenoh.CongestionControl.BLOCK
    expected = {"logger oversized": 0, "logger malformed": 0, "learner malformed": 0}

    def put(key: str, payload: bytes, attachment: bytes | None = None) -> None:
        session.put(key, payload, attachment=attachment or stamp(), congestion_control=block)

    for _ in range(300):  # 15.1: 2 MB calibrations
        put("gngdt/camera/calibration", b"\x00" * (2 * MB))
    expected["logger oversized"] += 300
    print("  sent 300 calibrations of 2 MB", flush=True)
    topology = big_topology(25_000, rng)
    for sequence in range(10):  # 15.2: at the node limit
        put("gngdt/camera/topology", topology, stamp(sequence))
    print(f"  sent 10 topologies of 25,000 nodes ({len(topology) / 1e6:.0f} MB each)", flush=True)
    put("gngdt/camera/topology", big_topology(100_000, rng))
    expected["logger malformed"] += 1
    print("  sent a topology of 100,000 nodes", flush=True)
    many = encode_topology(
        positions=np.zeros((10, 3)), colors=None, normals=None, errors=None, edges={},
        clusterings={f"c{i}": np.zeros(10, np.int32) for i in range(20_000)}, steps=1,
        frame_sequence=1, timestamp_ns=1, frame_id="camera").SerializeToString()
    put("gngdt/camera/topology", many)
    expected["logger malformed"] += 1
    print(f"  sent a topology of 20,000 clusterings ({len(many) / 1e3:.0f} kB)", flush=True)
    for key in ("gngdt/camera/points", "gngdt/nobody/reads"):  # 15.4
        put(key, b"\x00" * (200 * MB))
    print("  sent two samples of 200 MB", flush=True)
    for index in range(1000):  # 13.8
        put(f"gngdt/made-up-{index}/calibration", b"\x0a\xff\xff\x03")
    expected["logger malformed"] += 1000
    print("  sent garbage on 1,000 camera names", flush=True)
    cloud = cloud_to_msg(rng.random((5000, 3), dtype=np.float32),
                         rng.integers(0, 256, (5000, 3), dtype=np.uint8),
                         timestamp_ns=time.time_ns()).SerializeToString()
    for attachment in (struct.pack("<Qq", 2**64 - 1, time.time_ns()),
                       struct.pack("<Qq", 1, -(2**63))):  # 13.1, 15.10
        put("gngdt/camera/points", cloud, attachment)
        time.sleep(1.0)  # the learner keeps only the latest cloud: one at a time
        expected["learner malformed"] += 1
    put("gngdt/camera/points", cloud, stamp(2))  # a good frame: the status that counts
    print("  sent clouds stamped 2**64-1 and INT64_MIN, then a good one", flush=True)
    image = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    for sequence in range(90):  # 15.5: into the capped .rrd
        put("gngdt/camera/color", image_to_raw(image, timestamp_ns=time.time_ns())
            .SerializeToString(), stamp(sequence))
        time.sleep(1 / 30)
    print("  sent 3 s of 640x480 images", flush=True)
    return expected


def hostile_recordings(folder: Path) -> dict[str, Path]:
    from mcap_protobuf.writer import Writer as ProtobufWriter

    from gngdt.io.frame import CameraIntrinsics
    from gngdt.schemas.images import intrinsics_to_calibration

    def images(path: Path, shape: tuple[int, int], frames: int, calibrated: bool) -> Path:
        with open(path, "wb") as file, ProtobufWriter(file) as writer:
            color = image_to_raw(np.zeros((*shape, 3), np.uint8), timestamp_ns=1)
            depth = image_to_raw(np.zeros(shape, np.uint16), timestamp_ns=1)
            for index in range(frames):
                ns = 1_000_000_000 + index * 33_000_000
                color.timestamp.nanos = depth.timestamp.nanos = ns % 10**9
                if calibrated:
                    intrinsics = CameraIntrinsics(shape[1], shape[0], 500.0, 500.0, 1.0, 1.0)
                    writer.write_message("/camera/calibration", intrinsics_to_calibration(
                        intrinsics, timestamp_ns=ns), log_time=ns, publish_time=ns)
                writer.write_message("/camera/color", color, log_time=ns, publish_time=ns)
                writer.write_message("/camera/depth", depth, log_time=ns, publish_time=ns)
        return path

    return {
        "one 4000x4000 frame": images(folder / "huge-frame.mcap", (4000, 4000), 1, True),
        "64 uncalibrated 2000x2000": images(folder / "uncalibrated.mcap", (2000, 2000), 64,
                                            False),
        "zstd chunk of 256 MB": zstd_bomb(folder / "zstd-bomb.mcap", 256 * MB),
        "lz4 chunk hiding 256 MB": lz4_chunk_hiding_its_size(folder / "lz4-bomb.mcap",
                                                             256 * MB),
        "16 chunks of 40 MB overlapping": overlapping_chunks(folder / "overlap.mcap", 16,
                                                              40 * MB),
        f"{TRANSFORM_FLOOD:,} transforms": transform_flood(folder / "tf-flood.mcap"),
    }


#: transform samples in the flooded recording (capture reads 1,000,000 by default)
TRANSFORM_FLOOD = 1_500_000


def transform_flood(path: Path) -> Path:
    """One good 64x48 frame, then TRANSFORM_FLOOD identical /tf samples (they compress to
    little)."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from mcap.writer import CompressionType, IndexType, Writer

    from gngdt.io.frame import CameraIntrinsics
    from gngdt.schemas.images import intrinsics_to_calibration

    ns = 1_000_000_000
    transform = FrameTransform(parent_frame_id="world", child_frame_id="camera")
    transform.timestamp.seconds, transform.rotation.w = 1, 1.0
    messages = {
        "/camera/calibration": ("foxglove.CameraCalibration", intrinsics_to_calibration(
            CameraIntrinsics(64, 48, 50.0, 50.0, 32.0, 24.0), timestamp_ns=ns)),
        "/camera/color": ("foxglove.RawImage", image_to_raw(
            np.zeros((48, 64, 3), np.uint8), timestamp_ns=ns, frame_id="camera")),
        "/camera/depth": ("foxglove.RawImage", image_to_raw(
            np.full((48, 64), 1000, np.uint16), timestamp_ns=ns, frame_id="camera")),
        "/tf": ("foxglove.FrameTransform", transform),
    }
    with open(path, "wb") as file:
        writer = Writer(file, compression=CompressionType.ZSTD, chunk_size=16 * MB,
                        index_types=IndexType.CHUNK)  # no per-message index: a small file
        writer.start()
        channels = {}
        for topic, (schema_name, message) in messages.items():
            schema = writer.register_schema(schema_name, "protobuf", b"")
            channels[topic] = (writer.register_channel(topic, "protobuf", schema),
                               message.SerializeToString())
        for topic in ("/camera/calibration", "/camera/color", "/camera/depth"):
            channel, data = channels[topic]
            writer.add_message(channel, log_time=ns, data=data, publish_time=ns)
        channel, data = channels["/tf"]
        for _ in range(TRANSFORM_FLOOD):
            writer.add_message(channel, log_time=ns, data=data, publish_time=ns)
        writer.finish()
    return path


@dataclass
class ServiceRun:
    """What feeding the services left behind."""

    #: learner status messages received, in order
    statuses: list
    #: refusals each service should have counted (``feed``'s keys)
    expected: dict[str, int]
    #: seconds from the first hostile input to the good frame's status (plus the logger's drain)
    fed_s: float
    #: per service, whether it was still running once fed
    alive: dict[str, bool]
    #: per service, its exit code after SIGINT
    codes: dict[str, int] = field(default_factory=dict)


#: one row per hostile recording: (label, file size in bytes, exit code, seconds, reason)
CaptureRow = tuple[str, int, int, float, str]


def start_services(folder: Path, endpoint: str, peaks: Peaks) -> dict[str, subprocess.Popen]:
    """Start the router, learner and logger (a .rrd capped at 200 MB), their peaks watched."""
    connect = ("--zenoh-connect", endpoint)
    processes = {
        "router": gngdt("router", "--listen", endpoint, log=folder / "router.log"),
        "learner": gngdt("learn", "--samples-per-frame", "2000", *connect,
                         log=folder / "learner.log"),
        "logger": gngdt("log", "--save", str(folder / "hostile.rrd"), "--keep-running",
                        "--max-rrd-mb", "200", *connect, log=folder / "logger.log"),
    }
    for name, process in processes.items():
        peaks.watch(name, process.pid)
    return processes


def feed_services(folder: Path, endpoint: str,
                  processes: dict[str, subprocess.Popen]) -> ServiceRun:
    """Once the services are up, feed them every hostile input and wait for the good frame's
    status; which services survived."""
    session = open_config(client_config([endpoint]), wait_s=30)
    statuses: list = []
    session.declare_subscriber("gngdt/camera/learner/status",
                               lambda sample: statuses.append(decode_status(
                                   sample.payload.to_bytes())))
    wait_until(lambda: "learning from" in (folder / "learner.log").read_text()
               and "logging to" in (folder / "logger.log").read_text(), 120, "the services")
    print("feeding the services:", flush=True)
    started = time.monotonic()
    expected = feed(session, np.random.default_rng(0))
    wait_until(lambda: any(status.frame_sequence == 2 for status in statuses), 60,
               "the good frame's status")
    time.sleep(2.0)  # the logger drains its inbox
    fed_s = time.monotonic() - started
    alive = {name: process.poll() is None for name, process in processes.items()}
    session.close()
    return ServiceRun(statuses, expected, fed_s, alive)


def stop_services(processes: dict[str, subprocess.Popen]) -> dict[str, int]:
    """SIGINT every service; their exit codes."""
    for process in processes.values():
        process.send_signal(signal.SIGINT)
    return {name: process.wait(60) for name, process in processes.items()}


def capture_reason(log: Path) -> str:
    """Why capture refused a recording (its ERROR line), else the limit it warned of, else ""."""
    lines = log.read_text().splitlines()
    reason = next((line.split("ERROR gngdt.services.capture: ", 1)[1] for line in lines
                   if "ERROR gngdt.services.capture: " in line), "")
    return reason or next((line.split(": ", 2)[-1] for line in lines
                           if "WARNING" in line and "(--max-" in line), "")


def replay_recordings(folder: Path, endpoint: str, peaks: Peaks) -> list[CaptureRow]:
    """``gngdt capture`` replays each hostile recording through a fresh router, its peak
    watched; a row per recording."""
    print("\ncapture replaying hostile recordings:", flush=True)
    connect = ("--zenoh-connect", endpoint)
    capture_rows = []
    for label, path in hostile_recordings(folder).items():
        log = folder / f"capture-{path.stem}.log"
        router = gngdt("router", "--listen", endpoint, log=folder / "router-capture.log")
        wait_until(lambda: "listening on" in (folder / "router-capture.log").read_text(), 30,
                   "a router")
        began = time.monotonic()
        capture = gngdt("capture", str(path), "--fast", "--realtime", "--wait-subscribers", "0",
                        *connect,
                        log=log)
        peaks.watch(f"capture: {label}", capture.pid)
        code = capture.wait(300)
        seconds = time.monotonic() - began
        router.send_signal(signal.SIGINT)
        router.wait(30)
        capture_rows.append((label, path.stat().st_size, code, seconds, capture_reason(log)))
    return capture_rows


def logger_counts(logged: str) -> tuple[int, int, int, int]:
    """(malformed, dropped, oversized, refused) from the logger's closing line."""
    done = re.search(r"logger done: (\d+) malformed, (\d+) dropped, (\d+) oversized, (\d+) refused",
                     logged)
    malformed, dropped, oversized, refused = (int(value) for value in done.groups())
    return malformed, dropped, oversized, refused


def print_tables(run: ServiceRun, capture_rows: list[CaptureRow],
                 peaks: dict[str, float]) -> None:
    """Print the services' table (peak RSS, alive, exit) and the captures' table."""
    print(f"\nservices, fed for {run.fed_s:.1f} s (shared 2-core machine):")
    print(f"{'process':<34}{'peak RSS':>10}  alive after  exit")
    for name in run.codes:
        print(f"{name:<34}{peaks.get(name, 0):>7.0f} MB  {run.alive[name]!s:>11}  "
              f"{run.codes[name]:>4}")
    print(f"\n{'capture of a hostile recording':<34}{'size':>9}{'peak RSS':>11}  exit  "
          "seconds  reason")
    for label, size, code, seconds, reason in capture_rows:
        print(f"{label:<34}{size / 1e3:>6.0f} kB{peaks.get('capture: ' + label, 0):>8.0f} MB"
              f"  {code:>4}  {seconds:>7.1f}  {reason[:110]}")


def print_report(folder: Path, run: ServiceRun, capture_rows: list[CaptureRow],
                 peaks: dict[str, float]) -> None:
    """Print the tables, the refusals counted against those expected, and the targets."""
    status = next(s for s in run.statuses if s.frame_sequence == 2)
    logged = (folder / "logger.log").read_text()
    malformed, dropped, oversized, refused = logger_counts(logged)
    expected = run.expected
    print_tables(run, capture_rows, peaks)
    rrd_mb = (folder / "hostile.rrd").stat().st_size / 1e6
    print("\nrefusals counted:")
    print(f"  learner status: {status.malformed_messages} malformed "
          f"(expected >= {expected['learner malformed']})")
    print(f"  logger log: {oversized} oversized (expected >= {expected['logger oversized']}), "
          f"{malformed} malformed (expected >= {expected['logger malformed']}), {dropped} "
          f"dropped, {refused} cameras refused")
    print(f"  .rrd: {rrd_mb:.0f} MB (capped at 200 MB)"
          + ("; the logger said it stopped writing" if "stopped writing" in logged else ""))
    worst = max(peaks.values())
    counted = (status.malformed_messages >= expected["learner malformed"]
               and oversized >= expected["logger oversized"]
               and malformed >= expected["logger malformed"])
    print(f"\ntarget: peak RSS <= 1024 MB: {worst:.0f} MB "
          f"({'met' if worst <= 1024 else 'MISSED'}); services exit 0: "
          f"{'met' if not any(run.codes.values()) else 'MISSED'}; refusals counted: "
          f"{'met' if counted else 'MISSED'}")
    print(f"logs: {folder}")


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("issue15", "issue24", "issue38"),
                        help="run only issue 15's services and recordings, issue 24's or issue "
                        "38's attacks (default: all)")
    args = parser.parse_args()
    if args.only in (None, "issue15"):
        folder = Path(tempfile.mkdtemp(prefix="bench-hostile-"))
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        peaks = Peaks()
        processes = start_services(folder, endpoint, peaks)
        run = feed_services(folder, endpoint, processes)
        run.codes = stop_services(processes)
        capture_rows = replay_recordings(folder, endpoint, peaks)
        time.sleep(0.2)
        peaks.stop()
        print_report(folder, run, capture_rows, peaks.peaks)
    if args.only in (None, "issue24"):
        print("\nissue 24's attacks:", flush=True)
        print_trust(trust_attacks())
    if args.only in (None, "issue38"):
        print("\nissue 38's attacks:", flush=True)
        print_trust(door_attacks(), "issue 38 attack")


if __name__ == "__main__":
    main()
