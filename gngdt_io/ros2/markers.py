"""visualization_msgs/MarkerArray of what gngdt learns: the graph (a LINE_LIST per topology) and
the objects (a CUBE and a TEXT_VIEW_FACING label per object, DELETE for objects gone), as CDR
through rosbags.

Cost: rosbags serialises a marker's ``points`` and ``colors`` element by element in Python
(~1.3 µs each), so a graph of 3 x 3,000 edges takes ~50-140 ms on this machine; `gngdt ros2`
throttles the graph topic (``--graph-rate``, 2 Hz by default).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gngdt.io.ros2.messages import MARKER_ARRAY, header, msg_type, serialize

__all__ = ["OBJECTS_NS", "OBJECT_LABELS_NS", "ObjectMarker", "encode_graph_markers",
           "encode_object_markers"]

#: visualization_msgs/Marker types and actions (Marker.msg constants)
CUBE, LINE_LIST, TEXT_VIEW_FACING = 1, 5, 9
ADD, DELETE = 0, 2
#: marker namespaces of the objects' cubes and of their labels
OBJECTS_NS = "objects"
OBJECT_LABELS_NS = "object_labels"


def _rgba(r: float, g: float, b: float, a: float = 1.0) -> Any:
    return msg_type("std_msgs/msg/ColorRGBA")(r=float(r), g=float(g), b=float(b), a=float(a))


def _pose(position: Iterable[float] = (0.0, 0.0, 0.0),
          quaternion_xyzw: Iterable[float] = (0.0, 0.0, 0.0, 1.0)) -> Any:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion_xyzw)
    return msg_type("geometry_msgs/msg/Pose")(
        position=msg_type("geometry_msgs/msg/Point")(x=x, y=y, z=z),
        orientation=msg_type("geometry_msgs/msg/Quaternion")(x=qx, y=qy, z=qz, w=qw))


def _vector(x: float, y: float, z: float) -> Any:
    return msg_type("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def _marker(stamp: Any, ns: str, marker_id: int, **fields: Any) -> Any:
    """A visualization_msgs/Marker, every field not given at its neutral value (identity pose,
    white, shown until replaced or deleted)."""
    empty = np.zeros(0, np.uint8)
    values = dict(
        type=CUBE, action=ADD, pose=_pose(), scale=_vector(1.0, 1.0, 1.0), color=_rgba(1, 1, 1),
        lifetime=msg_type("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=False, points=[], colors=[], texture_resource="",
        texture=msg_type("sensor_msgs/msg/CompressedImage")(header=header(0, ""), format="",
                                                              data=empty),
        uv_coordinates=[], text="", mesh_resource="",
        mesh_file=msg_type("visualization_msgs/msg/MeshFile")(filename="", data=empty),
        mesh_use_embedded_materials=False)
    values.update(fields)
    return msg_type("visualization_msgs/msg/Marker")(header=stamp, ns=ns, id=int(marker_id),
                                                     **values)


def encode_graph_markers(
    positions: np.ndarray,
    layers: Mapping[str, tuple[np.ndarray, np.ndarray]],
    *,
    stamp_ns: int,
    frame_id: str,
    line_width: float = 0.003,
) -> bytes:
    """One LINE_LIST marker per layer (``ns`` = its name, id 0) in a MarkerArray.

    positions: (N, 3) float32 metres. layers: name -> (pairs (E, 2) node indices, edge colours
    (E, 3) uint8); both vertices of an edge take its colour. A layer without edges is sent as a
    DELETE of its marker (RViz would otherwise keep the last lines). ``ValueError`` for an
    index outside the nodes.
    """
    positions = np.asarray(positions, dtype=np.float64)
    point, color = msg_type("geometry_msgs/msg/Point"), msg_type("std_msgs/msg/ColorRGBA")
    stamp = header(stamp_ns, frame_id)
    markers = []
    for name, (pairs, edge_rgb) in layers.items():
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if pairs.size and (pairs.min() < 0 or pairs.max() >= len(positions)):
            raise ValueError(f"edges {name!r}: node index outside 0..{len(positions) - 1}")
        if len(edge_rgb) != len(pairs):
            raise ValueError(f"edges {name!r}: {len(pairs)} edges, {len(edge_rgb)} colours")
        if not len(pairs):
            markers.append(_marker(stamp, name, 0, type=LINE_LIST, action=DELETE))
            continue
        vertex_rgb = (np.repeat(np.asarray(edge_rgb, np.float64), 2, axis=0) / 255.0).tolist()
        markers.append(_marker(
            stamp, name, 0, type=LINE_LIST, scale=_vector(line_width, 0.0, 0.0),
            points=[point(x=x, y=y, z=z) for x, y, z in positions[pairs.reshape(-1)].tolist()],
            colors=[color(r=r, g=g, b=b, a=1.0) for r, g, b in vertex_rgb]))
    return serialize(msg_type(MARKER_ARRAY)(markers=markers), MARKER_ARRAY)


@dataclass(frozen=True)
class ObjectMarker:
    """One object to draw. center: (3,) metres; size: (3,) full extents, metres;
    quaternion_xyzw: (4,) the box's orientation; rgba: (4,) in [0, 1]; label: its text."""

    id: int
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    quaternion_xyzw: tuple[float, float, float, float]
    rgba: tuple[float, float, float, float]
    label: str


def encode_object_markers(
    objects: Iterable[ObjectMarker],
    *,
    stamp_ns: int,
    frame_id: str,
    gone_ids: Iterable[int] = (),
    text_height: float = 0.05,
) -> bytes:
    """A MarkerArray: per object a CUBE (ns ``objects``) and a TEXT_VIEW_FACING label at its
    centre (ns ``object_labels``), both with marker id = object id; then a DELETE of both for
    every id in ``gone_ids``."""
    stamp = header(stamp_ns, frame_id)
    markers = []
    for item in objects:
        pose = _pose(item.center, item.quaternion_xyzw)
        markers.append(_marker(stamp, OBJECTS_NS, item.id, type=CUBE, pose=pose,
                               scale=_vector(*item.size), color=_rgba(*item.rgba)))
        markers.append(_marker(stamp, OBJECT_LABELS_NS, item.id, type=TEXT_VIEW_FACING,
                               pose=pose, scale=_vector(0.0, 0.0, text_height),
                               color=_rgba(1.0, 1.0, 1.0), text=item.label))
    for gone in gone_ids:
        markers.append(_marker(stamp, OBJECTS_NS, gone, action=DELETE))
        markers.append(_marker(stamp, OBJECT_LABELS_NS, gone, type=TEXT_VIEW_FACING,
                               action=DELETE))
    return serialize(msg_type(MARKER_ARRAY)(markers=markers), MARKER_ARRAY)
