"""`gngdt ros2` at 30 fps with 640x480 frames: messages/s, added latency p50/p99, frames lost.

Run: ``python benchmarks/bench_ros2.py [--seconds 10] [--fps 30] [--max-points N]``. A loopback
router, the real bridge process (`gngdt ros2`), and this process as both ends:

- in: a ROS 2 camera (gngdt's node: colour rgb8, depth 16UC1, CameraInfo per frame) -> bridge
  -> ``gngdt/camera/points`` (+ colour, depth, calibration);
- out: ``gngdt/camera/points`` (a full 640x480 cloud, 307,200 points; ``--max-points N``: N of
  them, and the bridge caps its clouds in to N, as `gngdt run` caps capture's to 50,000) ->
  bridge -> ``/gngdt/camera/points`` sensor_msgs/PointCloud2.

Added latency = the bridge path minus the same payload's direct path through the router (this
process hears its own colour images / clouds too): per frame, p50 and p99. Frames lost: sent
and never bridged. Target: <= 5 ms p50 added, none lost at 30 fps on a quiet machine.
Baselines in the same run: the direct path (transport floor) and, for the translation itself,
a naive PointCloud2 encoder packing each point with ``struct.pack``, and the graph MarkerArray's
cost (why ``/graph`` is throttled).
"""

from __future__ import annotations

import argparse
import os
import struct
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from procstat import cpu_seconds, gngdt, wait_until

from gngdt.core.clustering import COL, NOR, POS
from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.ros2 import messages as m
from gngdt.io.ros2.markers import encode_graph_markers
from gngdt.io.ros2.node import Ros2Node
from gngdt.io.ros2.wire import decode_attachment
from gngdt.schemas.clouds import cloud_to_msg
from gngdt.schemas.wire import BRIDGE, DEFAULT_CAMERA, ENCODING_POINT_CLOUD, FrameStamp, alive_key
from gngdt.services.plumbing.session import (
    client_config,
    free_tcp_port,
    open_config,
    router_config,
)

WIDTH, HEIGHT = 640, 480
INTRINSICS = CameraIntrinsics(WIDTH, HEIGHT, 525.0, 525.0, 319.5, 239.5)
COLOR, DEPTH, INFO = ("/camera/camera/color/image_raw",
                      "/camera/camera/aligned_depth_to_color/image_raw",
                      "/camera/camera/color/camera_info")


def camera_frame(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A 640x480 colour (uint8 RGB) and depth (uint16 mm, 15 % holes) frame."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    color = np.stack([cols * 255 // WIDTH, rows * 255 // HEIGHT, np.full_like(rows, 90)], -1)
    depth = (800 + rows * 3 + rng.integers(-5, 6, rows.shape)).astype(np.uint16)
    depth[rng.random(depth.shape) < 0.15] = 0
    return color.astype(np.uint8), depth


class Arrivals:
    """Arrival times (ns) by frame stamp, recorded on zenoh's threads."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.at: dict[int, int] = {}

    def add(self, stamp_ns: int) -> None:
        now = time.time_ns()
        with self.lock:
            self.at.setdefault(stamp_ns, now)

    def latencies_ms(self, sent: dict[int, int]) -> np.ndarray:
        with self.lock:
            return np.array([(self.at[s] - sent[s]) / 1e6 for s in sent if s in self.at])

    def count(self, sent: dict[int, int]) -> int:
        with self.lock:
            return sum(1 for s in sent if s in self.at)


def pace(fps: float, seconds: float, send) -> dict[int, int]:
    """Call ``send(stamp_ns)`` at ``fps`` (0: as fast as possible) for ``seconds``; stamp -> sent
    time (ns)."""
    sent: dict[int, int] = {}
    started = time.monotonic()
    frame = 0
    while time.monotonic() - started < seconds:
        stamp = time.time_ns()
        send(stamp)
        sent[stamp] = stamp
        frame += 1
        if fps > 0:
            delay = started + frame / fps - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    return sent


def report(name: str, sent: dict[int, int], bridged: Arrivals, direct: Arrivals,
           seconds: float, messages_per_frame: int, cpu_s: float) -> None:
    through = bridged.latencies_ms(sent)
    floor = direct.latencies_ms(sent)
    lost = len(sent) - bridged.count(sent)
    if not len(through):
        print(f"{name}: nothing came through the bridge")
        return
    p50, p99 = np.percentile(through, [50, 99])
    f50, f99 = np.percentile(floor, [50, 99]) if len(floor) else (float("nan"),) * 2
    print(f"{name}: {len(sent)} frames sent in {seconds:g} s, {bridged.count(sent)} bridged "
          f"({bridged.count(sent) * messages_per_frame / seconds:.1f} messages/s out of the "
          f"bridge), {lost} lost")
    print(f"  latency through the bridge  p50 {p50:6.2f} ms  p99 {p99:6.2f} ms")
    print(f"  direct (no bridge, floor)   p50 {f50:6.2f} ms  p99 {f99:6.2f} ms")
    print(f"  added by the bridge         p50 {p50 - f50:6.2f} ms  p99 {p99 - f99:6.2f} ms")
    print(f"  bridge CPU {cpu_s * 1e3 / max(bridged.count(sent), 1):.1f} ms per frame bridged "
          f"({cpu_s / seconds:.0%} of one core)")


def bench_in(session, node: Ros2Node, args: argparse.Namespace, bridge_pid: int) -> None:
    """ROS 2 camera -> bridge -> gngdt."""
    color, depth = camera_frame(np.random.default_rng(0))
    hashes = {kind: m.type_hash(kind) for kind in (m.IMAGE, m.CAMERA_INFO)}
    publishers = {name: node.create_publisher(name, kind, hashes[kind])
                  for name, kind in ((INFO, m.CAMERA_INFO), (COLOR, m.IMAGE), (DEPTH, m.IMAGE))}
    bridged, direct = Arrivals(), Arrivals()

    def on_points(sample) -> None:
        bridged.add(FrameStamp.from_attachment(sample.attachment.to_bytes()).capture_time_ns)

    def on_color(sample) -> None:  # the colour image itself, straight through the router
        sample.payload.to_bytes()  # the copy the bridge makes too
        direct.add(decode_attachment(sample.attachment.to_bytes()).source_timestamp_ns)

    subscribers = [session.declare_subscriber("gngdt/camera/points", on_points),
                   session.declare_subscriber(publishers[COLOR].key, on_color)]
    wait_until(lambda: all(p.has_subscribers for p in publishers.values()), 30, "bridge's subs")

    def send(stamp: int) -> None:
        publishers[INFO].publish(m.encode_camera_info(m.CameraInfo(stamp, "optical",
                                                                   INTRINSICS)), stamp)
        publishers[COLOR].publish(m.encode_image(color, "rgb8", stamp_ns=stamp,
                                                 frame_id="optical"), stamp)
        publishers[DEPTH].publish(m.encode_image(depth, "16UC1", stamp_ns=stamp,
                                                 frame_id="optical"), stamp)

    pace(args.fps, 1.0, send)  # warm-up: calibration, caches
    time.sleep(0.5)
    cpu = cpu_seconds(bridge_pid)
    sent = pace(args.fps, args.seconds, send)
    time.sleep(1.0)
    report(f"in  (camera {args.fps:g} fps -> gngdt, clouds of "
           f"{args.max_points or 'all the'} points)", sent, bridged, direct, args.seconds, 4,
           cpu_seconds(bridge_pid) - cpu)
    for subscriber in subscribers:
        subscriber.undeclare()


def bench_out(session, node: Ros2Node, args: argparse.Namespace, bridge_pid: int) -> None:
    """gngdt clouds -> bridge -> ROS 2 PointCloud2."""
    color, depth = camera_frame(np.random.default_rng(1))
    z = depth.reshape(-1) / 1000.0
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    positions = np.stack([(cols - 319.5) / 525 * z, (rows - 239.5) / 525 * z, z],
                         1).astype(np.float32)
    colors = color.reshape(-1, 3)
    if args.max_points:
        keep = np.random.default_rng(2).choice(len(positions), args.max_points, replace=False)
        positions, colors = positions[np.sort(keep)], colors[np.sort(keep)]
    bridged, direct = Arrivals(), Arrivals()

    def on_ros_cloud(payload: bytes, _attachment) -> None:
        bridged.add(m.stamp_ns(m.deserialize(payload, m.POINT_CLOUD2).header.stamp))

    def on_gngdt_cloud(sample) -> None:  # the cloud itself, straight through the router
        sample.payload.to_bytes()  # the copy the bridge path makes too
        direct.add(FrameStamp.from_attachment(sample.attachment.to_bytes()).capture_time_ns)

    node.create_subscription("/gngdt/camera/points", m.POINT_CLOUD2,
                             m.type_hash(m.POINT_CLOUD2), on_ros_cloud)
    direct_sub = session.declare_subscriber("gngdt/camera/points", on_gngdt_cloud)
    publisher = session.declare_publisher("gngdt/camera/points", encoding=ENCODING_POINT_CLOUD)
    message = cloud_to_msg(positions, colors, timestamp_ns=0, frame_id="camera")
    sequence = iter(range(10**9))

    def send(stamp: int) -> None:
        message.timestamp.seconds, message.timestamp.nanos = divmod(stamp, 1_000_000_000)
        publisher.put(message.SerializeToString(),
                      attachment=FrameStamp(next(sequence), stamp).to_attachment())

    wait_until(lambda: publisher.matching_status.matching, 30, "bridge subscribed to clouds")
    deadline = time.monotonic() + 30
    while not bridged.at and time.monotonic() < deadline:  # until the bridge's /points matches
        send(time.time_ns())
        time.sleep(0.1)
    time.sleep(0.5)
    cpu = cpu_seconds(bridge_pid)
    sent = pace(args.fps, args.seconds, send)
    time.sleep(1.0)
    report(f"out (gngdt clouds {args.fps:g} fps -> ROS 2, {len(positions):,} points)", sent,
           bridged, direct, args.seconds, 1, cpu_seconds(bridge_pid) - cpu)
    direct_sub.undeclare()
    publisher.undeclare()


def naive_pointcloud2_data(positions: np.ndarray, colors: np.ndarray) -> bytes:
    """Baseline: PointCloud2 data (x, y, z, rgb) packed one point at a time."""
    point = struct.Struct("<fffI")
    return b"".join(point.pack(x, y, z, (r << 16) | (g << 8) | b)
                    for (x, y, z), (r, g, b) in zip(positions.tolist(), colors.tolist(),
                                                    strict=True))


def bench_translation() -> None:
    """The translations alone, against a naive encoder, in this process."""
    rng = np.random.default_rng(2)
    positions = rng.normal(size=(WIDTH * HEIGHT, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (WIDTH * HEIGHT, 3), dtype=np.uint8)

    def best(function, repeats: int = 5) -> float:
        times = []
        for _ in range(repeats):
            started = time.perf_counter()
            function()
            times.append(time.perf_counter() - started)
        return min(times) * 1e3

    ours = best(lambda: m.encode_pointcloud2(positions, colors=colors, stamp_ns=1,
                                             frame_id="camera"))
    naive = best(lambda: naive_pointcloud2_data(positions, colors), repeats=1)
    print(f"PointCloud2 640x480 (307,200 points): {ours:.1f} ms; per-point struct.pack "
          f"(data only): {naive:.0f} ms ({naive / ours:.0f}x slower)")
    nodes = rng.random((1000, 3)).astype(np.float32)
    edges = rng.integers(0, 1000, (3000, 2))
    grey = np.full((3000, 3), 150, np.uint8)
    graph = best(lambda: encode_graph_markers(nodes, {POS: (edges, grey), COL: (edges, grey),
                                                      NOR: (edges, grey)},
                                              stamp_ns=1, frame_id="world"), repeats=3)
    print(f"graph MarkerArray, 3 topologies x 3,000 edges: {graph:.0f} ms (hence --graph-rate 2)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="per direction (default 10)")
    parser.add_argument("--fps", type=float, default=30.0, help="offered rate; 0: flat out")
    parser.add_argument("--max-points", type=int, default=0,
                        help="points per cloud both ways (default 0: all, 307,200 out)")
    args = parser.parse_args()
    bench_translation()
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_config(router_config([endpoint]), what="router")
    session = open_config(client_config([endpoint]))
    log = Path(tempfile.mkdtemp(prefix="bench-ros2-")) / "ros2.log"
    bridge = gngdt("ros2", "--zenoh-connect", endpoint, "--log-level", "WARNING",
                   "--max-points", str(args.max_points), log=log)
    try:
        wait_until(lambda: any(True for _ in session.liveliness().get(
            alive_key(DEFAULT_CAMERA, BRIDGE), timeout=1.0)), 60, "the bridge")
        node = Ros2Node(session, "bench")
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        bench_in(session, node, args, bridge.pid)
        bench_out(session, node, args, bridge.pid)
        print(f"load average {os.getloadavg()[0]:.1f}; the bridge's log: {log}")
        node.close()
    finally:
        bridge.terminate()
        bridge.wait(30)
        session.close()
        router.close()


if __name__ == "__main__":
    main()
