"""gngdt -> ROS 2: a camera's clouds, learned nodes, graph, objects, camera pose and status as
ROS 2 topics (docs/contracts.md "ROS 2").

Clouds are translated on their own thread (latest wins: a cloud waiting is replaced by a newer
one), everything the learner publishes on another, so the slow graph never delays a cloud. A
topic nobody subscribes to (zenoh's matching status) is not encoded at all.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict
from typing import TYPE_CHECKING

import numpy as np

from gngdt.io.ros2.markers import ObjectMarker, encode_graph_markers, encode_object_markers
from gngdt.io.ros2.messages import (
    DIAGNOSTIC_ARRAY,
    MARKER_ARRAY,
    OK,
    POINT_CLOUD2,
    STALE,
    TF_MESSAGE,
    Status,
    Transform,
    encode_diagnostics,
    encode_pointcloud2,
    encode_tf,
    type_hash,
)
from gngdt.io.ros2.wire import QOS_DEFAULT_10, QOS_TF
from gngdt.schemas.wire import LEARNER, topic
from gngdt.services.ros2.worker import Worker

if TYPE_CHECKING:
    import zenoh

    from gngdt.io.ros2.node import Ros2Node, Ros2Publisher
    from gngdt.schemas.status import LearnerStatusInfo

log = logging.getLogger(__name__)

#: marker ids are int32 in ROS: objects with larger persistent ids are not drawn (counted)
MAX_MARKER_ID = 2**31 - 1
#: the learner's status is reported as STALE when it is older than this
STATUS_STALE_S = 5.0


def ros_topics(camera: str) -> dict[str, str]:
    """The ROS 2 topics the bridge publishes for ``camera`` (stream -> fully qualified name)."""
    prefix = f"/gngdt/{camera}"
    return {"points": f"{prefix}/points", "nodes": f"{prefix}/nodes", "graph": f"{prefix}/graph",
            "objects": f"{prefix}/objects", "tf": "/tf", "status": f"{prefix}/status"}


class GngdtToRos:
    """Subscribes to ``gngdt/<cam>/{points,topology,objects,learner/status,tf}`` on ``session``
    and publishes their translations with ``node``.

    camera_frame: ROS frame of a posed cloud's points (a cloud with a pose is published in it,
    and its pose as ``/tf`` fixed frame -> camera_frame, unless ``gngdt/<cam>/tf`` gives the
    transforms itself). graph_period_s: shortest interval between two graphs (MarkerArrays of
    thousands of lines take ~100 ms to encode).
    """

    def __init__(self, session: zenoh.Session, node: Ros2Node, camera: str, camera_frame: str,
                 graph_period_s: float) -> None:
        import zenoh

        self.camera = camera
        self.camera_frame = camera_frame
        self.graph_period_s = graph_period_s
        names = ros_topics(camera)
        kinds = {"points": POINT_CLOUD2, "nodes": POINT_CLOUD2, "graph": MARKER_ARRAY,
                 "objects": MARKER_ARRAY, "tf": TF_MESSAGE, "status": DIAGNOSTIC_ARRAY}
        self.publishers: dict[str, Ros2Publisher] = {
            stream: node.create_publisher(names[stream], kind, type_hash(kind),
                                          QOS_TF if stream == "tf" else QOS_DEFAULT_10)
            for stream, kind in kinds.items()}
        self.clouds = Worker("points", self._on_cloud, capacity=1, latest_only=("points",))
        self.learned = Worker("learner", self._on_learned, capacity=32,
                              latest_only=("topology", "objects", "learner/status"))
        self.published = dict.fromkeys(kinds, 0)
        self.objects_not_drawn = 0
        self._tf_given = False  # gngdt/<cam>/tf seen: clouds' poses are not sent as /tf again
        self._shown_objects: set[int] = set()
        self._last_graph = -float("inf")
        self._status: tuple[float, LearnerStatusInfo] | None = None
        self._subscribers = [  # called on zenoh's thread, not through a queue of 256 samples
            session.declare_subscriber(topic(camera, stream), zenoh.handlers.Callback(
                self._feed(worker, stream), None, indirect=False))
            for worker, stream in ((self.clouds, "points"), (self.learned, "topology"),
                                   (self.learned, "objects"), (self.learned, "learner/status"),
                                   (self.learned, "tf"))]
        self.clouds.start()
        self.learned.start()

    def _feed(self, worker: Worker, stream: str):
        def on_sample(sample: zenoh.Sample) -> None:
            if stream == "points" and not self._cloud_wanted():
                return  # not even copied: a cloud is megabytes, and nobody would get it
            attachment = sample.attachment
            worker.put(stream, sample.payload.to_bytes(),
                       None if attachment is None else attachment.to_bytes())
        return on_sample

    def _publish(self, stream: str, cdr: bytes) -> None:
        self.publishers[stream].publish(cdr)
        self.published[stream] += 1

    def _wanted(self, stream: str) -> bool:
        return self.publishers[stream].has_subscribers

    def _cloud_wanted(self) -> bool:
        """A cloud's points or its pose (/tf) has a subscriber."""
        return self._wanted("points") or self._wanted("tf")

    # --- clouds -------------------------------------------------------------------------------

    def _on_cloud(self, stream: str, payload: bytes, attachment: bytes | None) -> None:
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        from gngdt.schemas.clouds import MAX_CLOUD_POINTS, cloud_pose, msg_to_cloud
        from gngdt.schemas.messages import parse_message, timestamp_to_ns

        if not self._cloud_wanted():
            return
        message = parse_message(PointCloud, payload)
        stamp_ns = timestamp_to_ns(message.timestamp)
        pose = cloud_pose(message)
        frame_id = message.frame_id
        if not np.array_equal(pose, np.eye(4)):  # points in the camera frame, posed in frame_id
            if not self._tf_given and self._wanted("tf"):
                self._publish("tf", encode_tf([camera_transform(frame_id, self.camera_frame,
                                                                pose, stamp_ns)]))
            frame_id = self.camera_frame
        if self._wanted("points"):
            positions, colors = msg_to_cloud(message, max_points=MAX_CLOUD_POINTS, copy=False)
            self._publish("points", encode_pointcloud2(positions, colors=colors,
                                                       stamp_ns=stamp_ns, frame_id=frame_id))

    # --- what the learner publishes -----------------------------------------------------------

    def _on_learned(self, stream: str, payload: bytes, attachment: bytes | None) -> None:
        if stream == "topology":
            self._on_topology(payload)
        elif stream == "objects":
            self._on_objects(payload)
        elif stream == "learner/status":
            from gngdt.schemas.status import decode_status

            self._status = (time.monotonic(), decode_status(payload))
        elif stream == "tf":
            self._on_transform(payload)

    def _on_topology(self, payload: bytes) -> None:
        from gngdt.schemas.cluster_colors import edge_colors, id_colors, node_cluster_ids
        from gngdt.schemas.topology import decode_topology

        graph_due = (self._wanted("graph")
                     and time.monotonic() - self._last_graph >= self.graph_period_s)
        if not (self._wanted("nodes") or graph_due):
            return
        snapshot = decode_topology(payload)
        frame_id = snapshot.frame_id or self.camera
        ids = {name: node_cluster_ids(labels, snapshot.cluster_ids.get(name))
               for name, labels in snapshot.clusterings.items()}
        if self._wanted("nodes"):
            self._publish("nodes", encode_pointcloud2(
                snapshot.positions, colors=snapshot.colors, normals=snapshot.normals, labels=ids,
                stamp_ns=snapshot.timestamp_ns, frame_id=frame_id))
        if graph_due:
            layers = {}
            for name, pairs in snapshot.edges.items():
                clusters = ids.get(name, np.full(snapshot.node_count, -1, np.int64))
                layers[name] = (pairs, edge_colors(pairs, id_colors(clusters), clusters))
            self._publish("graph", encode_graph_markers(
                snapshot.positions, layers, stamp_ns=snapshot.timestamp_ns, frame_id=frame_id))
            self._last_graph = time.monotonic()

    def _on_objects(self, payload: bytes) -> None:
        from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

        from gngdt.schemas.messages import parse_message
        from gngdt.schemas.scene import decode_object_boxes

        if not self._wanted("objects"):
            return
        message = parse_message(SceneUpdate, payload)
        boxes = decode_object_boxes(message)
        frame_id = message.entities[0].frame_id if message.entities else self.camera
        drawn = [k for k, object_id in enumerate(boxes.ids) if 0 <= object_id <= MAX_MARKER_ID]
        self.objects_not_drawn += len(boxes.ids) - len(drawn)
        markers = [ObjectMarker(int(boxes.ids[k]), tuple(boxes.centers[k]),
                                tuple(2 * boxes.half_sizes[k]), tuple(boxes.quaternions_xyzw[k]),
                                tuple(boxes.colors[k] / 255.0), boxes.labels[k]) for k in drawn]
        shown = {marker.id for marker in markers}
        self._publish("objects", encode_object_markers(
            markers, stamp_ns=boxes.timestamp_ns, frame_id=frame_id,
            gone_ids=sorted(self._shown_objects - shown)))
        self._shown_objects = shown

    def _on_transform(self, payload: bytes) -> None:
        from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform

        from gngdt.core.sensor.geometry import checked_translation, unit_quaternion
        from gngdt.schemas.messages import parse_message, timestamp_to_ns

        message = parse_message(FrameTransform, payload)
        what = f"transform {message.parent_frame_id!r} -> {message.child_frame_id!r}"
        t, q = message.translation, message.rotation
        translation = checked_translation([t.x, t.y, t.z], what)
        rotation = unit_quaternion([q.x, q.y, q.z, q.w], what)
        self._tf_given = True
        if self._wanted("tf"):
            self._publish("tf", encode_tf([Transform(
                message.parent_frame_id, message.child_frame_id,
                timestamp_to_ns(message.timestamp), tuple(translation), tuple(rotation))]))

    # --- status -------------------------------------------------------------------------------

    def publish_status(self, bridge: Status) -> None:
        """``/gngdt/<cam>/status``: the bridge's own status and the learner's last one (STALE
        when older than ``STATUS_STALE_S``, absent before the first)."""
        statuses = [bridge]
        if self._status is not None:
            received_at, learner = self._status
            values = {key: value for key, value in asdict(learner).items()
                      if not isinstance(value, dict)}
            values.update({f"clusters/{name}": count
                           for name, count in learner.cluster_counts.items()})
            stale = time.monotonic() - received_at > STATUS_STALE_S
            statuses.append(Status(
                topic(self.camera, LEARNER), STALE if stale else OK,
                "no status for a while" if stale else f"{learner.nodes} nodes",
                self.camera, values))
        self._publish("status", encode_diagnostics(statuses, stamp_ns=time.time_ns()))

    def counts(self) -> dict[str, int]:
        """What the bridge did on this side, for its status."""
        values = {f"published/{stream}": count for stream, count in self.published.items()}
        for worker in (self.clouds, self.learned):
            values.update({f"{worker.name}/{key}": value
                           for key, value in asdict(worker.counts).items()})
        values["objects_not_drawn"] = self.objects_not_drawn
        return values

    def idle(self) -> bool:
        return self.clouds.idle() and self.learned.idle()

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()
        self.clouds.stop()
        self.learned.stop()


def camera_transform(fixed_frame: str, camera_frame: str, pose: np.ndarray,
                     stamp_ns: int) -> Transform:
    """The /tf transform fixed frame -> camera of a (4, 4) camera-to-fixed pose."""
    from gngdt.core.sensor.geometry import matrix_to_pose

    translation, quaternion = matrix_to_pose(pose)
    return Transform(fixed_frame, camera_frame, stamp_ns, tuple(translation.tolist()),
                     tuple(quaternion.tolist()))
