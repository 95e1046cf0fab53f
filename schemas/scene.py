"""foxglove.SceneUpdate messages: the learned scene and its objects, as Foxglove draws them.

Each update first deletes every entity older than its own timestamp (a ``SceneEntityDeletion`` of
type ALL), then adds the current ones, so a consumer that missed messages (they are published
latest-wins) still shows exactly the newest state. All positions are in the topology's frame
(``frame_id``), metres.

- objects (``gngdt/<cam>/objects``): one entity per object, id ``object/<id>`` (persistent), with
  an oriented cube in the object's colour, a text label, and metadata: ``id``, ``node_count``,
  ``centroid``, ``size``, ``mean_color``, ``normal`` (space-separated numbers) and ``role``
  (``object``; ``support``, a table or wall something rests on; ``clutter``, background
  structure): a consumer that wants the objects only keeps ``role == "object"``.
- scene (``gngdt/<cam>/scene``): entity ``nodes`` (a sphere per node in its learned colour) and
  ``edges/<clustering>`` (a line list per clustering, vertices coloured by cluster).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3

from gngdt.core.segmentation.supports import OBJECT, ROLE_NAMES
from gngdt.schemas.messages import MessageError, ns_to_timestamp, parse_message, timestamp_to_ns

OBJECT_ID_PREFIX = "object/"
#: the role of an object proper (a ``role`` metadata value; the others are supports and clutter)
OBJECT_ROLE = ROLE_NAMES[OBJECT]
#: most objects a decoded objects update may hold; more is refused as malformed
MAX_OBJECTS = 4096
#: opacity of object cubes, so the nodes inside stay visible
OBJECT_ALPHA = 0.35


def _color(rgb: np.ndarray, alpha: float = 1.0) -> Color:
    r, g, b = (float(c) / 255.0 for c in rgb)
    return Color(r=r, g=g, b=b, a=alpha)


def _words(values: np.ndarray, digits: int = 4) -> str:
    return " ".join(f"{float(v):.{digits}g}" for v in values)


def _new_update(timestamp_ns: int) -> SceneUpdate:
    update = SceneUpdate()
    deletion = update.deletions.add(type=SceneEntityDeletion.ALL)
    ns_to_timestamp(timestamp_ns, deletion.timestamp)
    return update


def _new_entity(update: SceneUpdate, entity_id: str, timestamp_ns: int,
                frame_id: str) -> SceneEntity:
    entity = update.entities.add(id=entity_id, frame_id=frame_id)
    ns_to_timestamp(timestamp_ns, entity.timestamp)
    return entity


def objects_to_scene_update(*, ids: np.ndarray, centers: np.ndarray, quaternions_xyzw: np.ndarray,
                            sizes: np.ndarray, colors: np.ndarray, node_counts: np.ndarray,
                            centroids: np.ndarray, mean_colors: np.ndarray, normals: np.ndarray,
                            timestamp_ns: int, frame_id: str,
                            roles: Sequence[str] | None = None) -> SceneUpdate:
    """One entity per object (row k of every array).

    ids: (K,) int64; centers, centroids, normals: (K, 3) metres / unit; quaternions_xyzw: (K, 4);
    sizes: (K, 3) full extents, metres; colors: (K, 3) uint8 display colour of each object;
    mean_colors: (K, 3) mean node colour (0-255); node_counts: (K,) int; roles: K role names
    (default: every one an ``object``); the label of any other names its role.
    """
    update = _new_update(timestamp_ns)
    for k in range(len(ids)):
        object_id = int(ids[k])
        entity = _new_entity(update, f"{OBJECT_ID_PREFIX}{object_id}", timestamp_ns, frame_id)
        x, y, z, w = (float(v) for v in quaternions_xyzw[k])
        cx, cy, cz = (float(v) for v in centers[k])
        pose = Pose(position=Vector3(x=cx, y=cy, z=cz), orientation=Quaternion(x=x, y=y, z=z, w=w))
        sx, sy, sz = (float(v) for v in sizes[k])
        entity.cubes.add(pose=pose, size=Vector3(x=sx, y=sy, z=sz),
                         color=_color(colors[k], OBJECT_ALPHA))
        role = OBJECT_ROLE if roles is None else roles[k]
        label = f"#{object_id}" if role == OBJECT_ROLE else f"#{object_id} {role}"
        entity.texts.add(pose=pose, billboard=True, font_size=14.0, scale_invariant=True,
                         color=_color(colors[k]), text=label)
        for key, value in (("id", str(object_id)), ("node_count", str(int(node_counts[k]))),
                           ("centroid", _words(centroids[k])), ("size", _words(sizes[k])),
                           ("mean_color", _words(mean_colors[k], 3)),
                           ("normal", _words(normals[k])), ("role", role)):
            entity.metadata.add(key=key, value=value)
    return update


EdgeLayers = dict[str, tuple[np.ndarray, np.ndarray]]


def topology_to_scene_update(*, positions: np.ndarray, colors: np.ndarray | None,
                             node_size: float, edge_layers: EdgeLayers, timestamp_ns: int,
                             frame_id: str) -> SceneUpdate:
    """Entity ``nodes`` (spheres of ``node_size`` metres in the learned colours) and one line-list
    entity ``edges/<name>`` per layer.

    positions: (N, 3) metres; colors: (N, 3) uint8 or None (grey); edge_layers: name ->
    (pairs (E, 2) node indices, vertex colours (N, 3) uint8).
    """
    update = _new_update(timestamp_ns)
    xyz = np.asarray(positions, dtype=np.float64).tolist()
    count = len(xyz)
    node_rgb = (np.full((count, 3), 150, np.uint8) if colors is None
                else np.asarray(colors, dtype=np.uint8))
    # one Color message per distinct colour, shared by reference (building messages dominates)
    all_rgb = np.concatenate([node_rgb, *(np.asarray(vertex_colors, dtype=np.uint8)
                                          for _, vertex_colors in edge_layers.values())])
    packed = all_rgb.astype(np.int64) @ np.array([1 << 16, 1 << 8, 1])
    distinct, which = np.unique(packed, return_inverse=True)
    palette = [_color(np.array([(v >> 16) & 255, (v >> 8) & 255, v & 255])) for v in distinct]
    which = which.ravel().tolist()
    nodes = _new_entity(update, "nodes", timestamp_ns, frame_id)
    size = Vector3(x=node_size, y=node_size, z=node_size)
    add_sphere = nodes.spheres.add
    for (px, py, pz), index in zip(xyz, which[:count], strict=True):
        sphere = add_sphere(size=size, color=palette[index])
        position = sphere.pose.position
        position.x, position.y, position.z = px, py, pz
        sphere.pose.orientation.w = 1.0
    points = [Point3(x=px, y=py, z=pz) for px, py, pz in xyz]
    for layer, (name, (pairs, _)) in enumerate(edge_layers.items(), start=1):
        entity = _new_entity(update, f"edges/{name}", timestamp_ns, frame_id)
        line = entity.lines.add(type=LinePrimitive.LINE_LIST, thickness=2.0, scale_invariant=True)
        line.pose.orientation.w = 1.0
        line.points.extend(points)
        line.colors.extend([palette[index] for index in which[layer * count:(layer + 1) * count]])
        line.indices.extend(np.asarray(pairs, dtype=np.int64).ravel().tolist())
    return update


@dataclass
class ObjectBoxes:
    """Boxes of one decoded objects update (row k = one object).

    ids: (K,) int64 (-1 where the entity id is not ``object/<int>``); centers: (K, 3);
    half_sizes: (K, 3); quaternions_xyzw: (K, 4); colors: (K, 4) uint8 RGBA; labels: K texts;
    node_counts: (K,) int64 (0 when not given); roles: K role names (``object`` when not given).
    """

    timestamp_ns: int
    ids: np.ndarray
    centers: np.ndarray
    half_sizes: np.ndarray
    quaternions_xyzw: np.ndarray
    colors: np.ndarray
    labels: list[str]
    node_counts: np.ndarray
    roles: list[str]


def decode_object_boxes(message: SceneUpdate | bytes,
                        max_objects: int = MAX_OBJECTS) -> ObjectBoxes:
    """The first cube of every entity of an objects update; ``MessageError`` when malformed or
    holding more than ``max_objects`` entities (a flood of ids is refused, not stored)."""
    message = parse_message(SceneUpdate, message)
    entities = [entity for entity in message.entities if entity.cubes]
    if len(message.entities) > max_objects:
        raise MessageError(f"objects update has {len(message.entities)} entities, more than the "
                           f"limit of {max_objects}")
    count = len(entities)
    boxes = ObjectBoxes(
        timestamp_ns=timestamp_to_ns(entities[0].timestamp) if count else 0,
        ids=np.full(count, -1, dtype=np.int64),
        centers=np.zeros((count, 3)),
        half_sizes=np.zeros((count, 3)),
        quaternions_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (count, 1)),
        colors=np.zeros((count, 4), dtype=np.uint8),
        labels=[],
        node_counts=np.zeros(count, np.int64),
        roles=[],
    )
    for k, entity in enumerate(entities):
        cube = entity.cubes[0]
        suffix = entity.id.removeprefix(OBJECT_ID_PREFIX)
        if entity.id.startswith(OBJECT_ID_PREFIX) and suffix.isdigit() and len(suffix) < 19:
            boxes.ids[k] = int(suffix)
        position, orientation = cube.pose.position, cube.pose.orientation
        boxes.centers[k] = (position.x, position.y, position.z)
        if cube.pose.HasField("orientation"):
            boxes.quaternions_xyzw[k] = (orientation.x, orientation.y, orientation.z,
                                         orientation.w)
        boxes.half_sizes[k] = (cube.size.x / 2, cube.size.y / 2, cube.size.z / 2)
        rgba = (cube.color.r, cube.color.g, cube.color.b, max(cube.color.a, 0.35))
        boxes.colors[k] = np.clip(np.rint(np.array(rgba) * 255), 0, 255)
        metadata = {pair.key: pair.value for pair in entity.metadata}
        count_text = metadata.get("node_count", "")
        boxes.node_counts[k] = int(count_text) if count_text.isdigit() and len(count_text) < 19 \
            else 0
        boxes.labels.append(entity.texts[0].text if entity.texts else entity.id)
        boxes.roles.append(metadata.get("role", OBJECT_ROLE))
    values = np.concatenate([boxes.centers.ravel(), boxes.half_sizes.ravel(),
                             boxes.quaternions_xyzw.ravel()])
    if not np.isfinite(values).all():
        raise MessageError("objects update has non-finite box poses or sizes")
    return boxes
