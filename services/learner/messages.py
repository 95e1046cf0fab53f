"""The learner's wire messages: what a learned frame becomes on zenoh (topology, objects, scene,
status), and the one decode path of an incoming ``points`` sample."""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np

from gngdt.core.clustering import POS
from gngdt.core.gas.sampling import finite_rows
from gngdt.core.learner.frame_budget import Budget
from gngdt.core.learner.frame_learner import DEFAULT_MAX_POINTS, FrameLearner, LearnedFrame
from gngdt.core.objects.object_set import ObjectSet
from gngdt.schemas.wire import FrameStamp


def topology_message(learner: FrameLearner, stamp: FrameStamp,
                     quantization_error: dict[str, float], learned: LearnedFrame) -> Any:
    """The current ``gngdt.Topology``."""
    from gngdt.schemas.topology import encode_topology

    model = learner.model
    return encode_topology(
        positions=model.positions_, colors=model.colors_, normals=model.normals_,
        errors=model.errors_, edges=learned.edges, clusterings=learned.labels,
        steps=int(model.n_steps_), frame_sequence=stamp.sequence,
        timestamp_ns=stamp.capture_time_ns, frame_id=learner.frame_id or learner.camera,
        quantization_error=quantization_error, node_ids=model.node_ids_,
        cluster_ids=learned.cluster_ids)


def objects_message(learner: FrameLearner, stamp: FrameStamp, objects: ObjectSet) -> Any:
    """The objects as a ``foxglove.SceneUpdate``, coloured as the logger colours clusters."""
    from gngdt.core.segmentation.supports import ROLE_NAMES
    from gngdt.schemas.cluster_colors import id_colors
    from gngdt.schemas.scene import objects_to_scene_update

    return objects_to_scene_update(
        ids=objects.ids, centers=objects.centers, quaternions_xyzw=objects.quaternions_xyzw,
        sizes=objects.sizes, colors=id_colors(objects.ids), node_counts=objects.node_counts,
        centroids=objects.centroids, mean_colors=objects.colors, normals=objects.normals,
        timestamp_ns=stamp.capture_time_ns, frame_id=learner.frame_id or learner.camera,
        roles=[ROLE_NAMES[role] for role in objects.roles])


def scene_message(learner: FrameLearner, stamp: FrameStamp, learned: LearnedFrame) -> Any:
    """Nodes in their learned colours and every clustering's edges coloured by cluster, as a
    ``foxglove.SceneUpdate``."""
    from gngdt.schemas.cluster_colors import clustering_edges, node_colors
    from gngdt.schemas.scene import topology_to_scene_update

    model = learner.model
    positions = model.positions_
    layers = {}
    for name, labels in learned.labels.items():
        pairs = clustering_edges(name, learned.edges, labels)
        layers[name] = (pairs, node_colors(labels, learned.cluster_ids[name],
                                           learner.options.min_cluster_size))
    pos_edges = learned.edges[POS]
    spacing = (float(np.median(np.linalg.norm(
        positions[pos_edges[:, 0]] - positions[pos_edges[:, 1]], axis=1)))
        if len(pos_edges) else 0.02)
    return topology_to_scene_update(
        positions=positions, colors=np.clip(np.rint(model.colors_), 0, 255),
        node_size=0.5 * spacing, edge_layers=layers, timestamp_ns=stamp.capture_time_ns,
        frame_id=learner.frame_id or learner.camera)


def status_message(learner: FrameLearner, stamp: FrameStamp, latency_ms: float,
                   latency_percentiles: tuple[float, float], topology: Any | None,
                   settled: str = "", budget: Budget | None = None) -> Any:
    """The ``gngdt.LearnerStatus`` after publishing ``topology`` (None: none published yet, or
    after a frame that was not learned, e.g. its pose was rejected); ``latency_percentiles``:
    p50 and p99 of the recent frames (ms); ``settled``: how learning on the stream's last frame
    stopped; ``budget``: the last frame's time budget."""
    from gngdt.schemas.status import encode_status

    counters = learner.counters
    seconds = counters.learning_seconds
    model = learner.model
    steps, nodes = (int(model.n_steps_), int(model.n_nodes_)) if model is not None else (0, 0)
    return encode_status(
        timestamp_ns=stamp.capture_time_ns,
        frame_sequence=stamp.sequence,
        frame_id=learner.camera,
        steps=steps,
        steps_per_second=counters.learning_steps / seconds if seconds > 0 else 0.0,
        nodes=nodes,
        frames_received=counters.frames_received,
        frames_used=counters.frames_used,
        frames_dropped=counters.frames_dropped,
        malformed_messages=counters.malformed_messages,
        latency_ms=latency_ms,
        latency_p50_ms=latency_percentiles[0],
        latency_p99_ms=latency_percentiles[1],
        quantization_error={} if topology is None else dict(topology.quantization_error),
        cluster_counts={} if topology is None else {c.name: c.cluster_count
                                                    for c in topology.clusterings},
        seen_nodes=learner.ghosts.seen_nodes,
        ghost_share=learner.ghosts.ghost_share,
        ghost_distance_m=learner.options.ghost_distance_m,
        nodes_forgotten=int(getattr(model, "n_forgotten_", 0)),
        frames_other_frame=counters.frames_other_frame,
        frames_pose_rejected=counters.frames_pose_rejected,
        pose_problem=learner.poses.last_problem,
        settle_reason=settled,
        settled=bool(settled),
        frame_budget_ms=0.0 if budget is None else budget.seconds * 1000.0,
        frame_steps=learner.last_steps,
        frames_lost_tracking=counters.frames_lost_tracking,
        tracking=tracking_state(learner),
    )


def tracking_state(learner: FrameLearner) -> str:
    """"" (not tracking), "tracked" or "lost: <why>" for the last cloud (status field)."""
    if learner.tracking is None:
        return ""
    problem = learner.tracking.problem
    return f"lost: {problem}" if problem else "tracked"


class PointsMessage(NamedTuple):
    """One decoded ``points`` sample: positions (N, 3) float32 metres in the cloud's own
    (camera) frame, colors (N, 3) uint8, the frame they are placed in and the (4, 4) pose that
    places them there (None: the identity, the points are in ``frame_id`` as they are)."""

    stamp: FrameStamp
    positions: np.ndarray
    colors: np.ndarray
    frame_id: str
    pose: np.ndarray | None


def finite_points(
    positions: np.ndarray, colors: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Drop points with a NaN/inf coordinate (a foreign publisher may send them)."""
    finite = finite_rows(positions)
    if finite is None:
        return positions, colors
    return positions[finite], None if colors is None else colors[finite]


def decode_points(payload: bytes, attachment: bytes | None, max_points: int = DEFAULT_MAX_POINTS,
                  now_ns: int | None = None) -> PointsMessage:
    """The learner's decode path for one ``points`` sample.

    positions: N >= 1 finite points. Raises ``ValueError`` (``MessageError`` for the payload)
    for a missing/malformed attachment, a capture time more than a day from ``now_ns``
    (default: this clock), an undecodable or oversized cloud (``max_points``, checked before
    allocation), a cloud without colour fields (DESIGN's points carry red, green, blue: a
    colourless model could learn nothing else) or without a single finite point, and a pose
    that is not a rigid transform (non-unit quaternion, NaN), naming the frame.
    """
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    from gngdt.schemas.clouds import cloud_pose, msg_to_cloud
    from gngdt.schemas.messages import MessageError, parse_message

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
    return PointsMessage(stamp, positions, colors, message.frame_id,
                         None if np.array_equal(pose, np.eye(4)) else pose)
