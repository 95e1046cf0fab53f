"""Decoded gngdt messages logged into a rerun recording stream, thinned by `DisplayRates`.

The world's up axis follows the data (`gngdt.io.outputs.up_axis`): with camera poses, the cameras'
mean up; for a static camera (the world is its frame), the largest plane that could be the
floor or a table, else the camera's own up (-y). It is logged as the ``world`` entity's
``ViewCoordinates`` (the frame axis nearest that up) and stated beside it (``up_axis``,
``up_from``, ``up_vector``), and re-logged when more data moves it to another axis.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gngdt.core.clustering import NOR
from gngdt.io.outputs.rerun_blueprint import (
    CLUSTERING_VIEWS,
    EntityPaths,
    Framing,
    cluster_archetype,
)
from gngdt.io.outputs.up_axis import CAMERA_UP, PoseUp, axis_name, nearest_axis, up_from_planes
from gngdt.schemas.wire import FrameStamp

if TYPE_CHECKING:
    import rerun as rr

    from gngdt.core.sensor.geometry import CameraIntrinsics
    from gngdt.schemas.scene import ObjectBoxes
    from gngdt.schemas.status import LearnerStatusInfo
    from gngdt.schemas.topology import TopologySnapshot

log = logging.getLogger(__name__)

#: clusters (segments) of fewer nodes are drawn grey, as the learner's own minimum cluster size
DISPLAY_MIN_NODES = 5


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
                "metrics and objects each time the learner publishes them (--keep-everything: "
                "all in full)")


def edge_lines(positions: np.ndarray, pairs: np.ndarray, ids: np.ndarray) -> Any:
    """LineStrips3D of the edges ``pairs`` (E, 2) between ``positions`` (N, 3) metres, coloured
    by the cluster both ends share (``ids`` (N,) persistent ids, -1 none: grey), the edges
    chained into polylines (`edge_strips`): about half the bytes of a two-point strip per edge."""
    import pyarrow as pa
    import rerun as rr

    from gngdt.schemas.cluster_colors import edge_classes, edge_strips, id_colors

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

        self.rec = recording
        self.rates = rates or DisplayRates()
        self._last_logged: dict[tuple[str, str], int] = {}
        #: per camera, where its views start, once its first topology showed the scene
        self.framings: dict[str, Framing] = {}
        #: per camera, its latest camera-to-world pose (moving cameras only)
        self.poses: dict[str, np.ndarray] = {}
        self._pose_up = PoseUp()
        #: the world's up: the frame axis (axis, sign) nearest ``up_vector``, and what said so
        self.up_axis: tuple[int, int] | None = None
        self.up_vector = np.array(CAMERA_UP)
        self.up_from = ""
        self.set_up(self.up_vector, "the camera's own up (no camera pose, no floor seen yet)")

    def set_up(self, vector: np.ndarray, source: str) -> bool:
        """Make ``vector`` the world's up (found from ``source``); True when the axis or its
        source changed (then ``world``'s ViewCoordinates and the statement beside them are
        logged again)."""
        import rerun as rr

        self.up_vector = np.asarray(vector, dtype=np.float64)
        axis = nearest_axis(vector)
        if axis == self.up_axis and source == self.up_from:
            return False
        self.up_axis, self.up_from = axis, source
        name = axis_name(*axis)
        coordinates = getattr(rr.ViewCoordinates,
                              f"RIGHT_HAND_{'XYZ'[axis[0]]}_{'UP' if axis[1] > 0 else 'DOWN'}")
        self.rec.log("world", coordinates, rr.AnyValues(
            up_axis=name, up_from=source, up_vector=[round(float(v), 4) for v in vector]),
            static=True)
        log.info("the world's up axis: %s (from %s)", name, source)
        return True

    def due(self, paths: EntityPaths, stream: str, sequence: int, every: int) -> bool:
        """Whether frame ``sequence`` of ``stream`` is logged: ``every`` frames after the last
        one logged (so frames the learner skipped do not starve a stream), or a new stream."""
        if not self.would_log(paths.camera, stream, sequence, every):
            return False
        if every > 1:
            self._last_logged[(paths.camera, stream)] = sequence
        return True

    def would_log(self, camera: str, stream: str, sequence: int, every: int) -> bool:
        """Whether `due` would log frame ``sequence`` of ``camera``'s ``stream``, without
        counting it as logged (asked from zenoh's thread too: a read of one entry)."""
        last = self._last_logged.get((camera, stream))
        return every == 1 or last is None or not last <= sequence < last + every

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
        """A moving camera's pose (camera-to-world (4, 4)): the camera (its frustum and images)
        follows it, and the world's up follows the poses."""
        import rerun as rr

        self.poses[paths.camera] = pose
        self._pose_up.add(pose[:3, :3])
        up = self._pose_up.up
        if up is not None:
            self.set_up(up, "the camera poses")
        self.rec.log(paths.pinhole, rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))

    def static_up(self, paths: EntityPaths, snapshot: TopologySnapshot) -> None:
        """A static camera's up from the largest horizontal plane of its topology (in its
        frame), unless camera poses already say where up is."""
        labels = snapshot.clusterings.get(NOR)
        if (self._pose_up.count or snapshot.frame_id != paths.camera
                or snapshot.normals is None or labels is None):
            return
        found = up_from_planes(snapshot.positions, snapshot.normals, labels)
        if found is not None:
            self.set_up(found[0], "the largest horizontal plane")

    def points(self, paths: EntityPaths, positions: np.ndarray, colors: np.ndarray | None,
               pose: np.ndarray | None = None, log_pose: bool = True) -> None:
        """The cloud at ``world/points``, at most ``max_cloud_points``; with a ``pose``
        (camera-to-world, the cloud was taken by a moving camera) the points are put in the
        world and, with ``log_pose``, the camera follows the pose (`camera_pose`)."""
        import rerun as rr

        cap = self.rates.max_cloud_points or len(positions)
        stride = max(1, -(-len(positions) // cap))
        shown = positions[::stride]
        if pose is not None:
            if log_pose:
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

        from gngdt.schemas.cluster_colors import (
            UNCLUSTERED_RGB,
            clustering_edges,
            id_colors,
            node_cluster_ids,
        )

        positions = snapshot.positions
        if paths.camera not in self.poses:
            self.static_up(paths, snapshot)
        if paths.camera not in self.framings and snapshot.node_count >= 50:
            up = np.zeros(3)
            up[self.up_axis[0]] = self.up_axis[1]  # level views: the up axis, not the tilt
            framing = self.framings[paths.camera] = Framing.of(
                positions, self.poses.get(paths.camera), tuple(up))
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
