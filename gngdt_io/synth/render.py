"""The virtual Kinect: ray-cast RGB-D frames of synthetic scenes, with Kinect-like depth.

Every pixel's ray is cast against every primitive of a scene (:mod:`gngdt.io.synth.scenes`)
with numpy, the nearest hit wins. The depth sensor model follows Khoshelham & Elberink (2012):
Gaussian noise whose sigma grows with the square of the depth (1.5 mm at 1 m, 6 mm at 2 m),
quantisation to millimetres, and holes where the surface is seen at a grazing angle or next to
a depth discontinuity, with the depth steps of a disparity-based sensor. Colours are flat
material colours (optionally with Gaussian noise), so colour regions stay separable by an RGB
distance of ~10.

Same scene, size, seed and frame index -> the same frame, bit for bit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from gngdt.core.sensor.geometry import apply_pose
from gngdt.io.frame import CameraIntrinsics, CameraPose, Frame
from gngdt.io.synth.scenes import SCENE_BUILDERS, Scene, build_scene

#: scene name -> one-line description
SCENES: dict[str, str] = {name: builder().description for name, builder in SCENE_BUILDERS.items()}

#: scene name -> what a clustering of the whole scene should find, per GNG-DT topology
#: (``pos``, ``col``, ``nor``, ``col+nor``: expected number of clusters), plus for ``tabletop``
#: the dominant plane orientations (world frame, z up). See the scene builders for the regions.
SCENE_GROUND_TRUTH: dict[str, dict[str, object]] = {
    name: builder().ground_truth for name, builder in SCENE_BUILDERS.items()
}

#: Kinect v1 focal length at 640x480, pixels
KINECT_FOCAL_PX = 525.0
#: depth noise sigma at 1 m, metres; grows with depth squared
DEPTH_NOISE_AT_1M = 0.0015
#: step between the depths a Kinect v1 can report at 1 m, metres: depth comes from disparity
#: measured in 1/8 pixel, so the steps grow with depth squared (2.9 mm at 1 m, 11 mm at 2 m)
DEPTH_STEP_AT_1M = 0.00287
#: surfaces seen at more than this angle from their normal give no depth
MAX_INCIDENCE_DEG = 75.0
#: a pixel whose 4-neighbour is nearer or farther by more than this fraction of its depth is a hole
DEPTH_EDGE_JUMP = 0.03
#: Kinect range, metres: farther or nearer surfaces give no depth
DEPTH_RANGE = (0.4, 4.5)
#: timestamp of frame 0 (2024-01-01 00:00:00 UTC), so tools showing dates show a plausible one
EPOCH_NS = 1_704_067_200 * 10**9

MIN_SIZE, MAX_SIZE = 8, 4096


def kinect_intrinsics(width: int = 640, height: int = 480) -> CameraIntrinsics:
    """Kinect-like pinhole intrinsics scaled to ``width`` (fx = fy = 525 * width / 640)."""
    focal = KINECT_FOCAL_PX * width / 640.0
    return CameraIntrinsics(
        width=width, height=height, fx=focal, fy=focal, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0
    )


@dataclass(frozen=True)
class RayHits:
    """Noise-free result of casting one ray per pixel; arrays are (H, W) unless noted."""

    #: depth along the optical axis (camera z), metres; inf where nothing is hit
    depth: np.ndarray
    #: index into ``scene.primitives`` of the hit primitive, -1 where nothing is hit
    primitive: np.ndarray
    #: face index within that primitive
    face: np.ndarray
    #: cosine of the angle between the ray and the surface normal, 0 where nothing is hit
    cos_incidence: np.ndarray


def _screen_window(
    corners: np.ndarray, camera_from_world: np.ndarray, intrinsics: CameraIntrinsics
) -> tuple[int, int, int, int] | None:
    """Pixel rows/columns ``(v0, v1, u0, u1)`` that can see a box with ``corners (8, 3)``.

    The whole image when the box reaches behind the camera; None when it is off screen.
    """
    in_camera = apply_pose(corners, camera_from_world)
    if np.any(in_camera[:, 2] <= 1e-3):
        return 0, intrinsics.height, 0, intrinsics.width
    u = intrinsics.fx * in_camera[:, 0] / in_camera[:, 2] + intrinsics.cx
    v = intrinsics.fy * in_camera[:, 1] / in_camera[:, 2] + intrinsics.cy
    u0, u1 = max(0, math.floor(u.min())), min(intrinsics.width, math.ceil(u.max()) + 1)
    v0, v1 = max(0, math.floor(v.min())), min(intrinsics.height, math.ceil(v.max()) + 1)
    if u0 >= u1 or v0 >= v1:
        return None
    return v0, v1, u0, u1


def camera_rays(intrinsics: CameraIntrinsics) -> np.ndarray:
    """``(H, W, 3) float64`` ray per pixel in the camera frame, scaled so that z = 1."""
    u = (np.arange(intrinsics.width) - intrinsics.cx) / intrinsics.fx
    v = (np.arange(intrinsics.height) - intrinsics.cy) / intrinsics.fy
    rays = np.empty((intrinsics.height, intrinsics.width, 3))
    rays[..., 0] = u[None, :]
    rays[..., 1] = v[:, None]
    rays[..., 2] = 1.0
    return rays


def cast_rays(
    scene: Scene,
    world_from_camera: np.ndarray,
    intrinsics: CameraIntrinsics,
    rays: np.ndarray | None = None,
) -> RayHits:
    """Cast one ray per pixel from the camera at ``world_from_camera (4, 4)`` into ``scene``.

    ``rays`` is :func:`camera_rays` of ``intrinsics`` (pass it to avoid recomputing it).
    """
    if rays is None:
        rays = camera_rays(intrinsics)
    rotation, origin = world_from_camera[:3, :3], world_from_camera[:3, 3]
    camera_from_world = np.linalg.inv(world_from_camera)
    # (H, W, 3); camera z = 1 so t is depth along the axis. einsum, not BLAS: a threaded BLAS
    # call on a small inner dimension costs more than it saves on a busy 2-core machine.
    directions = np.einsum("hwj,ij->hwi", rays, rotation)
    inverse_length = 1.0 / np.sqrt(np.einsum("hwi,hwi->hw", rays, rays))
    shape = (intrinsics.height, intrinsics.width)
    depth = np.full(shape, np.inf)
    primitive = np.full(shape, -1, dtype=np.int16)
    face = np.zeros(shape, dtype=np.int8)
    cos_incidence = np.zeros(shape)
    for index, candidate in enumerate(scene.primitives):
        if candidate.name in scene.absent:
            continue
        window = _screen_window(candidate.corners(), camera_from_world, intrinsics)
        if window is None:
            continue
        rows, columns = slice(window[0], window[1]), slice(window[2], window[3])
        window_directions = directions[rows, columns].reshape(-1, 3)
        t, hit_face = candidate.intersect(origin, window_directions)
        nearer = t < depth[rows, columns].ravel()
        if not nearer.any():
            continue
        t, hit_face, hit_directions = t[nearer], hit_face[nearer], window_directions[nearer]
        normals = candidate.normals(origin + t[:, None] * hit_directions, hit_face.astype(np.intp))
        nearer = nearer.reshape(depth[rows, columns].shape)
        depth[rows, columns][nearer] = t
        primitive[rows, columns][nearer] = index
        face[rows, columns][nearer] = hit_face
        cos_incidence[rows, columns][nearer] = (
            np.abs(np.einsum("ij,ij->i", normals, hit_directions))
            * inverse_length[rows, columns][nearer]
        )
    return RayHits(depth=depth, primitive=primitive, face=face, cos_incidence=cos_incidence)


def segment_names(scene: Scene) -> dict[int, str]:
    """Segment id -> ``"primitive/face"`` for every face of ``scene``; ids start at 1."""
    names = [f"{p.name}/{face}" for p in scene.primitives for face in p.face_names]
    return {i + 1: name for i, name in enumerate(names)}


def _segment_lookup(scene: Scene) -> np.ndarray:
    """``(P, F) uint16`` segment id of face f of primitive p (ids as in :func:`segment_names`)."""
    most_faces = max(len(p.face_names) for p in scene.primitives)
    lookup = np.zeros((len(scene.primitives), most_faces), dtype=np.uint16)
    next_id = 1
    for index, candidate in enumerate(scene.primitives):
        for face_index in range(len(candidate.face_names)):
            lookup[index, face_index] = next_id
            next_id += 1
    return lookup


def depth_edges(depth: np.ndarray, relative_jump: float = DEPTH_EDGE_JUMP) -> np.ndarray:
    """``(H, W) bool``: pixels with a 4-neighbour whose depth differs by more than
    ``relative_jump`` times the nearer of the two. ``depth (H, W)`` metres, inf where nothing is
    seen (nothing is not an edge: the rim of an object against empty space keeps its depth).
    """
    edges = np.zeros(depth.shape, dtype=bool)
    for first, second in (
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),  # vertical neighbours
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),  # horizontal neighbours
    ):
        a, b = depth[first], depth[second]
        with np.errstate(invalid="ignore"):
            step = np.abs(a - b) > relative_jump * np.minimum(a, b)
        step &= np.isfinite(a) & np.isfinite(b)
        edges[first] |= step
        edges[second] |= step
    return edges


def kinect_depth(hits: RayHits, rng: np.random.Generator) -> np.ndarray:
    """``(H, W) uint16`` millimetres from noise-free hits, as a Kinect v1 measures them.

    Gaussian noise with sigma ~ depth^2, then quantised to the disparity steps
    (:data:`DEPTH_STEP_AT_1M`) and to millimetres; holes (0) where nothing is seen, at grazing
    angles, at depth discontinuities and outside :data:`DEPTH_RANGE`.
    """
    depth = hits.depth
    seen = np.isfinite(depth)
    true_depth = np.where(seen, depth, 1.0)
    noisy = true_depth + DEPTH_NOISE_AT_1M * true_depth**2 * rng.standard_normal(depth.shape)
    # depth steps of z^2 * DEPTH_STEP_AT_1M are even steps of 1/z
    disparity_levels = np.rint(1.0 / (np.maximum(noisy, 0.01) * DEPTH_STEP_AT_1M))
    noisy = 1.0 / (np.maximum(disparity_levels, 1.0) * DEPTH_STEP_AT_1M)
    valid = (
        seen
        & (hits.cos_incidence >= math.cos(math.radians(MAX_INCIDENCE_DEG)))
        & ~depth_edges(depth)
        & (noisy >= DEPTH_RANGE[0])
        & (noisy <= DEPTH_RANGE[1])
    )
    millimetres = np.rint(noisy * 1000.0)
    return np.where(valid, millimetres, 0.0).astype(np.uint16)


def shade(
    scene: Scene, hits: RayHits, rng: np.random.Generator, color_noise: float = 0.0
) -> np.ndarray:
    """``(H, W, 3) uint8`` RGB: each pixel's material colour plus Gaussian noise of sigma
    ``color_noise`` (0-255 units; 0 = flat colours, which also compress to almost nothing)."""
    palette = np.array([p.color for p in scene.primitives] + [scene.background], dtype=np.float32)
    # primitive -1 (nothing hit) indexes the background, the palette's last row
    color = palette[hits.primitive]
    if color_noise > 0:
        color += color_noise * rng.standard_normal(color.shape, dtype=np.float32)
    return np.clip(np.rint(color), 0, 255).astype(np.uint8)


def render_frame(
    scene: Scene,
    index: int,
    intrinsics: CameraIntrinsics,
    *,
    seed: int = 0,
    fps: float = 30.0,
    color_noise: float = 0.0,
    rays: np.ndarray | None = None,
) -> Frame:
    """Frame ``index`` of ``scene``: the camera on its path and the scene as they are at time
    ``index / fps``; the frame's ``pose`` is the camera's in the scene's ``world`` frame.

    The noise depends only on ``(seed, index)``, so a frame is the same whichever frames are
    rendered before it. ``rays`` is :func:`camera_rays` of ``intrinsics``, to reuse.
    """
    time_s = index / fps
    world_from_camera = scene.orbit.pose(time_s)
    hits = cast_rays(scene.at(time_s), world_from_camera, intrinsics, rays)
    rng = np.random.default_rng([seed, index])
    depth = kinect_depth(hits, rng)
    color = shade(scene, hits, rng, color_noise)
    seen = hits.primitive >= 0
    labels = np.zeros(depth.shape, dtype=np.uint16)
    labels[seen] = _segment_lookup(scene)[hits.primitive[seen], hits.face[seen]]
    labels[depth == 0] = 0
    return Frame(
        index=index,
        timestamp_ns=EPOCH_NS + round(index * 1e9 / fps),
        color=color,
        depth=depth,
        intrinsics=intrinsics,
        labels=labels,
        pose=CameraPose(world_from_camera),
        extras={"scene": scene.name, "segments": segment_names(scene)},
    )


#: name of the MCAP metadata record describing a synthetic scene
SCENE_METADATA = "gngdt.scene"


def scene_metadata(scene: Scene, fps: float) -> dict[str, str]:
    """What a recording of ``scene`` stores about it (MCAP metadata ``gngdt.scene``, strings only):
    ``scene``, ``fps``, ``segments`` (JSON {id: "primitive/face"}) and ``motions`` (JSON list of
    {primitive, kind "move"/"vanish", start_frame, end_frame, offset_m})."""
    return {
        "scene": scene.name,
        "fps": repr(float(fps)),
        "segments": json.dumps(segment_names(scene)),
        "motions": json.dumps([motion.describe(fps) for motion in scene.motions]),
    }


def _check_int(name: str, value: object, low: int, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        bound = f"between {low} and {high}" if high is not None else f">= {low}"
        raise ValueError(f"{name} must be {bound}, got {value}")
    return int(value)


def render_scene(
    scene: str,
    frames: int,
    *,
    width: int = 640,
    height: int = 480,
    seed: int = 0,
    fps: float = 30.0,
    color_noise: float = 0.0,
) -> Iterator[Frame]:
    """Render ``frames`` frames of the synthetic ``scene`` (a key of :data:`SCENES`).

    Yields :class:`Frame` objects: color (H, W, 3) uint8 RGB, depth (H, W) uint16 mm (0 = hole),
    Kinect-like intrinsics, labels (H, W) uint16 segment ids (0 = nothing/hole), the camera's
    ``pose`` in the scene's ``world`` frame, and extras ``{"scene", "segments": {id:
    "primitive/face"}}``.
    ``color_noise``: sigma of Gaussian colour noise, 0-255 units (default 0: flat colours).
    Parameters are checked here, before the first frame: ``ValueError`` names the bad one.
    """
    built = build_scene(scene) if isinstance(scene, str) else None
    if built is None:
        raise ValueError(f"scene must be a scene name, got {scene!r}")
    frames = _check_int("frames", frames, 1)
    width = _check_int("width", width, MIN_SIZE, MAX_SIZE)
    height = _check_int("height", height, MIN_SIZE, MAX_SIZE)
    seed = _check_int("seed", seed, 0)
    if isinstance(fps, bool) or not isinstance(fps, int | float) or not 0 < fps < math.inf:
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    if not isinstance(color_noise, int | float) or not 0 <= color_noise <= 255:
        raise ValueError(f"color_noise must be between 0 and 255, got {color_noise!r}")
    intrinsics = kinect_intrinsics(width, height)
    return _frames(built, frames, intrinsics, seed=seed, fps=float(fps), color_noise=color_noise)


def _frames(
    scene: Scene, count: int, intrinsics: CameraIntrinsics, **options: float
) -> Iterator[Frame]:
    rays = camera_rays(intrinsics)
    for index in range(count):
        yield render_frame(scene, index, intrinsics, rays=rays, **options)
