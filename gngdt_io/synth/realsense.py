"""Virtual RealSense recordings: a known scene rendered by the virtual Kinect's ray caster
(`gngdt.io.synth.render.cast_rays`) from a depth camera and a colour camera ``baseline_m`` apart,
each with its own D435-like intrinsics, and written by the SDK's own recorder (a
``software_device`` with a z16 depth and an rgb8 colour sensor, recorded by ``rs.recorder``).

So every door RealSense users have is exercised without a camera: the file format the SDK
writes (a rosbag2 ``.db3`` since 2.58), its playback, the alignment of depth to colour (which
has real work to do: other intrinsics, another viewpoint), the intrinsics and the depth units
(1 mm, 0.1 mm) read back. Noise-free, so tests can hold the read-back to exact values.

The scene (`known_scene`), world frame x right, y forward, z up, metres: a grey wall facing
the cameras at y = ``WALL_Y`` and a red box whose front face is at y = ``BOX_FRONT_Y``; the depth
camera sits at the origin looking along +y, the colour camera ``baseline_m`` to its left
(librealsense's depth-to-colour extrinsics: +``baseline_m`` along x).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.realsense.sdk import pyrealsense
from gngdt.io.synth.motion import Orbit, look_at
from gngdt.io.synth.primitives import Rectangle, box
from gngdt.io.synth.render import cast_rays, shade
from gngdt.io.synth.scenes import Scene

log = logging.getLogger(__name__)

WALL_Y = 1.5
BOX_FRONT_Y = 1.0
BOX_SIZE = (0.3, 0.2, 0.24)
WALL_RGB = (128, 128, 128)
BOX_RGB = (200, 30, 30)
#: frame 0's time, ms since the epoch (the SDK's system-time domain)
START_TIME_MS = 1_700_000_000_000.0


def known_scene(wall_y: float = WALL_Y) -> Scene:
    """A wall facing the cameras and a box in front of it (see the module's docstring)."""
    depth = BOX_SIZE[1]
    return Scene(
        name="realsense_known",
        description="a grey wall and a red box in front of it, seen head-on",
        primitives=(
            Rectangle("wall", WALL_RGB, center=(0.0, wall_y, 0.0), normal=(0.0, -1.0, 0.0),
                      axis_u=(1.0, 0.0, 0.0), half_size=(4.0, 4.0)),
            box("box", BOX_RGB, center=(0.0, BOX_FRONT_Y + depth / 2, 0.0), size=BOX_SIZE),
        ),
        orbit=Orbit(target=(0.0, 1.0, 0.0), distance=1.0, elevation_deg=0.0,
                    azimuth_swing_deg=0.0, period_s=1.0),  # unused: the cameras stand still
        background=(0, 0, 0),
        ground_truth={},
    )


def d435_like_intrinsics(width: int, height: int) -> tuple[CameraIntrinsics, CameraIntrinsics]:
    """(depth, colour) intrinsics like a D435's at ``width`` x ``height``, each value an exact
    float32 so that a read-back can be compared exactly."""
    sx, sy = width / 640.0, height / 480.0

    def exact(value: float) -> float:
        return float(np.float32(value))

    depth = CameraIntrinsics(width, height, exact(385.25 * sx), exact(385.25 * sy),
                             exact(320.125 * sx), exact(239.875 * sy))
    color = CameraIntrinsics(width, height, exact(615.5 * sx), exact(615.75 * sy),
                             exact(318.625 * sx), exact(242.375 * sy))
    return depth, color


@dataclass(frozen=True)
class VirtualRecording:
    """What a virtual recording holds, for tests to compare the read-back with."""

    path: Path
    frames: int
    #: metres per z16 step (0.001 = 1 mm, 0.0001 = 0.1 mm)
    depth_units: float
    depth_intrinsics: CameraIntrinsics
    color_intrinsics: CameraIntrinsics
    #: (4, 4) world_from_camera of the colour camera (the aligned frames' camera)
    color_pose: np.ndarray
    scene: Scene
    timestamps_ms: tuple[float, ...]


def render_views(scene: Scene, depth_camera: CameraIntrinsics, color_camera: CameraIntrinsics,
                 baseline_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(depth_m, rgb, color_pose)``: (H, W) float64 metres along the depth camera's axis
    (0 = nothing), (H, W, 3) uint8 seen by the colour camera, and its (4, 4) pose."""
    depth_pose = look_at(np.zeros(3), np.array([0.0, 1.0, 0.0]))
    color_pose = depth_pose.copy()
    color_pose[:3, 3] -= baseline_m * depth_pose[:3, 0]  # to the left of the depth camera
    hits = cast_rays(scene, depth_pose, depth_camera)
    depth_m = np.where(np.isfinite(hits.depth), hits.depth, 0.0)
    rgb = shade(scene, cast_rays(scene, color_pose, color_camera), np.random.default_rng(0))
    return depth_m, rgb, color_pose


def to_depth_units(depth_m: np.ndarray, depth_units: float) -> np.ndarray:
    """(H, W) uint16 raw depth in ``depth_units`` metres per step; what does not fit is 0."""
    raw = np.rint(depth_m / depth_units)
    raw[(raw > 65535) | (raw < 0)] = 0
    return raw.astype(np.uint16)


def write_virtual_recording(path: str | Path, frames: int = 10, depth_units: float = 0.001,
                            width: int = 640, height: int = 480, *,
                            scene: Scene | None = None, baseline_m: float = 0.015,
                            fps: int = 30, serial: str = "SIM-0001",
                            timeout_s: float = 30.0) -> VirtualRecording:
    """Record ``frames`` framesets of ``scene`` (default `known_scene`) with the SDK's recorder
    into ``path`` (``.db3``: SDK 2.58 and later write nothing else). ``serial`` is stored as the
    device's serial number, so the recording loaded into a context (``rs.context().load_device``)
    is found by serial like a connected camera."""
    rs = pyrealsense()
    path = Path(path)
    path.unlink(missing_ok=True)
    scene = scene or known_scene()
    depth_camera, color_camera = d435_like_intrinsics(width, height)
    depth_m, rgb, color_pose = render_views(scene, depth_camera, color_camera, baseline_m)
    raw_depth = to_depth_units(depth_m, depth_units)
    timestamps = tuple(START_TIME_MS + i * 1000.0 / fps for i in range(frames))
    device = rs.software_device()
    device.register_info(rs.camera_info.serial_number, serial)
    device.register_info(rs.camera_info.name, "gngdt virtual RealSense")
    depth_sensor, color_sensor = device.add_sensor("Depth"), device.add_sensor("Color")
    depth_sensor.add_read_only_option(rs.option.depth_units, depth_units)
    depth_profile = depth_sensor.add_video_stream(_stream(
        rs, rs.stream.depth, rs.format.z16, 2, 0, depth_camera, fps)).as_video_stream_profile()
    color_profile = color_sensor.add_video_stream(_stream(
        rs, rs.stream.color, rs.format.rgb8, 3, 1, color_camera, fps)).as_video_stream_profile()
    extrinsics = rs.extrinsics()
    extrinsics.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    extrinsics.translation = [baseline_m, 0.0, 0.0]  # depth -> colour, metres
    depth_profile.register_extrinsics_to(color_profile, extrinsics)
    sensors = ((depth_sensor, depth_profile, raw_depth, 2), (color_sensor, color_profile, rgb, 3))
    recorder = rs.recorder(str(path), device, True)  # lossless PNG images
    try:
        _play(rs, sensors, timestamps, timeout_s)
    finally:
        del recorder  # closes the file
    log.debug("recorded %d framesets to %s", frames, path)
    return VirtualRecording(path, frames, depth_units, depth_camera, color_camera, color_pose,
                            scene, timestamps)


def _stream(rs: Any, kind: Any, fmt: Any, bytes_per_pixel: int, uid: int,
            camera: CameraIntrinsics, fps: int) -> Any:
    intrinsics = rs.intrinsics()
    intrinsics.width, intrinsics.height = camera.width, camera.height
    intrinsics.fx, intrinsics.fy, intrinsics.ppx, intrinsics.ppy = (
        camera.fx, camera.fy, camera.cx, camera.cy)
    intrinsics.model = rs.distortion.none
    intrinsics.coeffs = [0.0] * 5
    stream = rs.video_stream()
    stream.type, stream.index, stream.uid = kind, 0, uid
    stream.width, stream.height, stream.fps = camera.width, camera.height, fps
    stream.bpp, stream.fmt, stream.intrinsics = bytes_per_pixel, fmt, intrinsics
    return stream


def _play(rs: Any, sensors: tuple, timestamps: tuple[float, ...], timeout_s: float) -> None:
    """Feed every frame to the software sensors and wait until the recorder has them all."""
    received = 0
    done, lock = threading.Event(), threading.Lock()

    def on_frame(_frame: Any) -> None:
        nonlocal received
        with lock:
            received += 1
            if received >= len(sensors) * len(timestamps):
                done.set()

    buffers = []  # the SDK may point at the pixels until they are recorded
    for sensor, profile, _, _ in sensors:
        sensor.open(profile)
        sensor.start(on_frame)
    try:
        for index, stamp in enumerate(timestamps):
            for sensor, profile, image, bytes_per_pixel in sensors:
                pixels = np.ascontiguousarray(image.copy())
                buffers.append(pixels)
                frame = rs.software_video_frame()
                frame.pixels, frame.bpp = pixels, bytes_per_pixel
                frame.stride = bytes_per_pixel * profile.width()
                frame.timestamp, frame.domain = stamp, rs.timestamp_domain.system_time
                frame.frame_number, frame.profile = index, profile
                sensor.on_video_frame(frame)
        if timestamps and not done.wait(timeout_s):
            raise TimeoutError(f"the software sensors delivered {received} of "
                               f"{len(sensors) * len(timestamps)} frames")
        time.sleep(0.05)  # the recorder writes on its own thread
    finally:
        for sensor, _, _, _ in sensors:
            sensor.stop()
            sensor.close()
