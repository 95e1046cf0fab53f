"""Log every gngdt stream (``gngdt/**``) to rerun: images, cloud, topologies, clusters, objects,
metrics; optionally record every stream as it is into an MCAP file (``--mcap``).

Entities (DESIGN.md "Rerun") for the default camera ``camera``: ``world/camera`` (Pinhole),
``world/camera/image/rgb`` (JPEG), ``world/camera/image/depth``, ``world/points``,
``world/gng/nodes`` (positions once, in their learned colours, with each clustering's node
colours beside them as ``gngdt.clusters.<clustering>:colors``: one colour per persistent cluster
id, grey for nodes in no cluster), ``world/gng/edges/<clustering>`` (the clustering's edges,
coloured by cluster, chained into polylines), ``world/objects`` (Boxes3D,
one per object, labelled with its persistent id) and ``metrics/<name>``. Any other camera
``<cam>`` gets the same tree under ``world/<cam>/`` and ``metrics/<cam>/``. Timelines: ``frame``
(sequence) and ``capture_time``. The blueprint: the images, a 3D view per clustering plus one of
the cloud and the learned colours, all starting from the camera's viewpoint, and one plot per
metric.

What goes into the .rrd is thinned by default (`DisplayRates`): a 30 fps camera would otherwise
write ~1 GB a minute. Metrics and objects are logged for every frame; images, topologies and
clouds for every Nth frame (by frame sequence), colour as JPEG, clouds capped in points.
``--keep-everything`` logs every frame in full.

The logger stops on its own once every camera it knows of (from its first message, or from its
capture's liveliness token, whichever comes first) has ended its stream (eos) and the topology of
its last frame has arrived, or ``--eos-drain`` seconds after that eos (or after its capture left
without one).

Crash safety: the ``.rrd`` is flushed every ``RRD_FLUSH_SECONDS`` (10 s), so a logger killed
outright (``kill -9``) leaves a file rerun reads up to the last flush (without the footer, which
only makes rerun scan it whole); SIGINT/SIGTERM lose nothing. An existing ``--save`` file is
never overwritten: a restarted logger writes ``<name>.1.rrd`` (then ``.2``, ...) beside it and
says so.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from schemas.wire import DEFAULT_CAMERA, FrameStamp
from services.plumbing import lifecycle
from services.plumbing.session import (
    MAX_MESSAGE_BYTES,
    ZenohSetupError,
    add_zenoh_arguments,
    open_session,
)

if TYPE_CHECKING:
    import rerun as rr
    import zenoh

    from gngdt_io.frame import CameraIntrinsics
    from schemas.packing import LearnerStatusInfo, TopologySnapshot
    from schemas.scene import ObjectBoxes

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt log                                   # saves runs/log-<time>.rrd
  gngdt log --save out.rrd                    # out.1.rrd if out.rrd exists (never overwritten)
  gngdt log --connect --url rerun+http://127.0.0.1:9876/proxy   # a running viewer
  gngdt log --stdout | rerun -
"""

#: clusterings with a 3D view, in view order; "segments" is the segmentation, when published
CLUSTERING_VIEWS = ("segments", "pos", "col", "nor", "col+nor")
#: streams where only the newest sample matters when the logger falls behind
LATEST_ONLY_STREAMS = ("color", "depth", "points", "objects")
#: streams the .rrd does not show (the scene is the topology again, drawn for Foxglove)
NOT_LOGGED_STREAMS = ("scene",)
RUNS_DIR = Path("runs")
LIVELINESS_KEY = "gngdt/logger/alive"
#: how often a stream to a viewer (--stdout, --serve, --connect) is flushed
FLUSH_EVERY_SECONDS = 1.0
#: how often the .rrd is flushed to disk, and the longest its chunks span: what a killed logger
#: can lose at most; longer than a second because the .rrd writer's memory grows per chunk
#: (`file_batcher`)
RRD_FLUSH_SECONDS = 10.0
DEFAULT_MAX_CAMERAS = 16
#: 25 times the learner's default node budget: a topology of 25,000 nodes (~8 MB on the wire)
#: costs the .rrd ~20 MB; a learner with a larger --max-nodes needs a larger logger limit
DEFAULT_MAX_TOPOLOGY_NODES = 25_000


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
    from gngdt_io.outputs.rerun_sinks import DEFAULT_BIND, DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT

    group = parser.add_argument_group("serving (--serve)")
    group.add_argument("--bind", default=DEFAULT_BIND, metavar="ADDRESS",
                       help=f"address the served viewer listens on (default {DEFAULT_BIND}, this "
                       "machine only; 0.0.0.0 opens it to the network, with no authentication)")
    group.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT, metavar="PORT",
                       help=f"port of the gRPC server logs go to (default {DEFAULT_GRPC_PORT})")
    group.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                       help=f"port of the web viewer (default {DEFAULT_WEB_PORT})")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from gngdt_io.outputs.rerun_sinks import DEFAULT_MAX_RRD_MB, DEFAULT_MIN_FREE_MB

    add_viewer_arguments(parser)
    add_rate_arguments(parser)
    parser.add_argument("--mcap", type=Path, metavar="PATH",
                        help="also record every gngdt stream as it is (images, clouds, topology, "
                        "scene, objects, status) into this MCAP file, which Foxglove and rerun "
                        "open directly; <name>.1.mcap if it exists")
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


@dataclass(frozen=True)
class DisplayRates:
    """What goes into the .rrd: every ``*_every``-th frame (by sequence) of each stream.

    Metrics and objects are logged for every frame. ``jpeg_quality`` 0 logs raw colour images;
    ``max_cloud_points`` None logs whole clouds. Defaults keep a 30 fps 640x480 camera at
    ~120 MB of .rrd a minute (README "Performance").
    """

    image_every: int = 3
    depth_every: int = 15
    topology_every: int = 3
    cloud_every: int = 15
    max_cloud_points: int | None = 20_000
    jpeg_quality: int = 80

    def __post_init__(self) -> None:
        for name in ("image_every", "depth_every", "topology_every", "cloud_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got "
                                 f"{getattr(self, name)}")
        if self.max_cloud_points is not None and self.max_cloud_points <= 0:
            raise ValueError("--max-cloud-points must be positive (0: whole clouds)")
        if not 0 <= self.jpeg_quality <= 100:
            raise ValueError(f"--jpeg-quality must be 0..100, got {self.jpeg_quality}")

    @classmethod
    def everything(cls) -> DisplayRates:
        return cls(1, 1, 1, 1, None, 0)

    def describe(self) -> str:
        """One line for the run summary."""
        if self == DisplayRates.everything():
            return "every frame in full (--keep-everything)"

        def every(n: int) -> str:
            return "every frame" if n == 1 else f"1 frame in {n}"

        colour = f"JPEG q{self.jpeg_quality}" if self.jpeg_quality else "raw"
        cap = (f", at most {self.max_cloud_points:,} points" if self.max_cloud_points else "")
        return (f"colour {every(self.image_every)} ({colour}), depth {every(self.depth_every)}, "
                f"topology {every(self.topology_every)}, cloud {every(self.cloud_every)}{cap}, "
                "metrics and objects every frame (--keep-everything: all in full)")


def add_rate_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `DisplayRates` (shared by ``gngdt log`` and ``gngdt run``)."""
    defaults = DisplayRates()
    rates = parser.add_argument_group(
        "what goes into the .rrd (metrics and objects: every frame)")
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


def rate_arguments(args: argparse.Namespace) -> list[str]:
    """The `DisplayRates` options of ``args`` as command-line arguments (for ``gngdt run``)."""
    if args.keep_everything:
        return ["--keep-everything"]
    return ["--image-every", str(args.image_every), "--depth-every", str(args.depth_every),
            "--topology-every", str(args.topology_every), "--cloud-every", str(args.cloud_every),
            "--max-cloud-points", str(args.max_cloud_points),
            "--jpeg-quality", str(args.jpeg_quality)]


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

    @property
    def objects(self) -> str:
        return f"{self.world}/objects"

    def edges(self, clustering: str) -> str:
        return f"{self.world}/gng/edges/{clustering}"

    def metric(self, name: str) -> str:
        if self.camera == DEFAULT_CAMERA:
            return f"metrics/{name}"
        return f"metrics/{self.camera}/{name}"


#: the metric plots: title (with unit) and the metric names each shows
METRIC_PLOTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("nodes (count)", ("nodes",)),
    # segments are many (single nodes at creases count): their objects are plotted instead
    ("clusters per clustering (count)", tuple(f"clusters/{name}" for name in CLUSTERING_VIEWS
                                              if name != "segments")),
    ("objects (count)", ("objects",)),
    ("quantization error, position (m)", ("quantization_error/pos",)),
    ("quantization error, colour (RGB 0-255)", ("quantization_error/col",)),
    ("learning speed (steps/s)", ("steps_per_second",)),
    ("latency, capture to topology (ms)", ("latency_ms",)),
    ("frames dropped (count)", ("frames_dropped",)),
    ("ghost share of the seen nodes", ("ghost_share",)),
    ("nodes forgotten (count)", ("nodes_forgotten",)),
)
#: clusters (segments) of fewer nodes are drawn grey, as the learner's own minimum cluster size
DISPLAY_MIN_NODES = 5


@dataclass(frozen=True)
class Framing:
    """Where a camera's 3D views start. In the camera's own frame (RDF: at the origin, looking
    along +z), the topology views start from the camera itself, looking along its axis at the
    scene's median depth, so that they show the nodes as the colour image shows the scene
    (rerun's views are wider than a depth camera's field of view, so a little smaller); the
    overview starts behind and above the camera, so that the camera (frustum and image) is in
    sight with the scene beyond. With camera poses the same places are taken from the camera's
    pose when the views were framed, in the fixed frame.
    """

    depth: float = 1.5
    #: camera-to-frame pose (4, 4), row-major, as a tuple (identity: the camera's own frame)
    pose: tuple[float, ...] = tuple(np.eye(4).ravel())

    def _place(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        pose = np.asarray(self.pose).reshape(4, 4)
        return tuple(float(v) for v in pose[:3, :3] @ (x, y, z) + pose[:3, 3])

    @property
    def target(self) -> tuple[float, float, float]:
        return self._place(0.0, 0.0, self.depth)

    @property
    def camera_eye(self) -> tuple[float, float, float]:
        return self._place(0.0, 0.0, 0.0)

    @property
    def overview_eye(self) -> tuple[float, float, float]:
        return self._place(0.0, -0.2 * self.depth, -0.15 * self.depth)

    @property
    def up(self) -> tuple[float, float, float]:
        """The camera's up (-y in RDF) in the frame."""
        rotation = np.asarray(self.pose).reshape(4, 4)[:3, :3]
        return tuple(float(v) for v in rotation @ (0.0, -1.0, 0.0))

    @classmethod
    def of(cls, positions: np.ndarray, pose: np.ndarray | None = None) -> Framing:
        """Framing the nodes ``positions`` (N, 3), metres, seen by a camera at ``pose``
        (camera-to-frame (4, 4); None: the nodes are in the camera's frame)."""
        pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
        local = (np.asarray(positions, dtype=np.float64) - pose[:3, 3]) @ pose[:3, :3]
        depth = float(np.median(local[:, 2]))
        return cls(depth if depth > 0.05 else cls.depth, tuple(pose.ravel()))


def _spatial_view(name: str, origin: str, contents: list[str], framing: Framing,
                  eye: tuple[float, float, float], overrides: dict[str, Any] | None = None
                  ) -> Any:
    """A 3D view starting at ``eye``, looking at the scene, on a dark background."""
    import rerun.blueprint as rrb

    return rrb.Spatial3DView(
        name=name, origin=origin, contents=contents, overrides=overrides,
        eye_controls=rrb.EyeControls3D(position=eye, look_target=framing.target,
                                       eye_up=framing.up),
        background=rrb.Background(color=[22, 24, 28]))


def _cluster_colored_nodes(paths: EntityPaths, clustering: str) -> dict[str, Any]:
    """A view's override: its nodes take their colours from ``clustering``'s colours
    (`cluster_archetype`), logged beside the positions on the one nodes entity."""
    import rerun as rr
    from rerun.blueprint.encodings import ComponentSourceKind, VisualizerComponentMapping

    mapping = VisualizerComponentMapping(
        target="Points3D:colors", source_kind=ComponentSourceKind.SourceComponent,
        source_component=f"{cluster_archetype(clustering)}:colors")
    return {paths.nodes: [rr.Points3D.from_fields().visualizer(mappings=[mapping])]}


def _camera_row(camera: str, framing: Framing) -> Any:
    """The images beside a grid of six 3D views: objects and segments, one per clustering of
    properties, and the cloud with the nodes in their learned colours."""
    import rerun.blueprint as rrb

    paths = EntityPaths(camera)
    suffix = "" if camera == DEFAULT_CAMERA else f" ({camera})"
    eye = framing.camera_eye
    views = [_spatial_view(f"objects and segments{suffix}", paths.world, [
        paths.objects, paths.nodes, paths.edges("segments")], framing, eye,
        _cluster_colored_nodes(paths, "segments"))]
    views += [_spatial_view(f"{name} clusters{suffix}", paths.world,
                            [paths.nodes, paths.edges(name)], framing, eye,
                            _cluster_colored_nodes(paths, name))
              for name in CLUSTERING_VIEWS if name != "segments"]
    views.append(_spatial_view(f"cloud, learned colours and the camera{suffix}", paths.world,
                               [paths.points, paths.nodes, paths.pinhole, paths.rgb], framing,
                               framing.overview_eye))
    images = rrb.Vertical(
        rrb.Spatial2DView(name=f"rgb{suffix}", origin=paths.pinhole, contents=[paths.rgb]),
        rrb.Spatial2DView(name=f"depth{suffix}", origin=paths.pinhole, contents=[paths.depth]),
    )
    return rrb.Horizontal(images, rrb.Grid(*views, grid_columns=3), column_shares=[1, 3])


def blueprint(cameras: list[str], framings: dict[str, Framing] | None = None) -> Any:
    """Per camera a row (`_camera_row`), then one plot per metric (all cameras in each); the
    time cursor follows the newest data (a finished file opens on its last frame)."""
    import rerun.blueprint as rrb

    framings = framings or {}
    rows = [_camera_row(camera, framings.get(camera, Framing())) for camera in cameras]
    plots = [
        rrb.TimeSeriesView(name=title, origin="/",
                           contents=[EntityPaths(camera).metric(name)
                                     for camera in cameras for name in names])
        for title, names in METRIC_PLOTS
    ]
    return rrb.Blueprint(
        rrb.Vertical(*rows, rrb.Grid(*plots, grid_columns=5),
                     row_shares=[3] * len(rows) + [1.4]),
        rrb.TimePanel(timeline="frame", play_state="following", state="collapsed"),
        collapse_panels=True)


def cluster_archetype(clustering: str) -> str:
    """Name of the node colours of ``clustering`` on the nodes entity (its component is
    ``<name>:colors``); each clustering's view draws the nodes with them."""
    return f"gngdt.clusters.{clustering}"


def edge_lines(positions: np.ndarray, pairs: np.ndarray, ids: np.ndarray) -> Any:
    """LineStrips3D of the edges ``pairs`` (E, 2) between ``positions`` (N, 3) metres, coloured
    by the cluster both ends share (``ids`` (N,) persistent ids, -1 none: grey), the edges
    chained into polylines (`edge_strips`): about half the bytes of a two-point strip per edge."""
    import pyarrow as pa
    import rerun as rr

    from schemas.cluster_colors import edge_classes, edge_strips, id_colors

    nodes, starts, classes = edge_strips(pairs, edge_classes(pairs, ids))
    strip_type = rr.components.LineStrip3DBatch._ARROW_DATATYPE
    points = pa.FixedSizeListArray.from_arrays(
        pa.array(np.ascontiguousarray(positions[nodes], dtype=np.float32).ravel()),
        type=strip_type.value_type)
    strips = pa.ListArray.from_arrays(pa.array(starts, pa.int32()), points, type=strip_type)
    return rr.LineStrips3D(strips, colors=id_colors(classes), radii=rr.Radius.ui_points(1.5))


class RerunLog:
    """Writes decoded gngdt messages into one ``rr.RecordingStream``, thinned by `DisplayRates`."""

    def __init__(self, recording: rr.RecordingStream, rates: DisplayRates | None = None) -> None:
        import rerun as rr

        self.rec = recording
        self.rates = rates or DisplayRates()
        self._last_logged: dict[tuple[str, str], int] = {}
        #: per camera, where its views start, once its first topology showed the scene
        self.framings: dict[str, Framing] = {}
        #: per camera, its latest camera-to-world pose (moving cameras only)
        self.poses: dict[str, np.ndarray] = {}
        self.rec.log("world", rr.ViewCoordinates.RDF, static=True)
        self._world_up = False

    def due(self, paths: EntityPaths, stream: str, sequence: int, every: int) -> bool:
        """Whether frame ``sequence`` of ``stream`` is logged: ``every`` frames after the last
        one logged (so frames the learner skipped do not starve a stream), or a new stream."""
        if every == 1:
            return True
        key = (paths.camera, stream)
        last = self._last_logged.get(key)
        if last is not None and last <= sequence < last + every:
            return False
        self._last_logged[key] = sequence
        return True

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
            image_plane_distance=0.3,
        ))

    def color(self, paths: EntityPaths, image: np.ndarray) -> None:
        import rerun as rr

        quality = self.rates.jpeg_quality
        if not quality:
            self.rec.log(paths.rgb, rr.Image(image))
            return
        import cv2

        ok, encoded = cv2.imencode(".jpg", np.ascontiguousarray(image[..., ::-1]),
                                   [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise ValueError(f"colour image {image.shape} could not be JPEG-encoded")
        self.rec.log(paths.rgb, rr.EncodedImage(contents=encoded.tobytes(),
                                                media_type="image/jpeg"))

    def depth(self, paths: EntityPaths, depth_mm: np.ndarray) -> None:
        import rerun as rr

        self.rec.log(paths.depth, rr.DepthImage(depth_mm, meter=1000.0))

    def camera_pose(self, paths: EntityPaths, pose: np.ndarray) -> None:
        """A moving camera's pose (camera-to-world (4, 4)): the camera follows it."""
        import rerun as rr

        if not self._world_up:  # a fixed frame (world/map/odom): z up, as ROS and our scenes
            self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
            self._world_up = True
        self.poses[paths.camera] = pose
        self.rec.log(paths.pinhole, rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))

    def points(self, paths: EntityPaths, positions: np.ndarray, colors: np.ndarray | None,
               pose: np.ndarray | None = None) -> None:
        """The cloud at ``world/points``, at most ``max_cloud_points``; with a ``pose``
        (camera-to-world, the cloud was taken by a moving camera) the points are put in the
        world and the camera follows the pose (`camera_pose`)."""
        import rerun as rr

        cap = self.rates.max_cloud_points or len(positions)
        stride = max(1, -(-len(positions) // cap))
        shown = positions[::stride]
        if pose is not None:
            self.camera_pose(paths, pose)
            shown = shown @ pose[:3, :3].T.astype(np.float32) + pose[:3, 3].astype(np.float32)
        self.rec.log(paths.points, rr.Points3D(
            shown, colors=None if colors is None else colors[::stride],
            radii=rr.Radius.ui_points(1.5)))

    def topology(self, paths: EntityPaths, snapshot: TopologySnapshot, draw: bool) -> None:
        """Metrics of every topology; nodes, edges and clusters when ``draw``."""
        for clustering in snapshot.clusterings:
            self.scalar(paths, f"clusters/{clustering}", snapshot.cluster_counts[clustering])
        for prop, value in snapshot.quantization_error.items():
            self.scalar(paths, f"quantization_error/{prop}", value)
        self.scalar(paths, "nodes", snapshot.node_count)
        if draw:
            self._draw_topology(paths, snapshot)

    def _draw_topology(self, paths: EntityPaths, snapshot: TopologySnapshot) -> None:
        """The nodes once (positions, learned colours, and each clustering's colours beside
        them for its view to pick), and each clustering's edges as polylines by cluster."""
        import rerun as rr

        from schemas.cluster_colors import (
            UNCLUSTERED_RGB,
            clustering_edges,
            id_colors,
            node_cluster_ids,
        )

        positions = snapshot.positions
        if paths.camera not in self.framings and snapshot.node_count >= 50:
            framing = self.framings[paths.camera] = Framing.of(
                positions, self.poses.get(paths.camera))
            # a small frustum near the camera: the image on it stays a thumbnail in the
            # overview instead of covering the scene
            self.rec.log(paths.pinhole, rr.Pinhole.from_fields(
                image_plane_distance=0.1 * framing.depth))
        cluster_colors = []
        for clustering in CLUSTERING_VIEWS:
            labels = snapshot.clusterings.get(clustering)
            if labels is None:  # not published: grey nodes, no edges (nothing stale is shown)
                colors: np.ndarray = np.array([UNCLUSTERED_RGB], dtype=np.uint8)
                strips = rr.LineStrips3D(np.zeros((0, 2, 3), dtype=np.float32))
            else:
                ids = node_cluster_ids(labels, snapshot.cluster_ids.get(clustering),
                                       DISPLAY_MIN_NODES)
                colors = id_colors(ids)
                strips = edge_lines(positions, clustering_edges(clustering, snapshot.edges,
                                                                labels), ids)
            self.rec.log(paths.edges(clustering), strips)
            cluster_colors.append(rr.DynamicArchetype(
                cluster_archetype(clustering),
                components={"colors": rr.components.ColorBatch(colors)}))
        self.rec.log(paths.nodes, rr.Points3D(positions, colors=snapshot.colors,
                                              radii=rr.Radius.ui_points(4.0)), *cluster_colors)

    def objects(self, paths: EntityPaths, boxes: ObjectBoxes) -> None:
        """Boxes3D, one per object: colour and label by its persistent id (``object_id``)."""
        import rerun as rr

        ids = [rr.AnyValues(object_id=boxes.ids, node_count=boxes.node_counts)] if len(
            boxes.ids) else []  # no objects: empty boxes clear the previous ones
        self.rec.log(paths.objects, rr.Boxes3D(
            centers=boxes.centers, half_sizes=boxes.half_sizes,
            quaternions=boxes.quaternions_xyzw, colors=boxes.colors, labels=boxes.labels,
            radii=rr.Radius.ui_points(2.0), fill_mode="majorwireframe"), *ids)
        self.scalar(paths, "objects", len(boxes.ids))

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
        if stream in NOT_LOGGED_STREAMS:
            return
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
        from schemas.scene import decode_object_boxes

        parts = key.split("/")
        if len(parts) < 3 or parts[0] != "gngdt":
            return
        camera, stream = parts[1], "/".join(parts[2:])
        paths = EntityPaths(camera)
        rerun_log, rates = self.rerun_log, self.rerun_log.rates
        handlers = {
            "calibration": lambda: rerun_log.calibration(
                paths, packing.calibration_to_intrinsics(payload)),
            "color": lambda: rerun_log.color(paths, packing.raw_to_image(payload)),
            "depth": lambda: rerun_log.depth(paths, packing.raw_to_image(payload)),
            "points": lambda: self._points(paths, payload, stamp),
            "topology": lambda: self._topology(camera, paths, packing.decode_topology(
                payload, max_nodes=self.max_topology_nodes), stamp),
            "objects": lambda: rerun_log.objects(paths, decode_object_boxes(payload)),
            "learner/status": lambda: self._status(camera, paths, packing.decode_status(payload)),
            "eos": lambda: self._eos(camera, packing.decode_stream_end(payload)),
        }
        #: images thinned for the .rrd, skipped before they are decoded (clouds and topologies
        #: are thinned after: their poses and metrics are logged for every frame)
        thinned = {"color": rates.image_every, "depth": rates.depth_every}
        handler = handlers.get(stream)
        if handler is None:
            return
        new_camera = camera not in self.cameras
        if new_camera and not self._admit(camera):
            return
        try:
            stamp = FrameStamp.from_attachment(attachment)
            stamp.check_clock(time.time_ns())
            if stream in thinned and not rerun_log.due(paths, stream, stamp.sequence,
                                                       thinned[stream]):
                return
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
        if new_camera:
            self._layout_changed()

    def _layout_changed(self) -> None:
        """A camera appeared or its views were framed: a new blueprint."""
        if self._on_new_camera is not None:
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

    def _points(self, paths: EntityPaths, payload: bytes, stamp: FrameStamp) -> None:
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        from schemas import packing

        rerun_log = self.rerun_log
        message = packing.parse_message(PointCloud, payload)
        pose = packing.cloud_pose(message)
        moving = not np.array_equal(pose, np.eye(4))
        if rerun_log.due(paths, "points", stamp.sequence, rerun_log.rates.cloud_every):
            # views: the logger decimates, so only the logged points are copied
            positions, colors = packing.msg_to_cloud(message, copy=False)
            rerun_log.points(paths, positions, colors, pose if moving else None)
        elif moving:  # the camera's pose: every frame, whether its cloud is logged or not
            rerun_log.camera_pose(paths, pose)

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

    def _topology(self, camera: str, paths: EntityPaths, snapshot: TopologySnapshot,
                  stamp: FrameStamp) -> None:
        rerun_log = self.rerun_log
        progress = self.cameras[camera]
        # the stream's last frame is always drawn: after its end the learner settles on it and
        # publishes the final network again under the same frame sequence
        last_frame = (progress.eos_last_sequence is not None
                      and snapshot.frame_sequence >= progress.eos_last_sequence)
        draw = last_frame or rerun_log.due(paths, "topology", stamp.sequence,
                                           rerun_log.rates.topology_every)
        framed = camera in rerun_log.framings
        rerun_log.topology(paths, snapshot, draw)
        if not framed and camera in rerun_log.framings:
            self._layout_changed()  # the views now start looking at this camera's scene
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

    from gngdt_io.outputs.rerun_sinks import ViewerServer

    to_file = not (args.stdout or args.serve or args.connect)
    rec = rr.RecordingStream("gngdt", batcher_config=file_batcher() if to_file else None)
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
    from gngdt_io.outputs.mcap import McapRecorder
    from gngdt_io.outputs.rerun_sinks import RrdFile, exit_now_if_stuck

    for name in ("max_rrd_mb", "min_free_mb", "max_queue_mb"):
        if getattr(args, name) < 0:
            log.error("--%s must be >= 0, got %s", name.replace("_", "-"), getattr(args, name))
            return 2
    for name in ("max_cameras", "max_topology_nodes"):
        if getattr(args, name) < 1:
            log.error("--%s must be >= 1, got %s", name.replace("_", "-"), getattr(args, name))
            return 2
    try:
        rates = rates_from_args(args)
        rec, destination, path, server = open_recording(args)
        rerun_log = RerunLog(rec, rates)
        recorder = McapRecorder(unused_rrd_path(args.mcap)) if args.mcap else None
    except (ValueError, OSError) as error:
        log.error("%s", error)
        return 2
    if not args.stdout:
        print(f"logging to {destination}", flush=True)
        if recorder is not None:
            print(f"recording to {recorder.path}", flush=True)
    output = None if path is None else RrdFile(
        rerun_log, path, args.max_rrd_mb * 10**6, args.min_free_mb * 10**6, RRD_FLUSH_SECONDS)

    inbox = Inbox(args.max_queue_mb * 1024 * 1024)
    dispatcher = Dispatcher(
        rerun_log, on_new_camera=lambda cams: rerun_log.rec.send_blueprint(
            blueprint(cams, rerun_log.framings)),
        max_cameras=args.max_cameras, max_topology_nodes=args.max_topology_nodes)
    try:
        session = open_session(args)
    except ZenohSetupError as error:
        log.error("%s", error)
        rec.disconnect()
        if server is not None:
            server.stop()
        if recorder is not None:
            recorder.close()
        return 1
    subscriber = session.declare_subscriber("gngdt/**", inbox.put)
    recording = (session.declare_subscriber("gngdt/**", recorder.put)
                 if recorder is not None else None)
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
        if recording is not None:
            recording.undeclare()
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
        if recorder is not None:
            recorder.close()  # writes the MCAP index and footer
    log.info("logger done: %d malformed, %d dropped, %d oversized, %d refused (cameras beyond "
             "--max-cameras)%s", dispatcher.malformed, inbox.dropped, inbox.oversized,
             dispatcher.refused,
             f"; the .rrd stopped early: {output.stopped}" if output and output.stopped else "")
    return exit_now_if_stuck(output, 0)
