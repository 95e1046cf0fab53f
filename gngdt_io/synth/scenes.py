"""Synthetic scenes for the virtual Kinect: solid primitives, their layouts and camera paths.

World frame: x right, y forward (away from the default camera), z up, metres. Every primitive
answers one question for a batch of rays, "where do you first hit each ray, and on which face?",
which is all the renderer in :mod:`gngdt_io.synth.render` needs.

Rays are ``origin + t * directions`` with ``origin (3,) float64`` and ``directions (N, 3)
float64`` (not necessarily unit length); hit distances ``t`` are in units of the direction
vectors, ``inf`` where a ray misses.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

#: hits closer than this (in ray units) are ignored, so a camera never sees itself
_MIN_HIT = 1e-6

#: what :meth:`Primitive.intersect` returns: ``t (N,) float64`` (inf = miss), ``face (N,) int8``
RayHit = tuple[np.ndarray, np.ndarray]


def _dot(vectors: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``(N,)`` dot products of ``vectors (N, 3)`` with ``direction (3,)``.

    einsum rather than ``@``: a threaded BLAS call on an inner dimension of 3 costs far more
    than it saves when the 2 cores are busy with other services.
    """
    return np.einsum("ij,j->i", vectors, direction)


@dataclass(frozen=True)
class Primitive(ABC):
    """A solid, uniformly coloured object made of named faces."""

    name: str
    #: albedo, RGB 0-255
    color: tuple[int, int, int]

    @property
    @abstractmethod
    def face_names(self) -> tuple[str, ...]:
        """One name per face index returned by :meth:`intersect`."""

    @abstractmethod
    def intersect(self, origin: np.ndarray, directions: np.ndarray) -> RayHit:
        """Nearest hit of each ray: ``t (N,) float64`` (inf = miss) and ``face (N,) int8``."""

    @abstractmethod
    def normals(self, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Outward unit normals ``(N, 3) float64`` at ``points (N, 3)`` on ``faces (N,)``."""

    @abstractmethod
    def corners(self) -> np.ndarray:
        """``(8, 3) float64`` corners of a box enclosing the primitive (for culling)."""

    @abstractmethod
    def translated(self, offset: np.ndarray) -> Primitive:
        """The same primitive moved by ``offset (3,)`` metres."""


def _shifted(point: tuple[float, ...], offset: np.ndarray) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in np.asarray(point, dtype=np.float64) + offset)
    return x, y, z


def _axis_box_corners(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    return np.array(
        [
            [x, y, z]
            for x in (low[0], high[0])
            for y in (low[1], high[1])
            for z in (low[2], high[2])
        ],
        dtype=np.float64,
    )


@dataclass(frozen=True)
class Rectangle(Primitive):
    """A flat rectangle (a bounded plane), seen from both sides.

    ``center (3,)``, unit ``normal (3,)``, in-plane unit ``axis_u (3,)``; ``half_size`` is
    (half extent along ``axis_u``, half extent along ``normal x axis_u``), metres.
    """

    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    axis_u: tuple[float, float, float] = (1.0, 0.0, 0.0)
    half_size: tuple[float, float] = (1.0, 1.0)

    @property
    def face_names(self) -> tuple[str, ...]:
        return ("surface",)

    def _frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        normal = np.asarray(self.normal, dtype=np.float64)
        axis_u = np.asarray(self.axis_u, dtype=np.float64)
        return np.asarray(self.center, dtype=np.float64), normal, axis_u, np.cross(normal, axis_u)

    def intersect(self, origin: np.ndarray, directions: np.ndarray) -> RayHit:
        center, normal, axis_u, axis_v = self._frame()
        facing = _dot(directions, normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((center - origin) @ normal) / facing
        offset = origin - center
        along_u = offset @ axis_u + t * _dot(directions, axis_u)
        along_v = offset @ axis_v + t * _dot(directions, axis_v)
        hit = (
            (t > _MIN_HIT)
            & (np.abs(along_u) <= self.half_size[0])
            & (np.abs(along_v) <= self.half_size[1])
        )
        return np.where(hit, t, np.inf), np.zeros(len(t), dtype=np.int8)

    def normals(self, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.normal, dtype=np.float64), points.shape).copy()

    def corners(self) -> np.ndarray:
        center, _, axis_u, axis_v = self._frame()
        hu, hv = self.half_size
        rim = [center + su * hu * axis_u + sv * hv * axis_v for su in (-1, 1) for sv in (-1, 1)]
        return np.array(rim + rim, dtype=np.float64)

    def translated(self, offset: np.ndarray) -> Rectangle:
        return replace(self, center=_shifted(self.center, offset))


@dataclass(frozen=True)
class ConvexPolyhedron(Primitive):
    """A convex solid: the points x with ``plane_normals[i] . x <= plane_offsets[i]`` for all i.

    Built by :func:`box` and :func:`triangular_prism`; one face per plane.
    """

    plane_normals: tuple[tuple[float, float, float], ...] = ()
    plane_offsets: tuple[float, ...] = ()
    plane_names: tuple[str, ...] = ()
    vertices: tuple[tuple[float, float, float], ...] = ()

    @property
    def face_names(self) -> tuple[str, ...]:
        return self.plane_names

    def intersect(self, origin: np.ndarray, directions: np.ndarray) -> RayHit:
        plane_normals = np.asarray(self.plane_normals, dtype=np.float64)  # (P, 3)
        room = np.asarray(self.plane_offsets) - plane_normals @ origin  # (P,) >= 0 inside
        # (N, P), < 0 where the ray enters the half-space
        approach = np.einsum("ij,pj->ip", directions, plane_normals)
        with np.errstate(divide="ignore", invalid="ignore"):
            crossing = room / approach
        entering = approach < 0
        exiting = approach > 0
        # A ray parallel to a plane and outside it never enters the solid.
        parallel_outside = np.any((approach == 0) & (room < 0), axis=1)
        t_enter_each = np.where(entering, crossing, -np.inf)
        face = np.argmax(t_enter_each, axis=1)
        t_enter = np.take_along_axis(t_enter_each, face[:, None], axis=1)[:, 0]
        t_exit = np.min(np.where(exiting, crossing, np.inf), axis=1)
        hit = (t_enter <= t_exit) & (t_enter > _MIN_HIT) & ~parallel_outside
        return np.where(hit, t_enter, np.inf), face.astype(np.int8)

    def normals(self, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
        return np.asarray(self.plane_normals, dtype=np.float64)[faces]

    def corners(self) -> np.ndarray:
        vertices = np.asarray(self.vertices, dtype=np.float64)
        return _axis_box_corners(vertices.min(axis=0), vertices.max(axis=0))

    def translated(self, offset: np.ndarray) -> ConvexPolyhedron:
        normals = np.asarray(self.plane_normals, dtype=np.float64)
        offsets = np.asarray(self.plane_offsets, dtype=np.float64) + normals @ offset
        return replace(
            self,
            plane_offsets=tuple(float(d) for d in offsets),
            vertices=tuple(_shifted(vertex, offset) for vertex in self.vertices),
        )


def _yaw_matrix(yaw_deg: float) -> np.ndarray:
    """Rotation about world z (counter-clockwise seen from above)."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _polyhedron(
    name: str,
    color: tuple[int, int, int],
    local_planes: list[tuple[str, tuple[float, float, float], float]],
    local_vertices: np.ndarray,
    origin: tuple[float, float, float],
    yaw_deg: float,
) -> ConvexPolyhedron:
    """Place a solid given in local coordinates (planes ``n . x <= d``) at ``origin``, yawed."""
    rotation = _yaw_matrix(yaw_deg)
    translation = np.asarray(origin, dtype=np.float64)
    normals, offsets, names = [], [], []
    for face_name, local_normal, local_offset in local_planes:
        normal = rotation @ np.asarray(local_normal, dtype=np.float64)
        normal /= np.linalg.norm(normal)
        scale = np.linalg.norm(local_normal)
        normals.append(tuple(normal))
        offsets.append(local_offset / scale + float(normal @ translation))
        names.append(face_name)
    vertices = local_vertices @ rotation.T + translation
    return ConvexPolyhedron(
        name=name,
        color=color,
        plane_normals=tuple(normals),
        plane_offsets=tuple(offsets),
        plane_names=tuple(names),
        vertices=tuple(map(tuple, vertices)),
    )


def box(
    name: str,
    color: tuple[int, int, int],
    center: tuple[float, float, float],
    size: tuple[float, float, float],
    yaw_deg: float = 0.0,
) -> ConvexPolyhedron:
    """A box of ``size`` (x, y, z extents, metres) centred at ``center``, turned by ``yaw_deg``.

    Faces: ``left`` (-x), ``right`` (+x), ``front`` (-y, towards the default camera), ``back``,
    ``bottom``, ``top`` -- named in the box's own (unturned) axes.
    """
    hx, hy, hz = (s / 2 for s in size)
    planes = [
        ("left", (-1.0, 0.0, 0.0), hx),
        ("right", (1.0, 0.0, 0.0), hx),
        ("front", (0.0, -1.0, 0.0), hy),
        ("back", (0.0, 1.0, 0.0), hy),
        ("bottom", (0.0, 0.0, -1.0), hz),
        ("top", (0.0, 0.0, 1.0), hz),
    ]
    vertices = _axis_box_corners(np.array([-hx, -hy, -hz]), np.array([hx, hy, hz]))
    return _polyhedron(name, color, planes, vertices, center, yaw_deg)


def triangular_prism(
    name: str,
    color: tuple[int, int, int],
    base_center: tuple[float, float, float],
    length: float,
    width: float,
    height: float,
    yaw_deg: float = 0.0,
) -> ConvexPolyhedron:
    """A roof-shaped prism resting on its rectangular base, ridge along its local x axis.

    ``base_center`` is the centre of the base (metres); the cross-section is an isosceles
    triangle ``width`` wide and ``height`` high. Faces: ``left``/``right`` (the triangular
    ends), ``bottom``, ``front_slope`` (-y side), ``back_slope``.
    """
    hx, hy = length / 2, width / 2
    # Slope planes pass through the ridge (0, 0, height) and a base edge (0, +-hy, 0).
    planes = [
        ("left", (-1.0, 0.0, 0.0), hx),
        ("right", (1.0, 0.0, 0.0), hx),
        ("bottom", (0.0, 0.0, -1.0), 0.0),
        ("front_slope", (0.0, -height, hy), hy * height),
        ("back_slope", (0.0, height, hy), hy * height),
    ]
    vertices = np.array(
        [[x, y, 0.0] for x in (-hx, hx) for y in (-hy, hy)] + [[x, 0.0, height] for x in (-hx, hx)]
    )
    return _polyhedron(name, color, planes, vertices, base_center, yaw_deg)


@dataclass(frozen=True)
class Cylinder(Primitive):
    """A closed solid cylinder: ``base_center (3,)``, unit ``axis (3,)``, radius, height; metres."""

    base_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    radius: float = 0.1
    height: float = 0.2

    @property
    def face_names(self) -> tuple[str, ...]:
        return ("side", "bottom_cap", "top_cap")

    def intersect(self, origin: np.ndarray, directions: np.ndarray) -> RayHit:
        axis = np.asarray(self.axis, dtype=np.float64)
        offset = origin - np.asarray(self.base_center, dtype=np.float64)
        along_dir = _dot(directions, axis)  # (N,)
        along_origin = float(offset @ axis)
        # Side: |radial part of (offset + t d)| = radius.
        radial_dir = directions - along_dir[:, None] * axis
        radial_origin = offset - along_origin * axis
        a = np.einsum("ij,ij->i", radial_dir, radial_dir)
        b = 2.0 * _dot(radial_dir, radial_origin)
        c = float(radial_origin @ radial_origin) - self.radius**2
        discriminant = b * b - 4.0 * a * c
        with np.errstate(divide="ignore", invalid="ignore"):
            t_side = (-b - np.sqrt(discriminant)) / (2.0 * a)
        height_at_side = along_origin + t_side * along_dir
        side_ok = (discriminant >= 0) & (height_at_side >= 0) & (height_at_side <= self.height)
        candidates = [np.where(side_ok, t_side, np.inf)]
        for cap_height in (0.0, self.height):
            with np.errstate(divide="ignore", invalid="ignore"):
                t_cap = (cap_height - along_origin) / along_dir
                radial = radial_origin + t_cap[:, None] * radial_dir
                inside = np.einsum("ij,ij->i", radial, radial) <= self.radius**2
            candidates.append(np.where(inside, t_cap, np.inf))
        t_all = np.stack(candidates, axis=1)
        t_all[~(t_all > _MIN_HIT)] = np.inf
        face = np.argmin(t_all, axis=1)
        return np.take_along_axis(t_all, face[:, None], axis=1)[:, 0], face.astype(np.int8)

    def normals(self, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
        axis = np.asarray(self.axis, dtype=np.float64)
        offset = points - np.asarray(self.base_center, dtype=np.float64)
        radial = offset - _dot(offset, axis)[:, None] * axis
        radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
        cap_sign = np.where(faces == 1, -1.0, 1.0)[:, None]
        return np.where((faces == 0)[:, None], radial, cap_sign * axis)

    def corners(self) -> np.ndarray:
        axis = np.asarray(self.axis, dtype=np.float64)
        base = np.asarray(self.base_center, dtype=np.float64)
        ends = np.array([base, base + self.height * axis])
        return _axis_box_corners(ends.min(axis=0) - self.radius, ends.max(axis=0) + self.radius)

    def translated(self, offset: np.ndarray) -> Cylinder:
        return replace(self, base_center=_shifted(self.base_center, offset))


@dataclass(frozen=True)
class Sphere(Primitive):
    """A solid sphere: ``center (3,)`` and ``radius``, metres."""

    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.1

    @property
    def face_names(self) -> tuple[str, ...]:
        return ("surface",)

    def intersect(self, origin: np.ndarray, directions: np.ndarray) -> RayHit:
        offset = origin - np.asarray(self.center, dtype=np.float64)
        a = np.einsum("ij,ij->i", directions, directions)
        b = 2.0 * _dot(directions, offset)
        c = float(offset @ offset) - self.radius**2
        discriminant = b * b - 4.0 * a * c
        with np.errstate(invalid="ignore"):
            t = (-b - np.sqrt(discriminant)) / (2.0 * a)
        hit = (discriminant >= 0) & (t > _MIN_HIT)
        return np.where(hit, t, np.inf), np.zeros(len(t), dtype=np.int8)

    def normals(self, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
        return (points - np.asarray(self.center, dtype=np.float64)) / self.radius

    def corners(self) -> np.ndarray:
        center = np.asarray(self.center, dtype=np.float64)
        return _axis_box_corners(center - self.radius, center + self.radius)

    def translated(self, offset: np.ndarray) -> Sphere:
        return replace(self, center=_shifted(self.center, offset))


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``(4, 4) float64`` world_from_camera of a camera at ``position`` looking at ``target``,
    level (its x axis horizontal); camera axes x right, y down, z forward."""
    forward = target - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([right, down, forward])
    pose[:3, 3] = position
    return pose


@dataclass(frozen=True)
class Orbit:
    """A slow camera arc around ``target``, always looking at it.

    At time ``s`` seconds the camera sits ``distance + distance_swing * sin(w s)`` metres from the
    target at azimuth ``azimuth_deg + azimuth_swing_deg * sin(w s)`` (0 = on the -y side) and
    elevation ``elevation_deg + elevation_swing_deg * sin(w s / 2)``, with ``w = 2 pi / period_s``.
    """

    target: tuple[float, float, float]
    distance: float
    elevation_deg: float
    azimuth_swing_deg: float
    period_s: float
    azimuth_deg: float = 0.0
    elevation_swing_deg: float = 0.0
    distance_swing: float = 0.0

    def pose(self, time_s: float) -> np.ndarray:
        """``(4, 4) float64`` world_from_camera (camera axes: x right, y down, z forward)."""
        phase = 2.0 * math.pi * time_s / self.period_s
        azimuth = math.radians(self.azimuth_deg + self.azimuth_swing_deg * math.sin(phase))
        elevation = math.radians(
            self.elevation_deg + self.elevation_swing_deg * math.sin(phase / 2.0)
        )
        distance = self.distance + self.distance_swing * math.sin(phase)
        target = np.asarray(self.target, dtype=np.float64)
        position = target + distance * np.array(
            [
                math.cos(elevation) * math.sin(azimuth),
                -math.cos(elevation) * math.cos(azimuth),
                math.sin(elevation),
            ]
        )
        return look_at(position, target)


@dataclass(frozen=True)
class Walk:
    """A camera that travels from ``start`` to ``end`` and back (positions, metres), looking at a
    point that travels from ``look_start`` to ``look_end`` with it.

    One way takes ``period_s / 2`` seconds; the speed follows a cosine, so the camera eases out
    of and into both ends: at time ``s`` it is the fraction ``(1 - cos(2 pi s / period_s)) / 2``
    of the way.
    """

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    look_start: tuple[float, float, float]
    look_end: tuple[float, float, float]
    period_s: float

    def pose(self, time_s: float) -> np.ndarray:
        """``(4, 4) float64`` world_from_camera (camera axes: x right, y down, z forward)."""
        fraction = 0.5 - 0.5 * math.cos(2.0 * math.pi * time_s / self.period_s)

        def along(first: tuple[float, ...], last: tuple[float, ...]) -> np.ndarray:
            a, b = np.asarray(first, dtype=np.float64), np.asarray(last, dtype=np.float64)
            return a + fraction * (b - a)

        return look_at(along(self.start, self.end), along(self.look_start, self.look_end))


#: how the camera moves: anything with ``pose(time_s) -> (4, 4)`` and ``period_s``
CameraPath = Orbit | Walk


@dataclass(frozen=True)
class Motion:
    """A change of one primitive during a recording (the scene is static without any).

    From ``start_s`` to ``end_s`` (seconds from the first frame) the primitive ``primitive``
    slides by ``offset (3,)`` metres at constant speed and then stays; with ``vanish`` it is gone
    from ``start_s`` on (``offset`` and ``end_s`` unused). Segment ids never change: a vanished
    primitive's ids are simply no longer seen.
    """

    primitive: str
    start_s: float
    end_s: float | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    vanish: bool = False

    def displacement(self, time_s: float) -> np.ndarray:
        """``(3,)`` metres the primitive has moved by ``time_s``."""
        if time_s <= self.start_s:
            return np.zeros(3)
        span = (self.end_s if self.end_s is not None else self.start_s) - self.start_s
        fraction = 1.0 if span <= 0 else min(1.0, (time_s - self.start_s) / span)
        return fraction * np.asarray(self.offset, dtype=np.float64)

    def describe(self, fps: float) -> dict[str, object]:
        """The motion as recording metadata: frames rather than seconds."""
        end_s = self.end_s if self.end_s is not None else self.start_s
        return {
            "primitive": self.primitive,
            "kind": "vanish" if self.vanish else "move",
            "start_frame": math.ceil(self.start_s * fps - 1e-9),
            "end_frame": math.ceil(end_s * fps - 1e-9),
            "offset_m": list(self.offset),
        }


@dataclass(frozen=True)
class Scene:
    """Primitives, the camera path, and what the scene should look like to a clustering."""

    name: str
    description: str
    primitives: tuple[Primitive, ...]
    #: the camera's path (an Orbit or a Walk)
    orbit: CameraPath
    #: RGB 0-255 where a ray hits nothing
    background: tuple[int, int, int]
    #: expected cluster counts per GNG-DT topology, see ``SCENE_GROUND_TRUTH`` in synth.py
    ground_truth: dict[str, object]
    #: primitives that move or vanish during the recording
    motions: tuple[Motion, ...] = ()
    #: names of primitives that are not there (rays pass through them); set by :meth:`at`
    absent: frozenset[str] = frozenset()

    def primitive(self, name: str) -> Primitive:
        """The primitive called ``name``; ``KeyError`` if there is none."""
        for candidate in self.primitives:
            if candidate.name == name:
                return candidate
        raise KeyError(f"scene {self.name!r} has no primitive {name!r}")

    def at(self, time_s: float) -> Scene:
        """The scene as it is ``time_s`` seconds after the first frame (itself when static).

        Primitives keep their places in ``primitives`` (so segment ids stay the same); a moved
        one is replaced by its translated copy, a vanished one is named in ``absent``.
        """
        if not self.motions:
            return self
        primitives = list(self.primitives)
        absent = set(self.absent)
        for motion in self.motions:
            index = next(
                i for i, candidate in enumerate(primitives) if candidate.name == motion.primitive
            )
            if motion.vanish:
                if time_s >= motion.start_s:
                    absent.add(motion.primitive)
            else:
                primitives[index] = primitives[index].translated(motion.displacement(time_s))
        return replace(self, primitives=tuple(primitives), absent=frozenset(absent))


BROWN = (140, 90, 50)
RED = (200, 35, 35)


def data2_scene() -> Scene:
    """The paper's Data2: a half red / half brown square prism and a red half cylinder on a
    brown surface (section 3.1, Figures 7b and 11).

    The square prism (0.2 x 0.2 m cross-section, 0.7 m long) lies along x; its lower half is
    brown like the surface, its upper half red. The half cylinder is a 0.1 m radius cylinder
    whose axis lies in the surface, so only its upper half shows. The camera stays within
    x = +-0.35 m of the centre, so the objects' ends and back faces are never seen.

    Seen regions, giving the paper's Figure 11 counts:
    colour: {surface + prism lower half} brown, {prism top + upper front} red, cylinder -> 3;
    normal: surface, prism top, prism front, curved cylinder -> 4;
    colour+normal: surface, prism top, prism front red, prism front brown, cylinder -> 5;
    position: everything touches the surface -> 1.
    """
    length = 0.7
    primitives: tuple[Primitive, ...] = (
        Rectangle("surface", BROWN, center=(0.0, 0.0, 0.0), half_size=(0.6, 0.5)),
        box("prism_lower", BROWN, center=(0.0, 0.15, 0.05), size=(length, 0.2, 0.1)),
        box("prism_upper", RED, center=(0.0, 0.15, 0.15), size=(length, 0.2, 0.1)),
        Cylinder(
            "half_cylinder",
            RED,
            base_center=(-length / 2, -0.2, 0.0),
            axis=(1.0, 0.0, 0.0),
            radius=0.1,
            height=length,
        ),
    )
    return Scene(
        name="data2",
        description="the paper's Data2: half red/half brown square prism and red half cylinder "
        "on a brown surface",
        primitives=primitives,
        orbit=Orbit(
            target=(0.0, 0.0, 0.08),
            distance=1.2,
            elevation_deg=48.0,
            azimuth_swing_deg=10.0,
            elevation_swing_deg=6.0,
            distance_swing=0.1,
            period_s=8.0,
        ),
        background=(0, 0, 0),
        ground_truth={"pos": 1, "col": 3, "nor": 4, "col+nor": 5},
    )


TABLE_TOP_HEIGHT = 0.74


def _tabletop_primitives() -> tuple[Primitive, ...]:
    """The tabletop scene's floor, wall, table and four objects."""
    wood = (150, 105, 60)
    top = TABLE_TOP_HEIGHT
    # Two full-depth side panels rather than four legs: the back legs of a four-legged table
    # peek out under the top as small separate regions, which would blur the ground truth.
    sides = tuple(
        box(
            f"table_side_{side}",
            wood,
            center=(sign * 0.58, 0.3, (top - 0.04) / 2),
            size=(0.04, 0.8, top - 0.04),
        )
        for side, sign in (("left", -1.0), ("right", 1.0))
    )
    return (
        Rectangle("floor", (105, 105, 110), center=(0.0, 0.0, 0.0), half_size=(4.0, 4.0)),
        Rectangle(
            "wall",
            (225, 215, 190),
            center=(0.0, 1.5, 1.0),
            normal=(0.0, -1.0, 0.0),
            axis_u=(1.0, 0.0, 0.0),
            half_size=(4.0, 1.0),
        ),
        box("table_top", wood, center=(0.0, 0.3, top - 0.02), size=(1.2, 0.8, 0.04)),
        *sides,
        box(
            "red_box",
            (210, 40, 40),
            center=(-0.35, 0.25, top + 0.09),
            size=(0.18, 0.18, 0.18),
            yaw_deg=25.0,
        ),
        Cylinder(
            "green_cylinder",
            (40, 170, 60),
            base_center=(-0.05, 0.45, top),
            radius=0.06,
            height=0.22,
        ),
        Sphere("blue_sphere", (40, 80, 200), center=(0.15, 0.15, top + 0.08), radius=0.08),
        triangular_prism(
            "yellow_prism",
            (230, 200, 40),
            base_center=(0.4, 0.4, top),
            length=0.22,
            width=0.14,
            height=0.12,
            yaw_deg=-20.0,
        ),
    )


#: the tabletop scene's camera arc: 1.9-2.1 m from the table, 30-40 degrees above, +-20 degrees
TABLETOP_ORBIT = Orbit(
    target=(0.0, 0.3, 0.45),
    distance=2.0,
    elevation_deg=35.0,
    azimuth_swing_deg=20.0,
    elevation_swing_deg=5.0,
    distance_swing=0.1,
    period_s=12.0,
)


def tabletop_scene() -> Scene:
    """A table with four coloured objects, standing on a floor in front of a wall.

    Colour regions: floor, wall, table (top and side panels), red box, green cylinder, blue sphere,
    yellow prism -> 7. Dominant plane orientations: up (floor, table top, object tops) and the
    wall's normal, facing the camera.
    """
    return Scene(
        name="tabletop",
        description="a table with a red box, green cylinder, blue sphere and yellow prism, "
        "on a floor in front of a wall",
        primitives=_tabletop_primitives(),
        orbit=TABLETOP_ORBIT,
        background=(0, 0, 0),
        ground_truth={
            "col": 7,
            "plane_normals": {"up": (0.0, 0.0, 1.0), "wall": (0.0, -1.0, 0.0)},
        },
    )


#: when the tabletop's objects change in the moving scenes, seconds after the first frame
CHANGE_AT_S = 2.0


def tabletop_vanish_scene() -> Scene:
    """The tabletop, camera orbiting as in ``tabletop``; the red box vanishes 2 s in (frame 60
    at 30 fps, when a learner at 10,000 steps a frame has just reached 1,000 nodes), leaving the
    table top under it to be seen."""
    return Scene(
        name="tabletop_vanish",
        description="tabletop with the camera orbiting; the red box vanishes 2 s in",
        primitives=_tabletop_primitives(),
        orbit=TABLETOP_ORBIT,
        background=(0, 0, 0),
        ground_truth={},
        motions=(Motion("red_box", start_s=CHANGE_AT_S, vanish=True),),
    )


def tabletop_move_scene() -> Scene:
    """The tabletop, camera orbiting as in ``tabletop``; from 2 s to 3.5 s in the blue sphere
    slides 0.3 m away from the camera (+y, 0.2 m/s) across the table, then rests."""
    return Scene(
        name="tabletop_move",
        description="tabletop with the camera orbiting; the blue sphere slides 0.3 m across "
        "the table from 2 s to 3.5 s",
        primitives=_tabletop_primitives(),
        orbit=TABLETOP_ORBIT,
        background=(0, 0, 0),
        ground_truth={},
        motions=(
            Motion("blue_sphere", start_s=CHANGE_AT_S, end_s=CHANGE_AT_S + 1.5,
                   offset=(0.0, 0.3, 0.0)),
        ),
    )


def tabletop_walk_scene() -> Scene:
    """The tabletop plus a crate on the floor to its left and a bin to its right; the camera
    walks 3.2 m sideways past them and back (8 s period: 4 s one way), so the crate leaves the
    view on the way out and comes back into it on the way back. Nothing in the scene moves."""
    primitives = (
        *_tabletop_primitives(),
        box("crate", (70, 140, 160), center=(-1.7, 0.5, 0.25), size=(0.5, 0.5, 0.5), yaw_deg=10),
        Cylinder("bin", (150, 60, 150), base_center=(1.7, 0.4, 0.0), radius=0.25, height=0.6),
    )
    return Scene(
        name="tabletop_walk",
        description="a camera walking 3.2 m past the tabletop, a crate and a bin, and back "
        "(static scene)",
        primitives=primitives,
        orbit=Walk(
            start=(-1.6, -1.3, 1.5),
            end=(1.6, -1.3, 1.5),
            look_start=(-1.4, 0.6, 0.4),
            look_end=(1.4, 0.6, 0.4),
            period_s=8.0,
        ),
        background=(0, 0, 0),
        ground_truth={},
    )


#: scene name -> builder. Builders are cheap; scenes are immutable.
SCENE_BUILDERS: dict[str, Callable[[], Scene]] = {
    "data2": data2_scene,
    "tabletop": tabletop_scene,
    "tabletop_walk": tabletop_walk_scene,
    "tabletop_vanish": tabletop_vanish_scene,
    "tabletop_move": tabletop_move_scene,
}


def build_scene(name: str) -> Scene:
    """The scene called ``name``; ``ValueError`` naming the known scenes otherwise."""
    try:
        return SCENE_BUILDERS[name]()
    except KeyError:
        raise ValueError(
            f"scene: unknown scene {name!r}; known scenes: {', '.join(sorted(SCENE_BUILDERS))}"
        ) from None
