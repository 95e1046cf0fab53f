"""Flow control between a capture reading a file and the camera's learner.

A file is read completely and repeatably: capture sends frame n+1 only once the learner has
acknowledged frame n (``gngdt/<cam>/learner/ack``, `gngdt.FrameAck`: learned, or not and why), so
every frame reaches the learner in order whatever the machine's load, and the same file with the
same seed gives the same network. Waits are bounded: no acknowledgement for ``stall_s`` seconds, or
the learner's liveliness token gone for that long, ends the replay with the reason (`LearnerLost`).
A learner that comes back (restarted, or a router between them restarted) takes the replay on from
the next frame; the frame it had when it went is counted lost. A live camera, or ``--realtime``, is
not paced: frames leave at their own pace and the learner takes the latest (docs/contracts.md "Flow
control").
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from typing import TYPE_CHECKING

from gngdt.schemas.wire import LEARNER, FrameStamp, alive_key, learner_instance_key, topic

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

#: how often a wait says what it waits for
PROGRESS_EVERY_S = 10.0


class LearnerLost(RuntimeError):
    """The learner stopped taking frames: it left, or took none for too long."""


class LearnerPacing:
    """The acknowledgements and liveliness of one camera's learner, heard on ``session``."""

    def __init__(self, session: zenoh.Session, camera: str, stall_s: float) -> None:
        if not stall_s > 0:
            raise ValueError(f"--learner-timeout must be positive, got {stall_s}")
        self.camera = camera
        self.stall_s = stall_s
        self._changed = threading.Condition()
        #: the highest frame sequence acknowledged so far (-1: none)
        self.acknowledged = -1
        #: acknowledgements by outcome ("learned", "pose rejected", ...)
        self.outcomes: Counter[str] = Counter()
        self.learner_up = False
        #: learners that went away while they had a frame, so the frame went with them
        self.frames_lost = 0
        self._comings = 0  # how many times the learner's token appeared
        #: learners of the camera that announced themselves (their instance token): they are
        #: starting (compiling their kernels) until their liveliness token comes
        self._instances: set[str] = set()
        self._subscribers = [
            session.declare_subscriber(topic(camera, "learner/ack"), self._on_ack),
            session.liveliness().declare_subscriber(alive_key(camera, LEARNER), self._on_token,
                                                    history=True),
            session.liveliness().declare_subscriber(learner_instance_key(camera),
                                                    self._on_instance, history=True),
        ]

    def _on_ack(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.status import decode_frame_ack

        try:
            stamp = FrameStamp.from_attachment(
                None if sample.attachment is None else sample.attachment.to_bytes())
            outcome = decode_frame_ack(sample.payload.to_bytes()).outcome
        except ValueError as error:  # MessageError is a ValueError
            log.warning("malformed acknowledgement skipped: %s", error)
            return
        with self._changed:
            self.acknowledged = max(self.acknowledged, stamp.sequence)
            self.outcomes[outcome] += 1
            self._changed.notify_all()

    def _on_token(self, sample: zenoh.Sample) -> None:
        import zenoh

        with self._changed:
            self.learner_up = sample.kind == zenoh.SampleKind.PUT
            self._comings += self.learner_up
            self._changed.notify_all()

    def _on_instance(self, sample: zenoh.Sample) -> None:
        import zenoh

        with self._changed:
            if sample.kind == zenoh.SampleKind.PUT:
                self._instances.add(str(sample.key_expr))
            else:
                self._instances.discard(str(sample.key_expr))
            self._changed.notify_all()

    def wait_for_learner(self, timeout_s: float, stop: threading.Event) -> bool:
        """Wait up to ``timeout_s`` for the camera's learner to be up (its liveliness token),
        and past it as long as a learner of the camera is starting (its instance token is
        there: it compiles its kernels); whether it is up. Says every `PROGRESS_EVERY_S` what
        it waits for."""
        started = time.monotonic()
        deadline = started + timeout_s
        said = started
        with self._changed:
            while not self.learner_up and not stop.is_set():
                now = time.monotonic()
                if now >= deadline and not self._instances:
                    break
                if now - said >= PROGRESS_EVERY_S:
                    log.info("%s (%.0f s so far)", self._waiting_for(deadline - now),
                             now - started)
                    said = now
                self._changed.wait(0.5 if self._instances else min(0.5, deadline - now))
            return self.learner_up

    def _waiting_for(self, left_s: float) -> str:
        """What `wait_for_learner` waits for, in words."""
        if self._instances:
            return (f"waiting for the learner of camera {self.camera!r}: it is starting "
                    "(compiling its kernels; its first run on a machine takes minutes on a busy "
                    "one), and the file is sent once it takes frames")
        return (f"waiting for a learner of camera {self.camera!r} (`gngdt learn --cam "
                f"{self.camera}`), {left_s:.0f} s more (--wait-learner)")

    def wait_taken(self, sequence: int, stop: threading.Event) -> None:
        """Wait until the learner acknowledged frame ``sequence`` (or a stop signal), or came
        back after going away with it (the frame is counted lost); raises `LearnerLost` when
        it acknowledged nothing for ``stall_s``, gone or not."""
        started = time.monotonic()
        comings = self._comings
        with self._changed:
            while self.acknowledged < sequence and not stop.is_set():
                if self._comings > comings and self.learner_up:
                    self.frames_lost += 1
                    log.warning("the learner of camera %r came back; frame %d went with the "
                                "one before it", self.camera, sequence)
                    return
                waited = time.monotonic() - started
                if waited >= self.stall_s:
                    raise LearnerLost(self._stalled(sequence, waited))
                self._changed.wait(min(0.5, self.stall_s - waited))

    def _stalled(self, sequence: int, waited: float) -> str:
        if not self.learner_up:
            return (f"the learner of camera {self.camera!r} left (its liveliness token is gone) "
                    f"and did not come back within {waited:.0f} s (frame {sequence} went with "
                    "it; --learner-timeout)")
        return (f"the learner of camera {self.camera!r} took no frame for {waited:.0f} s "
                f"(frame {sequence} was sent; --learner-timeout)")

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()
