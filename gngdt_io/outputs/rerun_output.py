"""The logger's rerun output: a ``.rrd`` file by default, or a viewer (``--serve``,
``--connect``, ``--stdout``: rerun's own options).

What goes into the .rrd is thinned by default (`DisplayRates`): a 30 fps camera would otherwise
write ~1 GB a minute. Metrics and objects are logged for every frame; images, topologies and
clouds for every Nth frame (by frame sequence), colour as JPEG, clouds capped in points.
``--keep-everything`` logs every frame in full.

Crash safety: the ``.rrd`` is flushed every ``RRD_FLUSH_SECONDS`` (10 s), so a logger killed
outright (``kill -9``) leaves every message flushed before on disk (without the footer, which
only makes rerun scan it whole); a kill in the middle of a flush leaves its last message
partial, and rerun's reader then refuses the file until that tail is cut. SIGINT/SIGTERM lose
nothing. An existing ``--save`` file is
never overwritten: a restarted logger writes ``<name>.1.rrd`` (then ``.2``, ...) beside it and
says so.
"""

from __future__ import annotations

import argparse
import logging
import os
import time
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gngdt.io.outputs.base import Output, StreamSample, split_bind
from gngdt.io.outputs.file_limits import FILE_LIMITS_TITLE, add_file_limit_arguments
from gngdt.io.outputs.rerun_blueprint import EntityPaths, blueprint
from gngdt.io.outputs.rerun_log import DisplayRates, RerunLog
from gngdt.io.outputs.rerun_sinks import (
    DEFAULT_BIND,
    DEFAULT_GRPC_PORT,
    DEFAULT_WEB_PORT,
)
from gngdt.schemas.wire import DEFAULT_CAMERA

if TYPE_CHECKING:
    from gngdt.io.outputs.rerun_sinks import RrdFile, ViewerServer

log = logging.getLogger(__name__)

RUNS_DIR = Path("runs")
#: how often a stream to a viewer (--stdout, --serve, --connect) is flushed
FLUSH_EVERY_SECONDS = 1.0
#: how often the .rrd is flushed to disk, and the longest its chunks span: what a killed logger
#: can lose at most; longer than a second because the .rrd writer's memory grows per chunk
#: (`file_batcher`)
RRD_FLUSH_SECONDS = 10.0
#: 25 times the learner's default node budget: a topology of 25,000 nodes (~8 MB on the wire)
#: costs the .rrd ~20 MB; a learner with a larger --max-nodes needs a larger logger limit
DEFAULT_MAX_TOPOLOGY_NODES = 25_000
#: images thinned for the .rrd, skipped before they are decoded (clouds and topologies are
#: thinned after: their poses and metrics are logged for every frame)
THINNED_IMAGES = {"color": "image_every", "depth": "depth_every"}


def add_viewer_arguments(parser: argparse.ArgumentParser) -> None:
    """rerun's own viewer options, as ``rr.script_add_args`` adds them (a test checks they match),
    but ``--headless``: the logger never opens a GUI (it saves, streams or serves), so "don't
    show GUI" would change nothing.

    Declared here because importing rerun costs ~0.6 s, too much for ``gngdt --help``.
    """
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
    group = parser.add_argument_group("serving (--serve, --foxglove)")
    group.add_argument("--bind", default=DEFAULT_BIND, metavar="HOST[:PORT]",
                       help=f"address the servers listen on (default {DEFAULT_BIND}, this "
                       "machine only; 0.0.0.0 opens them to the network, with no "
                       "authentication); PORT is the Foxglove server's (default 8765), rerun's "
                       "are --grpc-port and --web-port")
    group.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT, metavar="PORT",
                       help=f"port of the gRPC server logs go to (default {DEFAULT_GRPC_PORT})")
    group.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                       help=f"port of the web viewer (default {DEFAULT_WEB_PORT})")


#: what the `DisplayRates` options are for, to title them
RATES_TITLE = "what goes into the .rrd (metrics and objects: every frame)"


def add_rate_arguments(rates: Any) -> None:
    """Options of `DisplayRates` (``gngdt log``'s, and through its option group ``gngdt
    run``'s), into ``rates`` (a parser or an argument group)."""
    defaults = DisplayRates()
    rates.add_argument("--image-every", type=int, default=defaults.image_every, metavar="N",
                       help="log the colour image of every Nth frame (default %(default)s)")
    rates.add_argument("--depth-every", type=int, default=defaults.depth_every, metavar="N",
                       help="log the depth image of every Nth frame (default %(default)s)")
    rates.add_argument("--topology-every", type=int, default=defaults.topology_every,
                       metavar="N", help="log nodes, edges and clusters of every Nth frame "
                       "(default %(default)s)")
    rates.add_argument("--cloud-every", type=int, default=defaults.cloud_every, metavar="N",
                       help="log the point cloud of every Nth frame (default %(default)s)")
    rates.add_argument("--max-cloud-points", type=int, default=defaults.max_cloud_points,
                       metavar="N", help="decimate each logged cloud to at most N points "
                       "(default %(default)s; 0: whole clouds)")
    rates.add_argument("--jpeg-quality", type=int, default=defaults.jpeg_quality, metavar="Q",
                       help="log colour as JPEG of this quality (default %(default)s; 0: raw)")
    rates.add_argument("--keep-everything", action="store_true",
                       help="log every frame in full: raw images, whole clouds (~1 GB/min at "
                       "30 fps 640x480)")


def rates_from_args(args: argparse.Namespace) -> DisplayRates:
    if args.keep_everything:
        return DisplayRates.everything()
    return DisplayRates(args.image_every, args.depth_every, args.topology_every,
                        args.cloud_every, args.max_cloud_points or None, args.jpeg_quality)


def default_rrd_path(name: str) -> Path:
    """``runs/<name>-<local time>.rrd``."""
    return RUNS_DIR / f"{name}-{datetime.now().strftime('%Y%m%d-%H%M%S')}.rrd"


def reserve_path(path: Path) -> Path:
    """``path``, or the first free ``<stem>.<n><suffix>`` beside it, created empty at once
    (exclusively: two runs started in the same second never get the same name); the caller
    then writes it over."""
    path.parent.mkdir(parents=True, exist_ok=True)
    candidate, number = path, 0
    while True:
        try:
            os.close(os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            return candidate
        except FileExistsError:
            number += 1
            candidate = path.with_name(f"{path.stem}.{number}{path.suffix}")


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


def file_batcher() -> Any:
    """Rerun's chunk batching for a .rrd: one chunk per entity per ``RRD_FLUSH_SECONDS`` (or
    per 2 MiB of it, rerun's default, for images and topologies).

    rerun 0.41's .rrd writer keeps a row per chunk in memory for the file's footer (its index for
    random access) until the file is closed, and each row is as wide as the recording has
    distinct components: ~100 bytes per component, ~3 kB per chunk for the logger's ~30
    (measured, README "Performance"). One chunk per entity per second (~25 entities, most of
    them metrics) grew the logger by ~8 MB a minute; per 10 s, by ~1/10 of that. Streams to a
    viewer (``--stdout``, ``--serve``, ``--connect``) keep rerun's default (low latency)."""
    import rerun as rr

    return rr.ChunkBatcherConfig(flush_tick=timedelta(seconds=RRD_FLUSH_SECONDS))


def open_recording(args: argparse.Namespace, default_name: str = "log"
                   ) -> tuple[Any, str, Path | None, Any]:
    """The rerun stream, its sink chosen by rerun's own options, where it goes (a description
    and, for a file, its path) and the viewer server ``--serve`` started (or None)."""
    import rerun as rr

    from gngdt.io.outputs.rerun_sinks import ViewerServer

    to_file = not (args.stdout or args.serve or args.connect)
    rec = rr.RecordingStream("gngdt", batcher_config=file_batcher() if to_file else None)
    rr.set_log_time_enabled(False, recording=rec)  # reproducible files: capture time is logged
    initial = blueprint([DEFAULT_CAMERA])
    if args.stdout:
        rec.stdout(default_blueprint=initial)
        return rec, "stdout", None, None
    if args.serve:
        binary = getattr(getattr(args, "environment", None), "rerun_cli_path", None)
        server = ViewerServer(split_bind(args.bind, 0)[0], args.grpc_port, args.web_port,
                              binary=binary)
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
    path = requested if getattr(args, "overwrite", False) else unused_rrd_path(requested)
    if path != requested:
        log.warning("%s exists (an earlier run); writing %s instead", requested, path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path), default_blueprint=initial)
    return rec, str(path), path, None


class RerunOutput(Output):
    """Decodes each sample by its stream and logs it to rerun (`RerunLog`), thinned by
    `DisplayRates`; the .rrd kept within its bounds (`RrdFile`), or a viewer fed."""

    def __init__(self, rerun_log: RerunLog, destination: str = "memory",
                 file: RrdFile | None = None, server: ViewerServer | None = None,
                 max_topology_nodes: int = DEFAULT_MAX_TOPOLOGY_NODES,
                 to_stdout: bool = False) -> None:
        self.rerun_log = rerun_log
        self.destination = destination
        self.file = file
        self.server = server
        self.max_topology_nodes = max_topology_nodes
        self.to_stdout = to_stdout
        self._cameras: list[str] = []
        #: per camera whose poses come on their own stream (gngdt/<cam>/tf), not with the
        #: clouds: its last transform (frame sequence, camera-to-world (4, 4))
        self._transforms: dict[str, tuple[int, np.ndarray]] = {}
        #: per such camera, its last cloud without a pose (sequence, positions, colors), drawn
        #: in the world when that frame's transform arrives (a tracked camera's: after learning)
        self._waiting: dict[str, tuple[int, Any, Any]] = {}
        self._last_flush = time.monotonic()

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        add_viewer_arguments(parser)
        add_rate_arguments(parser.add_argument_group(RATES_TITLE))
        add_serve_arguments(parser)
        add_file_limit_arguments(parser.add_argument_group(FILE_LIMITS_TITLE))
        limits = parser.add_argument_group("limits of the rerun output")
        limits.add_argument("--max-topology-nodes", type=int, default=DEFAULT_MAX_TOPOLOGY_NODES,
                            metavar="N", help="largest topology logged, in nodes (default "
                            f"{DEFAULT_MAX_TOPOLOGY_NODES:,}; a learner sends its --max-nodes)")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RerunOutput:
        from gngdt.io.outputs.rerun_sinks import RrdFile

        for name in ("max_rrd_mb", "min_free_mb"):
            if getattr(args, name) < 0:
                raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got "
                                 f"{getattr(args, name)}")
        if args.max_topology_nodes < 1:
            raise ValueError(f"--max-topology-nodes must be >= 1, got {args.max_topology_nodes}")
        rates = rates_from_args(args)
        rec, destination, path, server = open_recording(args)
        rerun_log = RerunLog(rec, rates)
        file = None if path is None else RrdFile(
            rerun_log, path, args.max_rrd_mb * 10**6, args.min_free_mb * 10**6, RRD_FLUSH_SECONDS)
        return cls(rerun_log, destination, file, server, args.max_topology_nodes,
                   bool(args.stdout))

    def describe(self) -> str:
        return "" if self.to_stdout else f"logging to {self.destination}"

    def wants(self, camera: str, stream: str, sequence: int) -> bool:
        """Images and clouds of frames the .rrd thins away are not wanted (a cloud still is
        while its camera's pose comes with the clouds, not on a tf stream)."""
        rates = self.rerun_log.rates
        if stream == "points":
            if camera not in self._transforms:
                return True
            every = rates.cloud_every
        elif stream in THINNED_IMAGES:
            every = getattr(rates, THINNED_IMAGES[stream])
        else:
            return True
        return self.rerun_log.would_log(camera, stream, sequence, every)

    def write(self, sample: StreamSample) -> None:
        from gngdt.schemas.images import calibration_to_intrinsics, raw_to_image
        from gngdt.schemas.scene import decode_object_boxes
        from gngdt.schemas.topology import decode_topology

        rerun_log, paths, payload = self.rerun_log, EntityPaths(sample.camera), sample.payload
        stream, stamp = sample.stream, sample.stamp
        every = getattr(rerun_log.rates, THINNED_IMAGES.get(stream, ""), 1)
        if stream in THINNED_IMAGES and not rerun_log.due(paths, stream, stamp.sequence, every):
            return
        rerun_log.set_time(stamp)
        if stream == "calibration":
            rerun_log.calibration(paths, calibration_to_intrinsics(payload))
        elif stream == "color":
            rerun_log.color(paths, raw_to_image(payload))
        elif stream == "depth":
            rerun_log.depth(paths, raw_to_image(payload))
        elif stream == "points":
            self._points(sample.camera, paths, payload, stamp.sequence)
        elif stream == "tf":
            self._transform(sample.camera, paths, payload, stamp.sequence)
        elif stream == "topology":
            self._topology(sample.camera, paths, decode_topology(
                sample.topology, max_nodes=self.max_topology_nodes), stamp.sequence)
        elif stream == "objects":
            rerun_log.objects(paths, decode_object_boxes(payload))
        elif stream == "learner/status":
            rerun_log.status(paths, sample.status)

    def _points(self, camera: str, paths: EntityPaths, payload: bytes, sequence: int) -> None:
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        from gngdt.schemas.clouds import cloud_pose, msg_to_cloud
        from gngdt.schemas.messages import parse_message

        rerun_log = self.rerun_log
        message = parse_message(PointCloud, payload)
        pose = cloud_pose(message)
        moving = not np.array_equal(pose, np.eye(4))
        if rerun_log.due(paths, "points", sequence, rerun_log.rates.cloud_every):
            # views: the logger decimates, so only the logged points are copied
            positions, colors = msg_to_cloud(message, copy=False)
            transform = self._transforms.get(camera)
            if moving or transform is None:
                rerun_log.points(paths, positions, colors, pose if moving else None,
                                 log_pose=transform is None)
            elif transform[0] == sequence:  # its transform came first
                rerun_log.points(paths, positions, colors, transform[1], log_pose=False)
            else:  # placed when its transform comes
                self._waiting[camera] = (sequence, positions, colors)
        elif moving and camera not in self._transforms:
            rerun_log.camera_pose(paths, pose)  # every frame, whether its cloud is logged or not

    def _transform(self, camera: str, paths: EntityPaths, payload: bytes, sequence: int) -> None:
        """The camera's pose (fixed frame -> camera): its frustum and images follow it, and
        its cloud of the same frame, waiting without a pose, is drawn in the world."""
        from gngdt.schemas.clouds import transform_to_pose

        _, child, matrix = transform_to_pose(payload)
        if child != camera:  # a transform of another frame: not this camera's pose
            return
        self._transforms[camera] = (sequence, matrix)
        waiting = self._waiting.pop(camera, None)
        if waiting is not None and waiting[0] == sequence:
            self.rerun_log.points(paths, waiting[1], waiting[2], matrix)
        else:
            self.rerun_log.camera_pose(paths, matrix)

    def _topology(self, camera: str, paths: EntityPaths, snapshot: Any, sequence: int) -> None:
        rerun_log = self.rerun_log
        # the settled network is always drawn: the file opens on it
        draw = snapshot.settled or rerun_log.due(paths, "topology", sequence,
                                                 rerun_log.rates.topology_every)
        framed = camera in rerun_log.framings
        rerun_log.topology(paths, snapshot, draw)
        if not framed and camera in rerun_log.framings:
            self._send_blueprint()  # the views now start looking at this camera's scene

    def cameras_changed(self, cameras: list[str]) -> None:
        self._cameras = list(cameras)
        self._send_blueprint()

    def _send_blueprint(self) -> None:
        self.rerun_log.rec.send_blueprint(blueprint(self._cameras or [DEFAULT_CAMERA],
                                                    self.rerun_log.framings))

    def tick(self) -> None:
        if self.file is not None:
            self.file.tick()
        elif time.monotonic() - self._last_flush >= FLUSH_EVERY_SECONDS:
            self.rerun_log.rec.flush()
            self._last_flush = time.monotonic()

    def stopped_early(self) -> str:
        return self.file.stopped if self.file is not None else ""

    @property
    def stuck(self) -> bool:
        """A write failed: rerun cannot finish the file (see `exit_now_if_stuck`)."""
        return self.file is not None and self.file.failed

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
        else:
            self.rerun_log.rec.flush()
            self.rerun_log.rec.disconnect()  # writes the .rrd footer
        if self.server is not None:
            self.server.stop()
