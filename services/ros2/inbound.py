"""ROS 2 -> gngdt: a camera driver's colour, depth and CameraInfo topics as gngdt frames, published
on ``gngdt/<cam>/{color,depth,calibration,points}`` exactly as `gngdt capture` publishes a
recording's (`gngdt.services.capture.CapturePublisher`, `gngdt.io.deproject.FrameToCloud`), so the
learner and the logger work unchanged.

Colour and depth are paired by stamp within ``max_skew_ns`` (`gngdt.io.mcap.frame_assembly`); images
wait at most ``max_held_bytes`` for a partner. With a fixed frame named, each frame's camera pose
is looked up in ``/tf`` and ``/tf_static`` at its stamp (as tf2 does, interpolated; up to
``LIVE_TF_EXTRAPOLATION_NS`` past the newest transform); a frame without a pose publishes its
images but no cloud. Each frame's capture time is its colour image's stamp when that is
wall-clock time (within a day of this clock), else (simulated time) the time it arrived.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from gngdt.io.frame import CameraPose
from gngdt.io.mcap.frame_assembly import DecodedImage, FrameAssembler
from gngdt.io.ros2.messages import (
    CAMERA_INFO,
    IMAGE,
    TF_MESSAGE,
    decode_camera_info,
    decode_image,
    decode_tf,
    type_hash,
)
from gngdt.io.ros2.wire import QOS_SENSOR_DATA, QOS_TF, Durability, Qos
from gngdt.io.tf_tree import TransformError, TransformTree
from gngdt.schemas.wire import MAX_CLOCK_OFFSET_NS, FrameStamp
from gngdt.services.capture import CapturePublisher, cloud_of
from gngdt.services.ros2.worker import Handler, Worker

if TYPE_CHECKING:
    import zenoh

    from gngdt.core.sensor.geometry import CameraIntrinsics
    from gngdt.io.deproject import FrameToCloud
    from gngdt.io.errors import RecordingError
    from gngdt.io.frame import Frame
    from gngdt.io.ros2.node import Ros2Node

log = logging.getLogger(__name__)

#: image encodings taken as colour and as depth (16UC1/mono16 millimetres, 32FC1 metres)
COLOR_ENCODINGS = frozenset({"rgb8", "bgr8", "rgba8", "bgra8", "mono8"})
DEPTH_ENCODINGS = frozenset({"16UC1", "mono16", "32FC1"})
#: a frame may be this much newer than the newest transform of its chain (a live /tf at 10 Hz)
LIVE_TF_EXTRAPOLATION_NS = 100_000_000
#: /tf is held over a window this wide either side of the latest image's stamp (before the
#: first image: behind each link's own newest sample); a transform stamped beyond it is
#: ignored and counted (a far-future stamp once emptied every other link)
TF_WINDOW_NS = 10_000_000_000
#: tf2_ros' static listener QoS: reliable, transient local, keep last 100
QOS_TF_STATIC = Qos(durability=Durability.TRANSIENT_LOCAL, depth=100)
#: bad frames, frames without pose, transforms refused: warned one by one up to this many
WARN_FIRST = 5


def camera_worker(handle: Handler) -> Worker:
    """The worker of a camera's samples: of the images of each role and of CameraInfo only the
    newest waits (a live camera: the newest frame wins; under a flood up to 64 MB of images
    waited), transforms in order."""
    return Worker("camera", handle, capacity=8, latest_only=("color", "depth", "camera_info"))


@dataclass(frozen=True)
class CameraTopics:
    """A camera driver's topics (realsense2_camera's default names)."""

    color: str = "/camera/camera/color/image_raw"
    depth: str = "/camera/camera/aligned_depth_to_color/image_raw"
    camera_info: str = "/camera/camera/color/camera_info"


@dataclass
class InboundCounts:
    """Frames made of the camera's images, and what was skipped (each also warned about)."""

    frames_published: int = 0
    frames_without_pose: int = 0
    images_before_calibration: int = 0
    calibrations_refused: int = 0
    bad_frames: int = 0
    transforms_refused: int = 0
    transforms_far_off: int = 0


class RosToGngdt:
    """Subscribes (with ``node``) to a camera's topics, and ``/tf`` + ``/tf_static`` when
    ``fixed_frame`` is named; publishes its frames on ``session`` as camera ``camera``."""

    def __init__(self, session: zenoh.Session, node: Ros2Node, camera: str, topics: CameraTopics,
                 to_cloud: FrameToCloud, *, max_skew_ns: int, max_pixels: int,
                 max_held_bytes: int, fixed_frame: str | None = None,
                 pool_bytes: int | None = None) -> None:
        self.publisher = CapturePublisher(session, camera, pool_bytes)
        self.to_cloud = to_cloud
        self.max_pixels = max_pixels
        self.fixed_frame = fixed_frame
        self.counts = InboundCounts()
        self.topics = topics
        self.transforms = TransformTree(max_extrapolation_ns=LIVE_TF_EXTRAPOLATION_NS,
                                        evict=True)
        self.assembler = FrameAssembler(
            Path(topics.color), None, max_skew_ns, on_bad_frame=self._bad_frame,
            poses=self._pose if fixed_frame else None, max_held_bytes=max_held_bytes)
        self.worker = camera_worker(self._on_sample)
        self._sequence = 0
        self._image_stamp_ns: int | None = None  # the latest image's: poses are looked up near
        self._pruned_at = 0.0
        self._simulated_time = False
        subscriptions = [(topics.color, "color", IMAGE, QOS_SENSOR_DATA),
                         (topics.depth, "depth", IMAGE, QOS_SENSOR_DATA),
                         (topics.camera_info, "camera_info", CAMERA_INFO, QOS_SENSOR_DATA)]
        if fixed_frame:
            subscriptions += [("/tf", "tf", TF_MESSAGE, QOS_TF),
                              ("/tf_static", "tf_static", TF_MESSAGE, QOS_TF_STATIC)]
        for name, stream, kind, qos in subscriptions:
            node.create_subscription(name, kind, type_hash(kind), self._feed(stream), qos)
        self.worker.start()

    def _feed(self, stream: str):
        def on_message(payload: bytes, _attachment: object) -> None:
            self.worker.put(stream, payload, None)
        return on_message

    def _on_sample(self, stream: str, payload: bytes, attachment: bytes | None) -> None:
        if stream == "camera_info":
            intrinsics = self._calibration(payload)
            if intrinsics is not None and intrinsics != self.assembler.calibration:
                log.info("camera calibration: %dx%d, fx %.1f fy %.1f cx %.1f cy %.1f",
                         intrinsics.width, intrinsics.height, intrinsics.fx, intrinsics.fy,
                         intrinsics.cx, intrinsics.cy)
                for frame in self.assembler.add_calibration(intrinsics):
                    self._publish(frame)
        elif stream in ("color", "depth"):
            self._on_image(stream, payload)
        else:
            self._on_transforms(payload, static=stream == "tf_static")

    def _calibration(self, payload: bytes) -> CameraIntrinsics | None:
        """The CameraInfo's intrinsics, or None when they cannot be a camera's: refused,
        counted, said once until a good one comes (a driver repeats it with every frame); the
        calibration in use stays."""
        from gngdt.io.ros2.messages import Ros2MessageError

        try:
            return decode_camera_info(payload).intrinsics
        except Ros2MessageError as error:
            self.counts.calibrations_refused += 1
            if self.assembler.refuse_calibration(str(error)):
                log.warning("%s: CameraInfo refused (%s); every CameraInfo refused is counted "
                            "in the status (camera/calibrations_refused)", self.topics.camera_info,
                            error)
            return None

    def _on_image(self, role: str, payload: bytes) -> None:
        from gngdt.io.ros2.messages import Ros2MessageError

        image = decode_image(payload, self.max_pixels)
        accepted = COLOR_ENCODINGS if role == "color" else DEPTH_ENCODINGS
        if image.encoding not in accepted:
            raise Ros2MessageError(f"{role} image encoding {image.encoding!r} is not one of "
                                   f"{', '.join(sorted(accepted))}")
        self._image_stamp_ns = image.stamp_ns
        if self.assembler.calibration is None:  # a driver sends CameraInfo with every frame
            self.counts.images_before_calibration += 1
            if self.counts.images_before_calibration == 1:
                log.info("images arrive; waiting for the first CameraInfo")
            return
        for frame in self.assembler.add_image(role, DecodedImage(image.stamp_ns, image.pixels,
                                                                 image.frame_id)):
            self._publish(frame)

    def _on_transforms(self, payload: bytes, static: bool) -> None:
        reference = self._image_stamp_ns
        for transform in decode_tf(payload):
            if (not static and reference is not None
                    and abs(transform.stamp_ns - reference) > TF_WINDOW_NS):
                self._far_off(1, f"transform {transform.parent!r} -> {transform.child!r} "
                              f"stamped {(transform.stamp_ns - reference) / 1e9:+.3g} s from "
                              "the latest image")
                continue
            try:
                self.transforms.add(transform.parent, transform.child, transform.stamp_ns,
                                    transform.translation, transform.rotation, static)
            except TransformError as error:
                self.counts.transforms_refused += 1
                if self.counts.transforms_refused <= WARN_FIRST:
                    log.warning("%s: %s; skipped", "/tf_static" if static else "/tf", error)
        if time.monotonic() - self._pruned_at > 1.0:
            self._prune(reference)
            self._pruned_at = time.monotonic()

    def _prune(self, reference: int | None) -> None:
        """Hold /tf over the window around the latest image (samples beyond it, taken before
        the first image, are counted as far off); before any image, each link over its own."""
        if reference is None:
            self.transforms.forget_stale(TF_WINDOW_NS)
            return
        far = self.transforms.forget_outside(-(2**63), reference + TF_WINDOW_NS)
        if far:
            self._far_off(far, f"{far} transform samples stamped over {TF_WINDOW_NS / 1e9:g} s "
                          "after the latest image")
        self.transforms.forget_outside(reference - TF_WINDOW_NS, 2**63 - 1)

    def _far_off(self, count: int, what: str) -> None:
        self.counts.transforms_far_off += count
        if self.counts.transforms_far_off <= WARN_FIRST:
            log.warning("/tf: %s ignored (another clock, or forged); counted in the status "
                        "(camera/transforms_far_off)", what)

    def _pose(self, camera_frame: str, stamp_ns: int,
              index: int) -> tuple[CameraPose | None, str | None]:
        """The camera's pose in the fixed frame at ``stamp_ns``, or why there is none."""
        assert self.fixed_frame is not None
        if not camera_frame:
            return None, "the images carry no frame_id"
        try:
            matrix = self.transforms.lookup(self.fixed_frame, camera_frame, stamp_ns)
        except TransformError as error:
            return None, str(error)
        return CameraPose(matrix, self.fixed_frame), None

    def _bad_frame(self, error: RecordingError) -> None:
        self.counts.bad_frames += 1
        if self.counts.bad_frames <= WARN_FIRST:
            log.warning("%s; skipped", error)

    def _publish(self, frame: Frame) -> None:
        """The frame on gngdt's topics: images, calibration when new, and its cloud unless a
        fixed frame is named and the frame has no pose in it."""
        now = time.time_ns()
        capture_time = frame.timestamp_ns
        if abs(now - capture_time) > MAX_CLOCK_OFFSET_NS:
            if not self._simulated_time:
                log.warning("image stamps are %.3g s from this clock (simulated time?): frames "
                            "are stamped with their arrival time", (capture_time - now) / 1e9)
                self._simulated_time = True
            capture_time = now
        cloud = None
        if frame.pose_error:
            self.counts.frames_without_pose += 1
            if self.counts.frames_without_pose <= WARN_FIRST:
                log.warning("frame %d has no pose in %r: %s; its images are published, not its "
                            "cloud", frame.index, self.fixed_frame, frame.pose_error)
        else:
            cloud, _ = cloud_of(frame, self.to_cloud, self.publisher.camera, capture_time)
        self.publisher.publish_frame(frame, FrameStamp(self._sequence, capture_time), None, None,
                                     cloud=cloud)
        self._sequence += 1
        self.counts.frames_published += 1

    def counts_for_status(self) -> dict[str, int]:
        values = {f"camera/{key}": value for key, value in asdict(self.counts).items()}
        values.update({f"camera/images/{key}": value
                       for key, value in asdict(self.worker.counts).items()})
        return values

    def idle(self) -> bool:
        return self.worker.idle()

    def close(self) -> None:
        self.worker.stop()
