"""Log every gngdt stream (``gngdt/**``) to rerun: images, cloud, topologies, clusters, metrics.

Entities (DESIGN.md "Rerun") for the default camera ``camera``: ``world/camera`` (Pinhole),
``world/camera/image/rgb``, ``world/camera/image/depth``, ``world/points`` (at most
``--max-cloud-points``), ``world/gng/nodes`` (learned colours), ``world/gng/edges/<prop>``,
``world/gng/clusters/<clustering>`` (nodes coloured by cluster) and ``metrics/<name>``. Any other
camera ``<cam>`` gets the same tree under ``world/<cam>/`` and ``metrics/<cam>/``. Timelines:
``frame`` (sequence) and ``capture_time``.

The logger stops on its own once every camera it knows of (from its first message, or from its
capture's liveliness token, whichever comes first) has ended its stream (eos) and the topology of
its last frame has arrived, or ``--eos-drain`` seconds after that eos (or after its capture left
without one).

Crash safety: the ``.rrd`` is flushed every ``FLUSH_EVERY_SECONDS``, so a logger killed outright
(``kill -9``) leaves a file rerun reads up to the last flush (without the footer, which only makes
rerun scan it whole). An existing ``--save`` file is never overwritten: a restarted logger writes
``<name>.1.rrd`` (then ``.2``, ...) beside it and says so.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from schemas.wire import DEFAULT_CAMERA, FrameStamp
from services import lifecycle
from services.zenoh_session import (
    MAX_MESSAGE_BYTES,
    ZenohSetupError,
    add_zenoh_arguments,
    open_session,
)

if TYPE_CHECKING:
    import rerun as rr
    import zenoh

    from schemas.packing import LearnerStatusInfo, TopologySnapshot
    from services.recording.frame import CameraIntrinsics

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt log                                   # saves runs/log-<time>.rrd
  gngdt log --save out.rrd                    # out.1.rrd if out.rrd exists (never overwritten)
  gngdt log --connect --url rerun+http://127.0.0.1:9876/proxy   # a running viewer
  gngdt log --stdout | rerun -
"""

TOPOLOGY_VIEWS = ("pos", "col", "nor", "col+nor")
#: streams where only the newest sample matters when the logger falls behind
LATEST_ONLY_STREAMS = ("color", "depth", "points")
RUNS_DIR = Path("runs")
LIVELINESS_KEY = "gngdt/logger/alive"
#: how often the .rrd is flushed to disk: what a killed logger can lose at most
FLUSH_EVERY_SECONDS = 1.0
DEFAULT_MAX_CAMERAS = 16
#: 25 times the learner's default node budget: a topology of 25,000 nodes (~8 MB on the wire)
#: costs the .rrd ~20 MB; a learner with a larger --max-nodes needs a larger logger limit
DEFAULT_MAX_TOPOLOGY_NODES = 25_000


def add_viewer_arguments(parser: argparse.ArgumentParser) -> None:
    """rerun's own viewer options, as ``rr.script_add_args`` adds them (a test checks they match).

    Declared here because importing rerun costs ~0.6 s, too much for ``gngdt --help``.
    """
    parser.add_argument("--headless", action="store_true", help="Don't show GUI")
    parser.add_argument("--connect", dest="connect", action="store_true",
                        help="Connect to an external viewer")
    parser.add_argument("--serve", dest="serve", action="store_true",
                        help="Host a GRPC & web server and open a web viewer connecting to it.")
    parser.add_argument("--url", type=str, default=None, help="Connect to this Rerun URL")
    parser.add_argument("--save", type=str, default=None,
                        help="Save data to a .rrd file at this path")
    parser.add_argument("--stdout", dest="stdout", action="store_true",
                        help="Log data to standard output, to be piped into a Rerun Viewer")


def add_serve_arguments(parser: argparse.ArgumentParser) -> None:
    """Where ``--serve`` listens (shared with `gngdt run`)."""
    from services.rerun_output import DEFAULT_BIND, DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT

    group = parser.add_argument_group("serving (--serve)")
    group.add_argument("--bind", default=DEFAULT_BIND, metavar="ADDRESS",
                       help=f"address the served viewer listens on (default {DEFAULT_BIND}, this "
                       "machine only; 0.0.0.0 opens it to the network, with no authentication)")
    group.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT, metavar="PORT",
                       help=f"port of the gRPC server logs go to (default {DEFAULT_GRPC_PORT})")
    group.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                       help=f"port of the web viewer (default {DEFAULT_WEB_PORT})")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from services.rerun_output import DEFAULT_MAX_RRD_MB, DEFAULT_MIN_FREE_MB

    add_viewer_arguments(parser)
    parser.add_argument("--max-cloud-points", type=int, default=50_000,
                        help="decimate the logged point cloud to at most this many points "
                        "(default 50000)")
    parser.add_argument("--eos-drain", type=float, default=10.0, metavar="SECONDS",
                        help="after an end-of-stream, wait at most this long for the last "
                        "topology (default 10)")
    parser.add_argument("--keep-running", action="store_true",
                        help="do not stop at end-of-stream (only on SIGINT/SIGTERM)")
    add_serve_arguments(parser)
    limits = parser.add_argument_group("limits (what arrives beyond them is refused, counted)")
    limits.add_argument("--max-rrd-mb", type=int, default=DEFAULT_MAX_RRD_MB, metavar="MB",
                        help="stop writing the .rrd (a complete file) once it is this large and "
                        f"go on running (default {DEFAULT_MAX_RRD_MB}; 0: no cap)")
    limits.add_argument("--min-free-mb", type=int, default=DEFAULT_MIN_FREE_MB, metavar="MB",
                        help="stop writing the .rrd when less than this is free on its disk "
                        f"(default {DEFAULT_MIN_FREE_MB}); a failed write stops it too")
    limits.add_argument("--max-cameras", type=int, default=DEFAULT_MAX_CAMERAS, metavar="N",
                        help=f"cameras logged at most (default {DEFAULT_MAX_CAMERAS})")
    limits.add_argument("--max-topology-nodes", type=int, default=DEFAULT_MAX_TOPOLOGY_NODES,
                        metavar="N", help="largest topology logged, in nodes (default "
                        f"{DEFAULT_MAX_TOPOLOGY_NODES:,}; a learner sends its --max-nodes)")
    limits.add_argument("--max-queue-mb", type=int, default=DEFAULT_QUEUE_MB, metavar="MB",
                        help="messages held while the logger is busy, in MB (default "
                        f"{DEFAULT_QUEUE_MB}); the oldest make room")
    add_zenoh_arguments(parser)


def default_rrd_path(name: str) -> Path:
    """``runs/<name>-<local time>.rrd``."""
    return RUNS_DIR / f"{name}-{datetime.now().strftime('%Y%m%d-%H%M%S')}.rrd"


def unused_rrd_path(path: Path) -> Path:
    """``path`` if no file is there, else the first free ``<stem>.<n><suffix>`` beside it."""
    if not path.exists():
        return path
    number = 1
    while True:
        candidate = path.with_name(f"{path.stem}.{number}{path.suffix}")
        if not candidate.exists():
            return candidate
        number += 1


@dataclass(frozen=True)
class EntityPaths:
    """Entity paths of one camera: DESIGN's paths for the default camera, else under ``<cam>``."""

    camera: str

    @property
    def world(self) -> str:
        return "world" if self.camera == DEFAULT_CAMERA else f"world/{self.camera}"

    @property
    def pinhole(self) -> str:
        return f"{self.world}/camera"

    @property
    def rgb(self) -> str:
        return f"{self.pinhole}/image/rgb"

    @property
    def depth(self) -> str:
        return f"{self.pinhole}/image/depth"

    @property
    def points(self) -> str:
        return f"{self.world}/points"

    @property
    def nodes(self) -> str:
        return f"{self.world}/gng/nodes"

    def edges(self, prop: str) -> str:
        return f"{self.world}/gng/edges/{prop}"

    def clusters(self, clustering: str) -> str:
        return f"{self.world}/gng/clusters/{clustering}"

    def metric(self, name: str) -> str:
        if self.camera == DEFAULT_CAMERA:
            return f"metrics/{name}"
        return f"metrics/{self.camera}/{name}"


def cluster_colors(labels: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 colour per cluster label (N,) int32; -1 (too small a cluster) is grey."""
    hue = (labels.astype(np.float64) * 0.618033988749895) % 1.0
    sector = hue * 6.0
    channel = np.clip(np.abs((sector[:, None] - np.array([3.0, 1.0, 5.0])) % 6.0 - 3.0) - 1.0, 0, 1)
    colors = (64 + 191 * channel).astype(np.uint8)  # saturated, never black
    colors[labels < 0] = 128
    return colors


def blueprint(cameras: list[str]) -> Any:
    """One 3D view per topology (pos, col, nor, col+nor) beside the images, metrics below."""
    import rerun.blueprint as rrb

    columns = []
    for camera in cameras:
        paths = EntityPaths(camera)
        suffix = "" if camera == DEFAULT_CAMERA else f" ({camera})"
        topology_views = [
            rrb.Spatial3DView(
                name=f"{clustering}{suffix}",
                origin=paths.world,
                contents=[paths.clusters(clustering)]
                + [paths.edges(prop) for prop in clustering.split("+")],
            )
            for clustering in TOPOLOGY_VIEWS
        ]
        learned = rrb.Spatial3DView(
            name=f"nodes and cloud{suffix}",
            origin=paths.world,
            contents=[paths.points, paths.nodes, paths.edges("pos")],
        )
        images = rrb.Vertical(
            rrb.Spatial2DView(name=f"rgb{suffix}", origin=paths.pinhole,
                              contents=[paths.rgb]),
            rrb.Spatial2DView(name=f"depth{suffix}", origin=paths.pinhole,
                              contents=[paths.depth]),
        )
        columns.append(rrb.Horizontal(images, rrb.Grid(*topology_views, learned),
                                      column_shares=[1, 3]))
    metrics = rrb.TimeSeriesView(name="metrics", origin="metrics")
    return rrb.Blueprint(rrb.Vertical(*columns, metrics, row_shares=[3] * len(columns) + [1]),
                         collapse_panels=True)


class RerunLog:
    """Writes decoded gngdt messages into one ``rr.RecordingStream``."""

    def __init__(self, recording: rr.RecordingStream, max_cloud_points: int = 50_000) -> None:
        import rerun as rr

        if max_cloud_points <= 0:
            raise ValueError(f"--max-cloud-points must be positive, got {max_cloud_points}")
        self.rec = recording
        self.max_cloud_points = max_cloud_points
        self.rec.log("world", rr.ViewCoordinates.RDF, static=True)
        self._world_up = False

    def set_time(self, stamp: FrameStamp) -> None:
        self.rec.set_time("frame", sequence=stamp.sequence)
        self.rec.set_time("capture_time", timestamp=np.datetime64(stamp.capture_time_ns, "ns"))

    def calibration(self, paths: EntityPaths, intrinsics: CameraIntrinsics) -> None:
        import rerun as rr

        self.rec.log(paths.pinhole, rr.Pinhole(
            focal_length=[intrinsics.fx, intrinsics.fy],
            principal_point=[intrinsics.cx, intrinsics.cy],
            resolution=[intrinsics.width, intrinsics.height],
            camera_xyz=rr.ViewCoordinates.RDF,
        ))

    def color(self, paths: EntityPaths, image: np.ndarray) -> None:
        import rerun as rr

        self.rec.log(paths.rgb, rr.Image(image))

    def depth(self, paths: EntityPaths, depth_mm: np.ndarray) -> None:
        import rerun as rr

        self.rec.log(paths.depth, rr.DepthImage(depth_mm, meter=1000.0))

    def points(self, paths: EntityPaths, positions: np.ndarray, colors: np.ndarray | None,
               pose: np.ndarray | None = None) -> None:
        """The cloud at ``world/points``; with a ``pose`` (camera-to-world, the cloud was taken
        by a moving camera) the points are put in the world and the camera follows the pose."""
        import rerun as rr

        stride = max(1, -(-len(positions) // self.max_cloud_points))
        shown = positions[::stride]
        if pose is not None:
            if not self._world_up:  # a fixed frame (world/map/odom): z up, as ROS and our scenes
                self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
                self._world_up = True
            self.rec.log(paths.pinhole, rr.Transform3D(translation=pose[:3, 3],
                                                       mat3x3=pose[:3, :3]))
            shown = shown @ pose[:3, :3].T.astype(np.float32) + pose[:3, 3].astype(np.float32)
        self.rec.log(paths.points, rr.Points3D(
            shown, colors=None if colors is None else colors[::stride], radii=0.002))

    def topology(self, paths: EntityPaths, snapshot: TopologySnapshot) -> None:
        import rerun as rr

        positions = snapshot.positions
        self.rec.log(paths.nodes, rr.Points3D(positions, colors=snapshot.colors, radii=0.006))
        for prop, pairs in snapshot.edges.items():
            segments = positions[pairs.astype(np.int64)] if len(pairs) else np.zeros((0, 2, 3))
            self.rec.log(paths.edges(prop), rr.LineStrips3D(segments, radii=0.0015))
        for clustering, labels in snapshot.clusterings.items():
            self.rec.log(paths.clusters(clustering),
                         rr.Points3D(positions, colors=cluster_colors(labels), radii=0.008))
            self.scalar(paths, f"clusters/{clustering}", snapshot.cluster_counts[clustering])
        for prop, value in snapshot.quantization_error.items():
            self.scalar(paths, f"quantization_error/{prop}", value)
        self.scalar(paths, "nodes", snapshot.node_count)

    def status(self, paths: EntityPaths, status: LearnerStatusInfo) -> None:
        self.scalar(paths, "steps_per_second", status.steps_per_second)
        self.scalar(paths, "latency_ms", status.latency_ms)
        self.scalar(paths, "frames_dropped", status.frames_dropped)
        self.scalar(paths, "ghost_share", status.ghost_share)
        self.scalar(paths, "nodes_forgotten", status.nodes_forgotten)

    def scalar(self, paths: EntityPaths, name: str, value: float) -> None:
        import rerun as rr

        self.rec.log(paths.metric(name), rr.Scalars(float(value)))


#: bytes a sample of each stream may take; larger ones are refused before they are copied
#: (images, clouds and topologies: zenoh's own message limit)
STREAM_BYTE_LIMITS = {
    "calibration": 64 * 1024,
    "learner/status": 64 * 1024,
    "eos": 64 * 1024,
    "color": MAX_MESSAGE_BYTES,
    "depth": MAX_MESSAGE_BYTES,
    "points": MAX_MESSAGE_BYTES,
    "topology": MAX_MESSAGE_BYTES,
}
#: streams not in STREAM_BYTE_LIMITS
OTHER_STREAM_BYTE_LIMIT = 4 * 1024 * 1024
#: bytes the inbox may hold while the logger is busy
DEFAULT_QUEUE_MB = 256


def stream_of(key: str) -> str:
    """``learner/status`` of ``gngdt/<cam>/learner/status``."""
    return key.split("/", 2)[2] if key.count("/") >= 2 else ""


class Inbox:
    """Samples handed over from zenoh's threads; the callbacks never block.

    Images and clouds keep only the newest sample per key (older ones are counted as dropped);
    the other streams (calibration, topology, status) queue in arrival order. What it holds is
    bounded in bytes (``max_bytes``): a sample over its stream's limit (``STREAM_BYTE_LIMITS``)
    is refused before it is copied, and when the inbox is full the oldest queued samples make
    room; each is counted. Ends of stream are kept apart and never evicted (64 at most).
    """

    def __init__(self, max_bytes: int = DEFAULT_QUEUE_MB * 1024 * 1024) -> None:
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[bytes, bytes | None]] = {}
        self._queued: deque[tuple[str, bytes, bytes | None]] = deque()
        self._ends: list[tuple[str, bytes, bytes | None]] = []
        self._bytes = 0
        self.max_bytes = max_bytes
        self.dropped = 0
        self.oversized = 0
        self.arrived = threading.Event()

    def put(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        stream = stream_of(key)
        size = len(sample.payload)
        if size > STREAM_BYTE_LIMITS.get(stream, OTHER_STREAM_BYTE_LIMIT) or size > self.max_bytes:
            with self._lock:
                self.oversized += 1
            return
        payload = sample.payload.to_bytes()
        attachment = sample.attachment
        attachment = attachment.to_bytes() if attachment is not None and len(attachment) <= 64 \
            else None
        with self._lock:
            if stream == "eos":
                if len(self._ends) < 64:
                    self._ends.append((key, payload, attachment))
                else:
                    self.dropped += 1
            elif stream in LATEST_ONLY_STREAMS:
                previous = self._latest.pop(key, None)
                if previous is not None:
                    self.dropped += 1
                    self._bytes -= len(previous[0])
                if self._make_room(size):
                    self._latest[key] = (payload, attachment)
                    self._bytes += size
            elif self._make_room(size):
                self._queued.append((key, payload, attachment))
                self._bytes += size
        self.arrived.set()

    def _make_room(self, size: int) -> bool:
        """Evict the oldest queued samples until ``size`` more bytes fit; False (the new sample
        is dropped) if they cannot."""
        while self._bytes + size > self.max_bytes and self._queued:
            self._bytes -= len(self._queued.popleft()[1])
            self.dropped += 1
        if self._bytes + size > self.max_bytes:
            self.dropped += 1
            return False
        return True

    def take(self) -> list[tuple[str, bytes, bytes | None]]:
        """Everything waiting: queued messages first (calibration before images), then latest,
        then the ends of stream."""
        with self._lock:
            taken = list(self._queued)
            taken += [(key, *value) for key, value in self._latest.items()]
            taken += self._ends
            self._queued.clear()
            self._latest.clear()
            self._ends = []
            self._bytes = 0
            self.arrived.clear()
        return taken


@dataclass
class CameraProgress:
    """What the logger knows about one camera's stream, to decide when it is over."""

    last_topology_sequence: int = -1
    eos_last_sequence: int | None = None
    eos_at: float = 0.0
    #: when the camera's capture left without an end of stream (its liveliness token went)
    capture_gone_at: float | None = None
    #: the learner said how learning on the stream's last frame stopped (its final network)
    settled: bool = False

    def finished(self, drain_seconds: float) -> bool:
        if self.eos_last_sequence is None:
            return (self.capture_gone_at is not None
                    and time.monotonic() - self.capture_gone_at > drain_seconds)
        return ((self.last_topology_sequence >= self.eos_last_sequence and self.settled)
                or time.monotonic() - self.eos_at > drain_seconds)


class CaptureWatch:
    """Captures coming and going (their liveliness tokens ``gngdt/<cam>/capture/alive``): a
    camera is expected from its capture's start, not only from its first message."""

    KEY = "gngdt/*/capture/alive"

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._events: list[tuple[str, bool]] = []

    def on_token(self, sample: zenoh.Sample) -> None:
        import zenoh

        camera = str(sample.key_expr).split("/")[1]
        with self._lock:
            self._events.append((camera, sample.kind == zenoh.SampleKind.PUT))

    def take(self) -> list[tuple[str, bool]]:
        """(camera, capture alive) events since the last call."""
        with self._lock:
            events, self._events = self._events, []
        return events


class Dispatcher:
    """Decodes one sample by stream name and logs it; malformed messages are counted, skipped.

    A camera becomes known with its first valid message (or its capture's token), up to
    ``max_cameras``; messages of further cameras are refused and counted, so that garbage on
    made-up camera names cannot grow the recording or its blueprint.
    """

    def __init__(self, rerun_log: RerunLog, on_new_camera: Any = None,
                 max_cameras: int = DEFAULT_MAX_CAMERAS,
                 max_topology_nodes: int = DEFAULT_MAX_TOPOLOGY_NODES) -> None:
        self.rerun_log = rerun_log
        self.cameras: dict[str, CameraProgress] = {}
        self.malformed = 0
        self.refused = 0
        self.max_cameras = max_cameras
        self.max_topology_nodes = max_topology_nodes
        self.last_status: dict[str, LearnerStatusInfo] = {}
        self._on_new_camera = on_new_camera

    def handle(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        from schemas import packing

        parts = key.split("/")
        if len(parts) < 3 or parts[0] != "gngdt":
            return
        camera, stream = parts[1], "/".join(parts[2:])
        paths = EntityPaths(camera)
        handlers = {
            "calibration": lambda: self.rerun_log.calibration(
                paths, packing.calibration_to_intrinsics(payload)),
            "color": lambda: self.rerun_log.color(paths, packing.raw_to_image(payload)),
            "depth": lambda: self.rerun_log.depth(paths, packing.raw_to_image(payload)),
            "points": lambda: self._points(paths, payload),
            "topology": lambda: self._topology(camera, paths, packing.decode_topology(
                payload, max_nodes=self.max_topology_nodes)),
            "learner/status": lambda: self._status(camera, paths, packing.decode_status(payload)),
            "eos": lambda: self._eos(camera, packing.decode_stream_end(payload)),
        }
        handler = handlers.get(stream)
        if handler is None:
            return
        new_camera = camera not in self.cameras
        if new_camera and not self._admit(camera):
            return
        try:
            stamp = FrameStamp.from_attachment(attachment)
            stamp.check_clock(time.time_ns())
            if new_camera:
                self.cameras[camera] = CameraProgress()
            self.rerun_log.set_time(stamp)
            handler()
        except (ValueError, OverflowError) as error:  # MessageError is a ValueError
            if new_camera:  # a camera is made by a valid message, not by garbage
                self.cameras.pop(camera, None)
            self.malformed += 1
            log.warning("%s: malformed message skipped: %s", key, error)
            return
        if new_camera and self._on_new_camera is not None:
            self._on_new_camera(list(self.cameras))

    def _admit(self, camera: str) -> bool:
        """Room for one more camera? Refusals are counted, the first one logged."""
        if len(self.cameras) < self.max_cameras:
            return True
        if self.refused == 0:
            log.warning("more than %d cameras (--max-cameras): messages of %r and further "
                        "cameras are refused", self.max_cameras, camera)
        self.refused += 1
        return False

    def _points(self, paths: EntityPaths, payload: bytes) -> None:
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        from schemas import packing

        message = packing.parse_message(PointCloud, payload)
        # views: the logger decimates, so only the logged points are copied
        positions, colors = packing.msg_to_cloud(message, copy=False)
        pose = packing.cloud_pose(message)
        self.rerun_log.points(paths, positions, colors,
                              None if np.array_equal(pose, np.eye(4)) else pose)

    def capture_seen(self, camera: str, alive: bool) -> None:
        """A capture of ``camera`` started (``alive``) or left."""
        self._expect(camera)
        if camera in self.cameras:
            self.cameras[camera].capture_gone_at = None if alive else time.monotonic()

    def _expect(self, camera: str) -> None:
        if camera not in self.cameras and self._admit(camera):
            self.cameras[camera] = CameraProgress()
            if self._on_new_camera is not None:
                self._on_new_camera(list(self.cameras))

    def _topology(self, camera: str, paths: EntityPaths, snapshot: TopologySnapshot) -> None:
        self.rerun_log.topology(paths, snapshot)
        progress = self.cameras[camera]
        progress.last_topology_sequence = max(progress.last_topology_sequence,
                                              snapshot.frame_sequence)

    def _status(self, camera: str, paths: EntityPaths, status: LearnerStatusInfo) -> None:
        self.rerun_log.status(paths, status)
        self.last_status[camera] = status
        if status.settled:
            self.cameras[camera].settled = True

    def _eos(self, camera: str, end: Any) -> None:
        progress = self.cameras[camera]
        progress.eos_last_sequence = end.last_frame_sequence
        progress.eos_at = time.monotonic()
        progress.settled = False  # the learner settles on this stream's last frame after it
        log.info("%s: end of stream after %d frames", camera, end.frames_sent)

    def all_finished(self, drain_seconds: float) -> bool:
        return bool(self.cameras) and all(
            progress.finished(drain_seconds) for progress in self.cameras.values())


def open_recording(args: argparse.Namespace, default_name: str = "log"
                   ) -> tuple[Any, str, Path | None, Any]:
    """The rerun stream, its sink chosen by rerun's own options, where it goes (a description
    and, for a file, its path) and the viewer server ``--serve`` started (or None)."""
    import rerun as rr

    from services.rerun_output import ViewerServer

    rec = rr.RecordingStream("gngdt")
    rr.set_log_time_enabled(False, recording=rec)  # reproducible files: capture time is logged
    initial = blueprint([DEFAULT_CAMERA])
    if args.stdout:
        rec.stdout(default_blueprint=initial)
        return rec, "stdout", None, None
    if args.serve:
        server = ViewerServer(args.bind, args.grpc_port, args.web_port)
        try:
            server.wait_ready()
        except OSError:
            server.stop()
            raise
        rec.connect_grpc(server.grpc_url, default_blueprint=initial)
        return rec, f"serving a web viewer at {server.web_url} (logs {server.grpc_url})", \
            None, server
    if args.connect:
        rec.connect_grpc(args.url, default_blueprint=initial)
        return rec, f"connected to {args.url or 'the default viewer'}", None, None
    requested = Path(args.save) if args.save else default_rrd_path(default_name)
    path = unused_rrd_path(requested)
    if path != requested:
        log.warning("%s exists (an earlier run); writing %s instead", requested, path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path), default_blueprint=initial)
    return rec, str(path), path, None


def main(args: argparse.Namespace) -> int:
    from services.rerun_output import RrdFile, exit_now_if_stuck

    for name in ("max_rrd_mb", "min_free_mb", "max_queue_mb"):
        if getattr(args, name) < 0:
            log.error("--%s must be >= 0, got %s", name.replace("_", "-"), getattr(args, name))
            return 2
    for name in ("max_cameras", "max_topology_nodes"):
        if getattr(args, name) < 1:
            log.error("--%s must be >= 1, got %s", name.replace("_", "-"), getattr(args, name))
            return 2
    try:
        rec, destination, path, server = open_recording(args)
        rerun_log = RerunLog(rec, args.max_cloud_points)
    except (ValueError, OSError) as error:
        log.error("%s", error)
        return 2
    if not args.stdout:
        print(f"logging to {destination}", flush=True)
    output = None if path is None else RrdFile(
        rerun_log, path, args.max_rrd_mb * 10**6, args.min_free_mb * 10**6, FLUSH_EVERY_SECONDS)

    inbox = Inbox(args.max_queue_mb * 1024 * 1024)
    dispatcher = Dispatcher(
        rerun_log, on_new_camera=lambda cams: rerun_log.rec.send_blueprint(blueprint(cams)),
        max_cameras=args.max_cameras, max_topology_nodes=args.max_topology_nodes)
    try:
        session = open_session(args)
    except ZenohSetupError as error:
        log.error("%s", error)
        rec.disconnect()
        if server is not None:
            server.stop()
        return 1
    subscriber = session.declare_subscriber("gngdt/**", inbox.put)
    captures = CaptureWatch()
    capture_tokens = session.liveliness().declare_subscriber(
        CaptureWatch.KEY, captures.on_token, history=True)
    token = session.liveliness().declare_token(f"{LIVELINESS_KEY}/{session.zid()}")
    last_flush = time.monotonic()
    try:
        with lifecycle.graceful() as stop:
            while not stop.is_set():
                inbox.arrived.wait(0.05)
                for key, payload, attachment in inbox.take():
                    dispatcher.handle(key, payload, attachment)
                    if output is not None:
                        output.tick()
                for camera, alive in captures.take():
                    dispatcher.capture_seen(camera, alive)
                if output is not None:
                    output.tick()
                elif time.monotonic() - last_flush >= FLUSH_EVERY_SECONDS:
                    rerun_log.rec.flush()
                    last_flush = time.monotonic()
                if not args.keep_running and dispatcher.all_finished(args.eos_drain):
                    break
    finally:
        token.undeclare()
        capture_tokens.undeclare()
        subscriber.undeclare()
        session.close()
        for key, payload, attachment in inbox.take():
            dispatcher.handle(key, payload, attachment)
        if output is not None:
            output.close()
        else:
            rec.flush()
            rec.disconnect()  # writes the .rrd footer
        if server is not None:
            server.stop()
    log.info("logger done: %d malformed, %d dropped, %d oversized, %d refused (cameras beyond "
             "--max-cameras)%s", dispatcher.malformed, inbox.dropped, inbox.oversized,
             dispatcher.refused,
             f"; the .rrd stopped early: {output.stopped}" if output and output.stopped else "")
    return exit_now_if_stuck(output, 0)
