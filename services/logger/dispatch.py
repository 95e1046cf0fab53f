"""Every sample the logger takes from its inbox: checked, counted, handed to its outputs."""

from __future__ import annotations

import logging
import time

from gngdt.io.outputs import Output, StreamSample, split_key
from gngdt.schemas.wire import FrameStamp
from gngdt.services.logger.cameras import Cameras
from gngdt.services.logger.inbox import LOGGED_STREAMS

log = logging.getLogger(__name__)

#: streams an output may thin: asked whether it wants a frame before the payload is copied
THINNED_STREAMS = ("color", "depth", "points")


class Dispatcher:
    """Hands each valid sample to every (non-raw) output; malformed ones are counted, skipped.

    A sample must carry a valid frame stamp (`FrameStamp`) with a plausible capture time, and
    decode in every output; a camera becomes known only with a valid sample (or its capture's
    liveliness token), so garbage on made-up camera names makes no camera.
    """

    def __init__(self, outputs: list[Output], cameras: Cameras) -> None:
        self.outputs = [output for output in outputs if not output.raw]
        self.cameras = cameras
        self.malformed = 0

    def handle(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        parts = split_key(key)
        if parts is None or parts[1] not in LOGGED_STREAMS:
            return
        camera, stream = parts
        new_camera = camera not in self.cameras
        if new_camera and not self.cameras.admit(camera):
            return
        try:
            stamp = FrameStamp.from_attachment(attachment)
            stamp.check_clock(time.time_ns())
            if new_camera:
                self.cameras.add(camera)
            sample = StreamSample(camera, stream, stamp, payload)
            self.cameras.note(sample)
            for output in self.outputs:
                output.write(sample)
        except (ValueError, OverflowError) as error:  # MessageError is a ValueError
            if new_camera:  # a camera is made by a valid message, not by garbage
                self.cameras.progress.pop(camera, None)
            self.malformed += 1
            log.warning("%s: malformed message skipped: %s", key, error)
            return
        if new_camera:
            self.cameras_changed()

    def wants(self, key: str, attachment: bytes | None) -> bool:
        """Whether an image or cloud is wanted by an output, before its payload is copied (on
        zenoh's thread; anything undecidable is wanted, and checked in `handle`)."""
        parts = split_key(key)
        if parts is None or parts[1] not in THINNED_STREAMS:
            return True
        try:
            sequence = FrameStamp.from_attachment(attachment).sequence
        except (ValueError, OverflowError):
            return True
        return any(output.wants(parts[0], parts[1], sequence) for output in self.outputs)

    def capture_seen(self, camera: str, alive: bool) -> None:
        """A capture of ``camera`` started (``alive``) or left."""
        if self.cameras.capture_seen(camera, alive):
            self.cameras_changed()

    def cameras_changed(self) -> None:
        for output in self.outputs:
            output.cameras_changed(self.cameras.names())
