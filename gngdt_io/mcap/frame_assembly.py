"""Frames out of decoded images: colour and depth paired by stamp, the latest calibration and
matching labels attached, sizes checked, the camera pose looked up; within the held-bytes limit."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.errors import RecordingError
from gngdt.io.frame import Frame
from gngdt.io.images import CameraParameters
from gngdt.io.mcap.decoding import normalize_color, normalize_depth
from gngdt.io.mcap.limits import ReadLimits
from gngdt.io.mcap.poses import PoseLookup

__all__ = ["BadFrameHandler", "DecodedImage", "FrameAssembler"]

logger = logging.getLogger(__name__)

#: Unpaired colour or depth images kept while waiting for their partner.
MAX_PENDING_IMAGES = 32
MAX_FRAMES_WITHOUT_CALIBRATION = 64


@dataclass
class DecodedImage:
    """A decoded image: colour (H, W, 3) uint8 RGB, depth (H, W) uint16 mm or labels (H, W)."""

    stamp_ns: int
    pixels: np.ndarray
    frame_id: str = ""


#: receives each bad frame's error when the caller chose to skip bad frames
BadFrameHandler = Callable[[RecordingError], None]


class CameraRefused(RecordingError):
    """The camera the user gave (--camera-json) cannot be this recording's: it ends the
    reading, as no frame can be read with it."""


class FrameAssembler:
    """Pairs colour and depth, attaches calibration and labels, and checks sizes."""

    def __init__(
        self,
        path: Path,
        intrinsics: CameraIntrinsics | None,
        max_skew_ns: int,
        on_bad_frame: BadFrameHandler | None = None,
        poses: PoseLookup | None = None,
        max_held_bytes: int = ReadLimits.max_held_bytes,
        camera: CameraParameters | None = None,
        depth_scale: float | None = None,
    ) -> None:
        self.path = path
        #: the user's camera (--camera-json): its intrinsics replace the recording's calibration
        self.camera = camera
        #: units per metre of the recording's 16-bit depth (--depth-scale, or the camera's);
        #: None: millimetres
        self.depth_scale = depth_scale or (None if camera is None else camera.depth_scale)
        self.poses = poses
        self.max_held_bytes = max_held_bytes
        self.on_bad_frame = on_bad_frame
        self.calibration = intrinsics
        self.max_skew_ns = max_skew_ns
        self.pending: dict[str, deque[DecodedImage]] = {
            "color": deque(maxlen=MAX_PENDING_IMAGES),
            "depth": deque(maxlen=MAX_PENDING_IMAGES),
        }
        self.labels: deque[DecodedImage] = deque(maxlen=MAX_PENDING_IMAGES)
        self.awaiting_calibration: list[tuple[DecodedImage, DecodedImage, np.ndarray | None]] = []
        self.next_index = 0
        #: calibration messages refused (not a camera's), and why the latest was
        self.calibrations_refused = 0
        self.refused_calibration = ""

    def error(self, reason: str) -> RecordingError:
        return RecordingError(self.path, self.next_index, reason)

    def skip_or_raise(self, error: RecordingError) -> None:
        """Report a bad frame to ``on_bad_frame`` (reading goes on), or raise it."""
        if self.on_bad_frame is None:
            raise error
        self.on_bad_frame(error)

    def refuse_calibration(self, reason: str) -> bool:
        """Note a calibration message that cannot be a camera's (nothing is deprojected with
        it): counted, and named if frames end up without a calibration. True when it is to be
        said: the first refusal since the last good calibration (a driver or a bag repeats
        its CameraInfo with every frame)."""
        self.calibrations_refused += 1
        first = not self.refused_calibration
        self.refused_calibration = reason
        return first

    def add_calibration(self, intrinsics: CameraIntrinsics) -> Iterator[Frame]:
        if self.camera is not None:
            return  # the user's intrinsics win over the recording's
        self.calibration = intrinsics
        self.refused_calibration = ""
        held, self.awaiting_calibration = self.awaiting_calibration, []
        for color, depth, labels in held:
            yield from self._checked_frame(color, depth, labels)

    def add_labels(self, image: DecodedImage) -> None:
        self._make_room(image.pixels.nbytes)
        self.labels.append(image)

    def held_bytes(self) -> int:
        """Bytes of the images held: unpaired, and frames waiting for a calibration."""
        waiting = [image for queue in (*self.pending.values(), self.labels) for image in queue]
        held = sum(image.pixels.nbytes for image in waiting)
        for color, depth, labels in self.awaiting_calibration:
            held += color.pixels.nbytes + depth.pixels.nbytes
            held += 0 if labels is None else labels.nbytes
        return held

    def _make_room(self, nbytes: int) -> None:
        """Drop the oldest unpaired images until ``nbytes`` more fit in ``max_held_bytes``."""
        held = self.held_bytes()
        queues = [*self.pending.values(), self.labels]
        while held + nbytes > self.max_held_bytes and any(queues):
            oldest = min((queue for queue in queues if queue), key=lambda q: q[0].stamp_ns)
            dropped = oldest.popleft()
            held -= dropped.pixels.nbytes
            logger.debug("%s: dropping unpaired image at %d ns (--max-pending-mb)", self.path,
                         dropped.stamp_ns)

    def add_image(self, role: str, image: DecodedImage) -> Iterator[Frame]:
        other = self.pending["depth" if role == "color" else "color"]
        partner = min(other, key=lambda item: abs(item.stamp_ns - image.stamp_ns), default=None)
        if partner is None or abs(partner.stamp_ns - image.stamp_ns) > self.max_skew_ns:
            self._make_room(image.pixels.nbytes)
            self.pending[role].append(image)
            return
        while other[0] is not partner:  # older unpaired images can no longer pair: drop them
            logger.debug(
                "%s: dropping unpaired image at %d ns", self.path, other.popleft().stamp_ns
            )
        other.popleft()
        # and those of this role: a later image of the other role is no older than the partner
        same = self.pending[role]
        while same and same[0].stamp_ns < partner.stamp_ns - self.max_skew_ns:
            logger.debug("%s: dropping unpaired image at %d ns", self.path, same.popleft().stamp_ns)
        color, depth = (image, partner) if role == "color" else (partner, image)
        labels = next(
            (item.pixels for item in self.labels if item.stamp_ns == color.stamp_ns), None
        )
        if self.calibration is None and self.camera is None:
            frame_bytes = color.pixels.nbytes + depth.pixels.nbytes
            frame_bytes += 0 if labels is None else labels.nbytes
            if (len(self.awaiting_calibration) >= MAX_FRAMES_WITHOUT_CALIBRATION
                    or self.held_bytes() + frame_bytes > self.max_held_bytes):
                raise self.error(
                    f"no calibration channel (CameraCalibration/CameraInfo) in the first "
                    f"{len(self.awaiting_calibration) + 1} frames (at most "
                    f"{MAX_FRAMES_WITHOUT_CALIBRATION} frames or {self.max_held_bytes >> 20} "
                    f"MB are held waiting for one, --max-pending-mb){self._refusal_note()}"
                )
            self.awaiting_calibration.append((color, depth, labels))
            return
        yield from self._checked_frame(color, depth, labels)

    def finish(self) -> None:
        if self.awaiting_calibration:
            raise RecordingError(
                self.path, 0, "no calibration (foxglove CameraCalibration or ROS CameraInfo) "
                f"found{self._refusal_note()}"
            )

    def _refusal_note(self) -> str:
        if not self.calibrations_refused:
            return ""
        return (f"; {self.calibrations_refused} calibration messages were refused, the latest "
                f"because {self.refused_calibration}")

    def _checked_frame(
        self, color: DecodedImage, depth: DecodedImage, labels: np.ndarray | None
    ) -> Iterator[Frame]:
        """The frame, or nothing when it is bad and bad frames are skipped (index still used)."""
        try:
            yield self._frame(color, depth, labels)
        except CameraRefused:
            raise  # the user's camera: every frame would be refused, not one bad frame
        except RecordingError as error:
            self.next_index += 1
            self.skip_or_raise(error)

    def _intrinsics(self, width: int, height: int) -> CameraIntrinsics:
        if self.camera is not None:
            try:
                return self.camera.intrinsics(width, height)
            except ValueError as error:
                raise CameraRefused(self.path, self.next_index,
                                    f"--camera-json refused: {error}") from None
        assert self.calibration is not None
        return self.calibration

    def _frame(self, color: DecodedImage, depth: DecodedImage, labels: np.ndarray | None) -> Frame:
        color_pixels = normalize_color(color.pixels)
        height, width = color_pixels.shape[:2]
        intrinsics = self._intrinsics(width, height)
        if depth.pixels.shape != (height, width):
            depth_height, depth_width = depth.pixels.shape[:2]
            raise self.error(
                f"depth {depth_width}x{depth_height} does not match colour {width}x{height}"
            )
        if labels is not None and labels.shape != (height, width):
            raise self.error(
                f"labels {labels.shape[1]}x{labels.shape[0]} do not match colour {width}x{height}"
            )
        if (intrinsics.width, intrinsics.height) != (width, height):
            raise self.error(
                f"calibration is for {intrinsics.width}x{intrinsics.height}, "
                f"colour is {width}x{height}"
            )
        pose, pose_error = None, None
        if self.poses is not None:
            pose, pose_error = self.poses(
                color.frame_id or depth.frame_id, color.stamp_ns, self.next_index
            )
        frame = Frame(
            index=self.next_index,
            timestamp_ns=color.stamp_ns,
            color=color_pixels,
            depth=normalize_depth(depth.pixels, self.depth_scale),
            intrinsics=intrinsics,
            labels=None if labels is None else labels.astype(np.uint16, copy=False),
            pose=pose,
            pose_error=pose_error or "",
        )
        self.next_index += 1
        return frame
