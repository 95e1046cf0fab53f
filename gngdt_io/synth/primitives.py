"""Solid primitives of the synthetic scenes, each answering one question for a batch of rays:
"where do you first hit each ray, and on which face?" -- all the renderer in
:mod:`gngdt.io.synth.render` needs.

World frame: x right, y forward (away from the default camera), z up, metres. Rays are
``origin + t * directions`` with ``origin (3,) float64`` and ``directions (N, 3) float64`` (not
necessarily unit length); hit distances ``t`` are in units of the direction vectors, ``inf``
where a ray misses.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace

import numpy as np

__all__ = [
    "ConvexPolyhedron",
    "Cylinder",
    "Primitive",
    "RayHit",
    "Rectangle",
    "Sphere",
    "box",
    "triangular_prism",
]

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
