"""The aligned RGB-D stream of a RealSense device or recording: one code path for both.

A ``rs.pipeline`` is started on a recording (``config.enable_device_from_file(path,
repeat_playback=False)``, real-time playback off, so every frame is decoded and none skipped) or
on a device (``config.enable_device(serial)``, depth z16 + colour rgb8, 640x480 at 30 fps by
default). Each frameset is aligned to colour (``rs.align(rs.stream.color)``); the intrinsics are
the colour stream's, the depth goes from the device's units (``depth_frame.get_units()``,
metres per step) to millimetres. Every wait on the SDK is bounded (``frame_timeout_s``); failures
are `RealSenseError` subclasses (RecordingErrors) whose message is meant for a person.

Playback quirks of SDK 2.59 handled here (each reproduced on recordings the SDK wrote):
real-time mode must be off before the pipeline starts (else the first framesets are dropped);
even so the first frameset is sometimes lost, which is checked against the file's first frame
numbers and cured by restarting playback; when one stream has a gap the syncer re-sends the
other's last frame, so framesets repeating a frame are skipped; an undecodable frame stops
playback silently, which is told from the end of the file by the image counts.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.errors import RecordingError
from gngdt.io.mcap.limits import ReadLimits
from gngdt.io.realsense.files import RecordingInfo

log = logging.getLogger(__name__)

#: playbacks restarted at most this often when the first frameset was lost
START_ATTEMPTS = 8
#: frames the better-read stream may fall short of its count at the end of a recording
EOF_TOLERANCE = 1
#: how long one wait for a frameset lasts before the stop conditions are checked again, ms
POLL_MS = 100
#: timestamp domains that are Unix time (others are a device clock)
UNIX_DOMAINS = ("global_time", "system_time")


class RealSenseError(RecordingError):
    """A RealSense device or recording cannot deliver frames (the message says why)."""


class NoDeviceError(RealSenseError):
    """No RealSense device is connected."""


class DeviceNotFoundError(RealSenseError):
    """No connected device has the serial number asked for."""


class DeviceLostError(RealSenseError):
    """A device stopped delivering frames: unplugged, or stalled."""


@dataclass(frozen=True)
class StreamMode:
    """What a live device is asked to stream (depth z16 and colour rgb8 alike)."""

    width: int = 640
    height: int = 480
    fps: int = 30

    def __str__(self) -> str:
        return f"{self.width}x{self.height} at {self.fps} fps"


@dataclass(frozen=True)
class AlignedFrame:
    """One frameset aligned to colour.

    color: (H, W, 3) uint8 RGB. depth_mm: (H, W) uint16 millimetres along the optical axis,
    aligned to ``color``, 0 = no depth. intrinsics: of both. timestamp_ns: the colour frame's
    time in ``timestamp_domain`` (``global_time``/``system_time`` are Unix time).
    """

    color: np.ndarray
    depth_mm: np.ndarray
    intrinsics: CameraIntrinsics
    timestamp_ns: int
    timestamp_domain: str
    frame_number: int
    #: metres per raw depth step of the source (0.001 or 0.0001 typically)
    depth_units_m: float
    #: the colour stream's distortion model (``brown_conrady``, ``none``, ...)
    distortion_model: str


def depth_to_mm(raw: np.ndarray, units_m: float) -> tuple[np.ndarray, int]:
    """``(depth_mm, overflow)``: raw (H, W) uint16 depth in ``units_m`` metres per step as a new
    (H, W) uint16 array of millimetres, rounded (0.1 mm units lose at most 0.5 mm, and their
    largest value, 6553.5 mm, fits). Values beyond 65535 mm (units coarser than 1 mm) become 0,
    counted in ``overflow``."""
    factor = units_m * 1000.0
    if abs(factor - 1.0) < 1e-6:  # 1 mm (stored as float32: 0.001 -> 1.00000005 mm)
        return raw.copy(), 0
    millimetres = np.rint(raw.astype(np.float32) * np.float32(factor))
    over = millimetres > 65535.0
    overflow = int(np.count_nonzero(over))
    if overflow:
        millimetres[over] = 0.0
    return millimetres.astype(np.uint16), overflow


def color_to_rgb(rs: ModuleType, data: np.ndarray, fmt: Any) -> np.ndarray:
    """A colour frame's pixels in SDK format ``fmt`` as a new (H, W, 3) uint8 RGB array."""
    if fmt == rs.format.rgb8:
        return data.copy()
    if fmt == rs.format.bgr8:
        return np.ascontiguousarray(data[..., ::-1])
    if fmt == rs.format.rgba8:
        return np.ascontiguousarray(data[..., :3])
    if fmt == rs.format.bgra8:
        return np.ascontiguousarray(data[..., 2::-1])
    if fmt == rs.format.yuyv:
        import cv2

        return cv2.cvtColor(data.reshape(data.shape[0], -1, 2), cv2.COLOR_YUV2RGB_YUYV)
    raise ValueError(f"unsupported colour format {fmt}")


def sdk_intrinsics(intrinsics: Any) -> CameraIntrinsics:
    """The SDK's ``rs.intrinsics`` as `CameraIntrinsics` (not yet judged: ``.problem()``)."""
    return CameraIntrinsics(
        width=int(intrinsics.width), height=int(intrinsics.height),
        fx=float(intrinsics.fx), fy=float(intrinsics.fy), cx=float(intrinsics.ppx),
        cy=float(intrinsics.ppy), distortion=tuple(float(c) for c in intrinsics.coeffs))


def list_devices(rs: ModuleType, context: Any) -> list[dict[str, str]]:
    """Connected devices: ``[{"serial": ..., "name": ...}]`` (1-2 ms, never waits)."""
    found = []
    for device in context.query_devices():
        def info(key: Any, device: Any = device) -> str:
            return device.get_info(key) if device.supports(key) else ""

        found.append({"serial": info(rs.camera_info.serial_number),
                      "name": info(rs.camera_info.name)})
    return found


def find_device(rs: ModuleType, context: Any, serial: str | None, spec: str) -> dict[str, str]:
    """The device to open (the only or first one when ``serial`` is None); NoDeviceError or
    DeviceNotFoundError (listing the serials connected) at once, where starting a pipeline would
    wait 15 s to say less."""
    devices = list_devices(rs, context)
    if not devices:
        raise NoDeviceError(spec, None, "no RealSense device connected (the SDK lists none: "
                            "check the USB cable, a USB 3 port, and the udev rules or "
                            "permissions of the device)")
    serials = [device["serial"] for device in devices]
    if serial is None:
        if len(devices) > 1:
            log.warning("several RealSense devices (%s); using %s", ", ".join(serials),
                        serials[0])
        return devices[0]
    if serial not in serials:
        raise DeviceNotFoundError(spec, None, f"no RealSense device with serial {serial!r}; "
                                  f"connected: {', '.join(serials)}")
    return devices[serials.index(serial)]


class AlignedStream:
    """One pass over a recording, or one session of a live device: `frames` until the
    recording ends, the device is lost or `close` (from any thread).

    ``recording``: a ``.db3`` (its `RecordingInfo` in ``info``) or a legacy ``.bag`` to play;
    None: the device ``serial`` streaming ``mode``. ``strict``: an early end of playback (an
    undecodable frame) raises, else it is warned about. ``context``: the ``rs.context`` to use.
    ``max_frame_pixels``: largest image a stream's calibration may claim.
    """

    def __init__(self, rs: ModuleType, context: Any, *, name: str,
                 recording: Path | None = None, info: RecordingInfo | None = None,
                 serial: str | None = None, mode: StreamMode | None = None,
                 frame_timeout_s: float = 5.0, strict: bool = True,
                 max_frame_pixels: int = ReadLimits.max_frame_pixels) -> None:
        self.rs = rs
        self.context = context
        #: how errors name the source: the file, or ``realsense:SERIAL``
        self.name = name
        self.recording = recording
        self.info = info
        self.serial = serial
        self.mode = mode or StreamMode()
        self.frame_timeout_s = frame_timeout_s
        self.strict = strict
        self.max_frame_pixels = max_frame_pixels
        self._pipe: Any = None
        self._profile: Any = None
        self._playback: Any = None
        self._pending: Any = None
        self._removed = threading.Event()
        self._seen_depth: set[int] = set()
        self._seen_color: set[int] = set()
        self.frames_read = 0
        self.stale_skipped = 0
        self.depth_overflow_pixels = 0

    # -- opening ---------------------------------------------------------------------------
    def open(self) -> None:
        """Start the pipeline (a RealSenseError says why it cannot)."""
        try:
            if self.recording is not None:
                self._open_recording(self.recording)
            else:
                self._open_device()
        except BaseException:
            self.close()
            raise

    def _open_recording(self, path: Path) -> None:
        first = None
        for attempt in range(1, START_ATTEMPTS + 1):
            self._start_playback(path)
            first = self._first_frameset()
            if first is None or self._is_first_of_file(first):
                break
            if attempt == START_ATTEMPTS:
                log.warning("%s: playback does not start at the file's first frame", path)
                break
            log.debug("playback lost the first frameset (attempt %d); restarting", attempt)
            self._stop_pipeline()
        self._pending = first

    def _start_playback(self, path: Path) -> None:
        """A pipeline on ``path`` with real-time playback off before the sensors start (set on
        the device ``config.resolve`` makes, which ``start`` reuses)."""
        rs = self.rs
        config = rs.config()
        config.enable_device_from_file(str(path), repeat_playback=False)
        config.enable_stream(rs.stream.depth)
        config.enable_stream(rs.stream.color)
        pipe = rs.pipeline(self.context)
        try:
            resolved = config.resolve(rs.pipeline_wrapper(pipe))
        except RuntimeError as error:
            raise RealSenseError(self.name, None, f"the SDK cannot play it: {error}") from error
        resolved.get_device().as_playback().set_real_time(False)
        self._start(pipe, config)
        self._playback = self._profile.get_device().as_playback()

    def _first_frameset(self) -> Any:
        """The playback's first frameset, or None when the recording ends without one."""
        deadline = time.monotonic() + self.frame_timeout_s
        while time.monotonic() < deadline:
            ok, frameset = self._pipe.try_wait_for_frames(POLL_MS)
            if ok:
                frameset.keep()
                return frameset
            if self._playback.current_status() == self.rs.playback_status.stopped:
                return None
        raise RealSenseError(self.name, None, f"no frame within {self.frame_timeout_s:g} s")

    def _is_first_of_file(self, frameset: Any) -> bool:
        """Whether the frameset holds the file's first depth or first colour frame (a file
        whose streams start unevenly passes: its first frameset holds one of them)."""
        info = self.info
        if info is None or info.first_depth_number is None or info.first_color_number is None:
            return True
        depth, color = frameset.get_depth_frame(), frameset.get_color_frame()
        return bool(depth and depth.get_frame_number() == info.first_depth_number) or bool(
            color and color.get_frame_number() == info.first_color_number)

    def _open_device(self) -> None:
        rs, mode = self.rs, self.mode
        device = find_device(rs, self.context, self.serial, self.name)
        self.serial = device["serial"]
        config = rs.config()
        config.enable_device(self.serial)
        config.enable_stream(rs.stream.depth, mode.width, mode.height, rs.format.z16, mode.fps)
        config.enable_stream(rs.stream.color, mode.width, mode.height, rs.format.rgb8, mode.fps)
        pipe = rs.pipeline(self.context)
        if not config.can_resolve(rs.pipeline_wrapper(pipe)):
            raise RealSenseError(self.name, None, f"{device['name'] or 'the device'} "
                                 f"{self.serial} cannot stream depth z16 and colour rgb8 at "
                                 f"{mode}")
        self.context.set_devices_changed_callback(self._on_devices_changed)
        self._start(pipe, config)
        log.info("RealSense %s %s streaming %s", device["name"], self.serial, mode)

    def _start(self, pipe: Any, config: Any) -> None:
        try:
            self._profile = pipe.start(config)
        except RuntimeError as error:
            raise RealSenseError(self.name, None, f"cannot start: {error}") from error
        self._pipe = pipe
        self._check_streams()

    def _check_streams(self) -> None:
        """RealSenseError unless every stream's calibration can be a camera's and its images
        fit ``max_frame_pixels`` (a recording's CameraInfo may claim anything: 65535x65535
        made the SDK's alignment fail on every frame)."""
        try:
            streams = [(str(stream.stream_type()).rsplit(".", 1)[-1],
                        stream.as_video_stream_profile().get_intrinsics())
                       for stream in self._profile.get_streams()]
        except RuntimeError as error:
            raise RealSenseError(self.name, None, f"the SDK cannot describe its streams: "
                                 f"{error}") from error
        for kind, sdk in streams:
            intrinsics = sdk_intrinsics(sdk)
            problem = intrinsics.problem()
            if not problem and intrinsics.width * intrinsics.height > self.max_frame_pixels:
                problem = (f"images of {intrinsics.width}x{intrinsics.height} exceed the limit "
                           f"of {self.max_frame_pixels:,} pixels")
            if problem:
                raise RealSenseError(self.name, None, f"{kind} stream calibration refused: "
                                     f"{problem}")

    def _on_devices_changed(self, event: Any) -> None:
        """The SDK's callback (its own thread): note when our device goes away."""
        try:
            removed = self._profile is not None and event.was_removed(self._profile.get_device())
        except RuntimeError:  # the handle is unusable already: ask the context instead
            removed = self.serial not in {device["serial"] for device in
                                          list_devices(self.rs, self.context)}
        if removed:
            self._removed.set()

    # -- reading ---------------------------------------------------------------------------
    def frames(self) -> Iterator[AlignedFrame]:
        """Aligned frames until the end of the recording or `close`; a frameset repeating the
        previous depth or colour frame is skipped, so every frame comes once. DeviceLostError
        (nothing for ``frame_timeout_s``, or unplugged) or RealSenseError (playback stalled or
        ended early) otherwise."""
        pipe, align = self._pipe, self.rs.align(self.rs.stream.color)
        last: tuple[tuple[int, float], tuple[int, float]] | None = None
        last_frame_at = time.monotonic()
        while self._pipe is pipe and pipe is not None:
            frameset = self._next_frameset(pipe, last_frame_at)
            if frameset is None:
                if self._pipe is not pipe or self._ended():
                    return
                continue
            last_frame_at = time.monotonic()
            try:
                self._note_seen(frameset)
                aligned = align.process(frameset)
                depth, color = aligned.get_depth_frame(), aligned.get_color_frame()
                if not depth or not color:
                    continue
                ids = ((depth.get_frame_number(), depth.get_timestamp()),
                       (color.get_frame_number(), color.get_timestamp()))
                if last is not None and (ids[0] == last[0] or ids[1] == last[1]):
                    self.stale_skipped += 1
                    continue
                last = ids
                frame = self._to_frame(depth, color)
            except (RuntimeError, ValueError) as error:  # the SDK's (its processing blocks'),
                # and a colour format it delivered that gngdt does not read
                raise RealSenseError(self.name, self.frames_read,
                                     f"the SDK cannot read this frame: {error}") from error
            yield frame

    def _next_frameset(self, pipe: Any, last_frame_at: float) -> Any:
        """The next frameset, or None after one poll without (raising when the wait is over)."""
        if self._pending is not None:
            frameset, self._pending = self._pending, None
            return frameset
        try:
            ok, frameset = pipe.try_wait_for_frames(POLL_MS)
        except RuntimeError as error:
            if self._pipe is not pipe:
                return None
            raise self._lost(f"waiting for frames failed: {error}") from error
        if ok:
            return frameset
        if self._playback is None and self._removed.is_set():
            raise DeviceLostError(self.name, None, f"RealSense {self.serial} was disconnected "
                                  f"after {self.frames_read} frames")
        waited = time.monotonic() - last_frame_at
        if waited > self.frame_timeout_s and not self._ended():
            raise self._lost(f"no frame for {waited:.1f} s")
        return None

    def _ended(self) -> bool:
        """Whether playback reached its end (checked: `_check_complete`)."""
        if self._playback is None or (
                self._playback.current_status() != self.rs.playback_status.stopped):
            return False
        self._check_complete()
        return True

    def _to_frame(self, depth: Any, color: Any) -> AlignedFrame:
        units = float(depth.get_units())
        depth_mm, overflow = depth_to_mm(np.asanyarray(depth.get_data()), units)
        if overflow:
            self.depth_overflow_pixels += overflow
            log.warning("%s: %d depth pixels beyond 65535 mm set to 0", self.name, overflow)
        profile = color.get_profile()
        rgb = color_to_rgb(self.rs, np.asanyarray(color.get_data()), profile.format())
        intrinsics = profile.as_video_stream_profile().get_intrinsics()
        camera = sdk_intrinsics(intrinsics)
        problem = camera.problem((rgb.shape[1], rgb.shape[0]))
        if not problem and depth_mm.shape != rgb.shape[:2]:
            problem = (f"aligned depth {depth_mm.shape[1]}x{depth_mm.shape[0]} is not the "
                       f"colour's {rgb.shape[1]}x{rgb.shape[0]}")
        if problem:
            raise RealSenseError(self.name, self.frames_read, f"frame refused: {problem}")
        self.frames_read += 1
        return AlignedFrame(
            color=rgb, depth_mm=depth_mm, intrinsics=camera,
            timestamp_ns=round(color.get_timestamp() * 1e6),
            timestamp_domain=str(color.get_frame_timestamp_domain()).rsplit(".", 1)[-1],
            frame_number=int(color.get_frame_number()), depth_units_m=units,
            distortion_model=str(intrinsics.model).rsplit(".", 1)[-1])

    def _lost(self, why: str) -> RealSenseError:
        if self._playback is not None:
            return RealSenseError(self.name, None, f"playback stalled ({why})")
        state = "was disconnected" if self._removed.is_set() else "stopped streaming"
        return DeviceLostError(self.name, None, f"RealSense {self.serial} {state} after "
                               f"{self.frames_read} frames ({why})")

    def _note_seen(self, frameset: Any) -> None:
        depth, color = frameset.get_depth_frame(), frameset.get_color_frame()
        if depth:
            self._seen_depth.add(depth.get_frame_number())
        if color:
            self._seen_color.add(color.get_frame_number())

    def _check_complete(self) -> None:
        """Raise (strict) or warn when playback stopped well before the end of the file: the
        SDK stops silently at an undecodable frame, after which both streams fall short of the
        file's image counts (one within ``EOF_TOLERANCE`` means the end was reached)."""
        info = self.info
        if info is None:
            return
        depth_short = info.depth_frames - len(self._seen_depth)
        color_short = info.color_frames - len(self._seen_color)
        if min(depth_short, color_short) <= EOF_TOLERANCE:
            return
        reason = (f"playback stopped early, after {self.frames_read} frames: "
                  f"{len(self._seen_depth)} of {info.depth_frames} depth and "
                  f"{len(self._seen_color)} of {info.color_frames} colour images read (an "
                  "undecodable image stops the SDK's playback)")
        if self.strict:
            raise RealSenseError(self.name, None, reason)
        log.warning("%s: %s", self.name, reason)

    # -- closing ---------------------------------------------------------------------------
    def _stop_pipeline(self) -> None:
        pipe, self._pipe = self._pipe, None
        self._playback = None
        self._pending = None
        if pipe is not None:
            try:
                pipe.stop()
            except RuntimeError as error:  # the device is gone already
                log.debug("pipeline stop: %s", error)

    def close(self) -> None:
        """Stop the pipeline (safe twice, and from another thread: `frames` then ends)."""
        self._stop_pipeline()
