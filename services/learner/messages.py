"""The learner's wire messages: what a learned frame becomes on zenoh (topology, objects, scene,
status), and the one decode path of an incoming ``points`` sample."""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np

from gngdt.core.clustering import POS, cluster_count
from gngdt.core.gas.sampling import finite_rows
from gngdt.core.learner.frame_budget import Budget
from gngdt.core.learner.frame_learner import DEFAULT_MAX_CLOUD_POINTS
from gngdt.core.learner.results import LearnerFigures, Publication
from gngdt.schemas.wire import FrameStamp


def topology_message(published: Publication, stamp: FrameStamp, settled: bool = False) -> Any:
    """The ``gngdt.Topology`` of a learned frame (``settled``: the final network, settled on
    the stream's last frame)."""
    from gngdt.schemas.topology import encode_topology

    learned = published.learned
    return encode_topology(
        positions=published.positions, colors=published.colors, normals=published.normals,
        errors=published.errors, edges=learned.edges, clusterings=learned.labels,
        steps=published.steps, frame_sequence=stamp.sequence,
        timestamp_ns=stamp.capture_time_ns, frame_id=published.frame_id,
        quantization_error=published.quantization_error, node_ids=published.node_ids,
        cluster_ids=learned.cluster_ids, settled=settled)


def objects_message(published: Publication, stamp: FrameStamp) -> Any:
    """The objects as a ``foxglove.SceneUpdate``, coloured as the logger colours clusters."""
    from gngdt.core.segmentation.supports import ROLE_NAMES
    from gngdt.schemas.cluster_colors import id_colors
    from gngdt.schemas.scene import objects_to_scene_update

    objects = published.objects
    return objects_to_scene_update(
        ids=objects.ids, centers=objects.centers, quaternions_xyzw=objects.quaternions_xyzw,
        sizes=objects.sizes, colors=id_colors(objects.ids), node_counts=objects.node_counts,
        centroids=objects.centroids, mean_colors=objects.colors, normals=objects.normals,
        timestamp_ns=stamp.capture_time_ns, frame_id=published.frame_id,
        roles=[ROLE_NAMES[role] for role in objects.roles])


def scene_message(published: Publication, stamp: FrameStamp) -> Any:
    """Nodes in their learned colours and every clustering's edges coloured by cluster, as a
    ``foxglove.SceneUpdate``."""
    from gngdt.schemas.cluster_colors import clustering_edges, node_colors
    from gngdt.schemas.scene import topology_to_scene_update

    learned = published.learned
    positions = published.positions
    layers = {}
    for name, labels in learned.labels.items():
        pairs = clustering_edges(name, learned.edges, labels)
        layers[name] = (pairs, node_colors(labels, learned.cluster_ids[name],
                                           published.min_cluster_size))
    pos_edges = learned.edges[POS]
    spacing = (float(np.median(np.linalg.norm(
        positions[pos_edges[:, 0]] - positions[pos_edges[:, 1]], axis=1)))
        if len(pos_edges) else 0.02)
    return topology_to_scene_update(
        positions=positions, colors=np.clip(np.rint(published.colors), 0, 255),
        node_size=0.5 * spacing, edge_layers=layers, timestamp_ns=stamp.capture_time_ns,
        frame_id=published.frame_id)


def status_message(figures: LearnerFigures, stamp: FrameStamp, latency_ms: float,
                   latency_percentiles: tuple[float, float], published: Publication | None,
                   settled: str = "", budget: Budget | None = None) -> Any:
    """The ``gngdt.LearnerStatus`` of the learner's ``figures`` after the last publication
    (None: nothing published yet); ``latency_percentiles``: p50 and p99 of the recent frames
    (ms); ``settled``: how learning on the stream's last frame stopped; ``budget``: the last
    frame's time budget."""
    from gngdt.schemas.status import encode_status

    counters = figures.counters
    return encode_status(
        timestamp_ns=stamp.capture_time_ns,
        frame_sequence=stamp.sequence,
        frame_id=figures.frame_id,
        steps=figures.steps,
        steps_per_second=figures.steps_per_second,
        nodes=figures.nodes,
        frames_received=counters.frames_received,
        frames_used=counters.frames_used,
        frames_dropped=counters.frames_dropped,
        malformed_messages=counters.malformed_messages,
        latency_ms=latency_ms,
        latency_p50_ms=latency_percentiles[0],
        latency_p99_ms=latency_percentiles[1],
        quantization_error={} if published is None else published.quantization_error,
        cluster_counts={} if published is None else {
            name: cluster_count(labels) for name, labels in published.learned.labels.items()},
        seen_nodes=figures.ghosts.seen_nodes,
        ghost_share=figures.ghosts.ghost_share,
        ghost_distance_m=figures.ghost_distance_m,
        nodes_forgotten=figures.nodes_forgotten,
        frames_other_frame=counters.frames_other_frame,
        frames_pose_rejected=counters.frames_pose_rejected,
        pose_problem=figures.pose_problem,
        settle_reason=settled,
        settled=bool(settled),
        frame_budget_ms=0.0 if budget is None else budget.seconds * 1000.0,
        frame_steps=figures.frame_steps,
        frames_lost_tracking=counters.frames_lost_tracking,
        tracking=figures.tracking,
        frames_posed=counters.frames_posed,
        frames_lost_by_reason=figures.lost_reasons,
    )


class PointsMessage(NamedTuple):
    """One decoded ``points`` sample: positions (N, 3) float32 metres in the cloud's own
    (camera) frame, colors (N, 3) uint8, the frame they are placed in and the (4, 4) pose that
    places them there (None: the identity, the points are in ``frame_id`` as they are)."""

    stamp: FrameStamp
    positions: np.ndarray
    colors: np.ndarray
    frame_id: str
    pose: np.ndarray | None
    #: when the camera took it (the cloud's own timestamp, ns; the stamp's capture time when
    #: it has none): the learner's motion and pose checks use it
    sensor_ns: int


def finite_points(
    positions: np.ndarray, colors: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Drop points with a NaN/inf coordinate (a foreign publisher may send them)."""
    finite = finite_rows(positions)
    if finite is None:
        return positions, colors
    return positions[finite], None if colors is None else colors[finite]


def decode_points(payload: bytes, attachment: bytes | None,
                  max_points: int = DEFAULT_MAX_CLOUD_POINTS,
                  now_ns: int | None = None) -> PointsMessage:
    """The learner's decode path for one ``points`` sample.

    positions: N >= 1 finite points. Raises ``ValueError`` (``MessageError`` for the payload)
    for a missing/malformed attachment, a capture time more than a day from ``now_ns``
    (default: this clock), an undecodable or oversized cloud (``max_points``, checked before
    allocation), a cloud without colour fields (the contract's points carry red, green, blue: a
    colourless model could learn nothing else) or without a single finite point, and a pose
    that is not a rigid transform (non-unit quaternion, NaN), naming the frame.
    """
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    from gngdt.schemas.clouds import cloud_pose, msg_to_cloud
    from gngdt.schemas.messages import MessageError, parse_message, timestamp_to_ns

    stamp = FrameStamp.from_attachment(attachment)
    stamp.check_clock(time.time_ns() if now_ns is None else now_ns)
    message = parse_message(PointCloud, payload)
    # views into the payload: learning samples only samples_per_frame of its points
    positions, colors = msg_to_cloud(message, max_points=max_points, copy=False)
    if colors is None:
        raise MessageError("cloud has no red/green/blue fields; the learner needs colour")
    positions, colors = finite_points(positions, colors)
    if len(positions) == 0:
        raise MessageError("no finite points in the cloud")
    pose = cloud_pose(message)
    sensor_ns = timestamp_to_ns(message.timestamp) or stamp.capture_time_ns
    return PointsMessage(stamp, positions, colors, message.frame_id,
                         None if np.array_equal(pose, np.eye(4)) else pose, sensor_ns)
