"""GNG-DT topologies: node arrays, edge sets and clusterings <-> ``gngdt.Topology``.

Arrays of a decoded :class:`TopologySnapshot` are read-only views on the message bytes
(zero-copy); ``.copy()`` them to modify. :func:`decode_topology` raises
:class:`~gngdt.schemas.messages.MessageError` for anything malformed or beyond the limits below.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

import gngdt.schemas.gngdt_pb2 as gngdt_pb2
from gngdt.core.clustering import cluster_count
from gngdt.schemas.messages import (
    MessageError,
    ns_to_timestamp,
    pack_array,
    parse_message,
    timestamp_to_ns,
    unpack_array,
)

__all__ = [
    "MAX_CLUSTERINGS",
    "MAX_EDGES_PER_NODE",
    "MAX_EDGE_SETS",
    "MAX_NAME_LENGTH",
    "MAX_TOPOLOGY_NODES",
    "TopologySnapshot",
    "decode_topology",
    "encode_topology",
]

#: What a GNG-DT learner can send, enforced before anything is allocated: a node keeps at most
#: 16 neighbours (``gngdt.core.kernels.layout.MAX_DEGREE``), so an edge set holds at most 8 edges a
#: node; a learner publishes a handful of named edge sets and clusterings.
MAX_TOPOLOGY_NODES = 1_000_000
MAX_EDGES_PER_NODE = 8
MAX_EDGE_SETS = 16
MAX_CLUSTERINGS = 16
MAX_NAME_LENGTH = 64


@dataclass
class TopologySnapshot:
    """One decoded ``gngdt.Topology``.

    positions: (N, 3) float32 metres; colors: (N, 3) uint8 RGB; normals: (N, 3) float32;
    errors: (N,) float32; node_ids: (N,) int64 persistent node ids -- each None if the publisher
    left it out. edges: property -> (E, 2) uint32 node-index pairs. clusterings: name -> (N,) int32
    labels; cluster_ids: name -> (K,) int64 persistent id of each label 0..K-1, for the
    clusterings whose publisher tracks them.
    """

    positions: np.ndarray
    colors: np.ndarray | None
    normals: np.ndarray | None
    errors: np.ndarray | None
    edges: dict[str, np.ndarray]
    clusterings: dict[str, np.ndarray]
    steps: int
    frame_sequence: int
    timestamp_ns: int
    frame_id: str
    quantization_error: dict[str, float] = field(default_factory=dict)
    cluster_counts: dict[str, int] = field(default_factory=dict)
    node_ids: np.ndarray | None = None
    cluster_ids: dict[str, np.ndarray] = field(default_factory=dict)
    #: the learner's final network on the stream's last frame: nothing newer will come
    settled: bool = False

    @property
    def node_count(self) -> int:
        return int(self.positions.shape[0])


def _node_array(values: np.ndarray | None, name: str, count: int, width: int | None) -> np.ndarray:
    array = np.asarray(values)
    expected = (count,) if width is None else (count, width)
    if array.shape != expected:
        raise ValueError(f"encode_topology: {name} must have shape {expected}, got {array.shape}")
    return array


def encode_topology(
    *,
    positions: np.ndarray,
    colors: np.ndarray | None,
    normals: np.ndarray | None,
    errors: np.ndarray | None,
    edges: Mapping[str, np.ndarray],
    clusterings: Mapping[str, np.ndarray],
    steps: int,
    frame_sequence: int,
    timestamp_ns: int,
    frame_id: str,
    quantization_error: Mapping[str, float] | None = None,
    node_ids: np.ndarray | None = None,
    cluster_ids: Mapping[str, np.ndarray] | None = None,
    settled: bool = False,
) -> gngdt_pb2.Topology:
    """Build a ``gngdt.Topology``; see :class:`TopologySnapshot` for shapes.

    Casts positions/normals/errors to float32, clips and rounds colours to uint8, edges to uint32,
    labels to int32. Raises ValueError naming the parameter for wrong shapes or edge indices >= N.
    ``cluster_count`` per clustering counts the distinct labels >= 0.
    """
    positions = _node_array(positions, "positions", np.shape(positions)[0], 3)
    count = positions.shape[0]
    message = gngdt_pb2.Topology(
        frame_sequence=int(frame_sequence), steps=int(steps), frame_id=frame_id,
        settled=bool(settled),
    )
    ns_to_timestamp(timestamp_ns, message.timestamp)
    message.positions.CopyFrom(pack_array(positions, np.float32))
    if colors is not None:
        colors = _node_array(colors, "colors", count, 3)
        message.colors.CopyFrom(pack_array(np.clip(np.rint(colors), 0, 255), np.uint8))
    if normals is not None:
        message.normals.CopyFrom(pack_array(_node_array(normals, "normals", count, 3), np.float32))
    if errors is not None:
        message.errors.CopyFrom(pack_array(_node_array(errors, "errors", count, None), np.float32))
    if node_ids is not None:
        message.node_ids.CopyFrom(
            pack_array(_node_array(node_ids, "node_ids", count, None), np.int64))
    cluster_ids = cluster_ids or {}
    unknown = sorted(set(cluster_ids) - set(clusterings))
    if unknown:
        raise ValueError(f"encode_topology: cluster_ids for unknown clusterings {unknown}")
    for prop, pairs in edges.items():
        pairs = np.asarray(pairs)
        if pairs.size == 0:
            pairs = pairs.reshape(0, 2)
        if pairs.ndim != 2 or pairs.shape[1] != 2:
            raise ValueError(f"encode_topology: edges[{prop!r}] must be (E, 2), got {pairs.shape}")
        if pairs.size and (pairs.min() < 0 or pairs.max() >= count):
            raise ValueError(
                f"encode_topology: edges[{prop!r}] has node indices outside 0..{count - 1}"
            )
        message.edges.add(property=prop, pairs=pack_array(pairs, np.uint32))
    for name, labels in clusterings.items():
        labels = _node_array(labels, f"clusterings[{name!r}]", count, None).astype(np.int32)
        clustering = message.clusterings.add(
            name=name, labels=pack_array(labels), cluster_count=cluster_count(labels)
        )
        if name in cluster_ids:
            ids = np.asarray(cluster_ids[name])
            n_labels = int(labels.max()) + 1 if labels.size else 0
            if ids.shape != (n_labels,):
                raise ValueError(f"encode_topology: cluster_ids[{name!r}] must have shape "
                                 f"({n_labels},), one id per label, got {ids.shape}")
            clustering.cluster_ids.CopyFrom(pack_array(ids, np.int64))
    for prop, value in (quantization_error or {}).items():
        message.quantization_error[prop] = float(value)
    return message


def _check_topology_limits(message: gngdt_pb2.Topology) -> None:
    """MessageError unless ``message`` has positions and few, short-named edge sets and
    clusterings."""
    if not message.HasField("positions"):
        raise MessageError("topology has no positions")
    if len(message.edges) > MAX_EDGE_SETS or len(message.clusterings) > MAX_CLUSTERINGS:
        raise MessageError(f"topology has {len(message.edges)} edge sets and "
                           f"{len(message.clusterings)} clusterings; at most {MAX_EDGE_SETS} and "
                           f"{MAX_CLUSTERINGS} are accepted")
    names = [edge_set.property for edge_set in message.edges]
    names += [clustering.name for clustering in message.clusterings]
    if any(len(name) > MAX_NAME_LENGTH for name in names):
        raise MessageError(f"topology has a name longer than {MAX_NAME_LENGTH} characters")


def _decode_node_array(
    message: gngdt_pb2.Topology, name: str, dtype: type, width: int | None, count: int
) -> np.ndarray | None:
    """Per-node field ``name``: (count,) or (count, width) of ``dtype``, None when absent."""
    if not message.HasField(name):
        return None
    expected = (count,) if width is None else (count, width)
    array = unpack_array(
        getattr(message, name),
        dtype=dtype,
        ndim=len(expected),
        max_elements=math.prod(expected),
        name=name,
    )
    if array.shape != expected:
        raise MessageError(f"{name}: shape {array.shape}, expected {expected} like positions")
    return array


def _decode_edges(message: gngdt_pb2.Topology, count: int) -> dict[str, np.ndarray]:
    """property -> (E, 2) uint32 node-index pairs, each index < ``count``."""
    edges: dict[str, np.ndarray] = {}
    for edge_set in message.edges:
        label = f"edges[{edge_set.property!r}]"
        if edge_set.property in edges:
            raise MessageError(f"{label} appears twice")
        pairs = unpack_array(edge_set.pairs, dtype=np.uint32, ndim=2,
                             max_elements=2 * MAX_EDGES_PER_NODE * count, name=label)
        if pairs.shape[1] != 2:
            raise MessageError(f"{label}: shape {pairs.shape}, expected (E, 2)")
        if pairs.size and int(pairs.max()) >= count:
            raise MessageError(f"{label}: node index {int(pairs.max())} >= node count {count}")
        edges[edge_set.property] = pairs
    return edges


def _decode_clusterings(
    message: gngdt_pb2.Topology, count: int
) -> tuple[dict[str, np.ndarray], dict[str, int], dict[str, np.ndarray]]:
    """name -> (count,) int32 labels (>= -1), name -> cluster_count, and name -> (K,) int64
    persistent cluster ids for the clusterings that carry them."""
    clusterings: dict[str, np.ndarray] = {}
    cluster_counts: dict[str, int] = {}
    cluster_ids: dict[str, np.ndarray] = {}
    for clustering in message.clusterings:
        label = f"clusterings[{clustering.name!r}]"
        if clustering.name in clusterings:
            raise MessageError(f"{label} appears twice")
        labels = unpack_array(
            clustering.labels, dtype=np.int32, ndim=1, max_elements=count, name=label
        )
        if labels.shape != (count,):
            raise MessageError(f"{label}: {labels.shape[0]} labels for {count} nodes")
        if labels.size and int(labels.min()) < -1:
            raise MessageError(f"{label}: label {int(labels.min())} < -1")
        clusterings[clustering.name] = labels
        cluster_counts[clustering.name] = int(clustering.cluster_count)
        if clustering.HasField("cluster_ids"):
            n_labels = int(labels.max()) + 1 if labels.size else 0
            ids = unpack_array(clustering.cluster_ids, dtype=np.int64, ndim=1,
                               max_elements=n_labels, name=f"{label}.cluster_ids")
            if ids.shape != (n_labels,):
                raise MessageError(f"{label}.cluster_ids: {ids.shape[0]} ids for {n_labels} "
                                   "labels")
            cluster_ids[clustering.name] = ids
    return clusterings, cluster_counts, cluster_ids


def decode_topology(
    message: gngdt_pb2.Topology | bytes, max_nodes: int = MAX_TOPOLOGY_NODES
) -> TopologySnapshot:
    """Decode and validate a ``gngdt.Topology`` (consistent N, edge indices < N, label lengths).

    At most ``max_nodes`` nodes, ``MAX_EDGES_PER_NODE`` edges per node in each of at most
    ``MAX_EDGE_SETS`` edge sets, and ``MAX_CLUSTERINGS`` clusterings, names of at most
    ``MAX_NAME_LENGTH`` characters, are accepted: what a learner really sends.
    """
    message = parse_message(gngdt_pb2.Topology, message)
    _check_topology_limits(message)
    positions = unpack_array(
        message.positions, dtype=np.float32, ndim=2, max_elements=3 * max_nodes, name="positions"
    )
    count = positions.shape[0]
    if positions.shape[1] != 3:
        raise MessageError(f"positions: shape {positions.shape}, expected (N, 3)")
    edges = _decode_edges(message, count)
    clusterings, cluster_counts, cluster_ids = _decode_clusterings(message, count)
    return TopologySnapshot(
        positions=positions,
        colors=_decode_node_array(message, "colors", np.uint8, 3, count),
        normals=_decode_node_array(message, "normals", np.float32, 3, count),
        errors=_decode_node_array(message, "errors", np.float32, None, count),
        edges=edges,
        clusterings=clusterings,
        steps=int(message.steps),
        frame_sequence=int(message.frame_sequence),
        timestamp_ns=timestamp_to_ns(message.timestamp),
        frame_id=message.frame_id,
        quantization_error=dict(message.quantization_error),
        cluster_counts=cluster_counts,
        node_ids=_decode_node_array(message, "node_ids", np.int64, None, count),
        cluster_ids=cluster_ids,
        settled=message.settled,
    )
