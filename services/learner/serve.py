"""The learner on zenoh: subscribe to a camera's clouds, learn each through the `FrameLearner`,
publish what it learned, answer late joiners, checkpoint, stop at the stream's end when asked.

Latest frame wins: the points subscriber keeps only the newest cloud (a zenoh ring channel of
size 1), so when learning falls behind, stale frames are dropped (counted from sequence gaps) and
memory stays bounded. With ``frame_time_share`` > 0 (off by default) each frame gets the
learning steps that fit in that share of the time between frames, and what was learned is
published less often when publishing would not fit (`gngdt.core.learner.frame_budget`; the status
reports the budget). Objects and
scene are published latest-wins (congestion control DROP): a consumer that cannot keep up misses
updates, and never slows the learner down. With ``--track`` the learner also reads the camera's
calibration, and publishes each tracked cloud's camera pose on ``gngdt/<cam>/tf``.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gngdt.core.learner.frame_budget import StepBudget
from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig
from gngdt.core.learner.results import Counters, FrameResult, Outcome, Publication
from gngdt.schemas.wire import (
    ENCODING_FRAME_TRANSFORM,
    ENCODING_SCENE_UPDATE,
    ENCODING_STATUS,
    ENCODING_TOPOLOGY,
    LEARNER,
    FrameStamp,
    alive_key,
    learner_instance_key,
    topic,
)
from gngdt.services.learner import checkpoints
from gngdt.services.learner.messages import (
    decode_points,
    objects_message,
    scene_message,
    status_message,
    topology_message,
)
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.session import declare_publisher, through_shared_memory

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

#: bytes a stream-end message may take (a real one is under 200)
MAX_EOS_BYTES = 64 * 1024
#: bytes per point a foreign cloud layout may use (gngdt's own uses 15)
MAX_POINT_STRIDE_BYTES = 64
#: bytes a calibration message may take (a real one is under 500)
MAX_CALIBRATION_BYTES = 64 * 1024


class LatencyWindow:
    """The last ``size`` frame-to-topology latencies (ms), for p50/p99."""

    def __init__(self, size: int = 1000) -> None:
        self._values: deque[float] = deque(maxlen=size)

    def add(self, latency_ms: float) -> None:
        self._values.append(latency_ms)

    def percentile(self, q: float) -> float:
        return float(np.percentile(np.fromiter(self._values, float), q)) if self._values else 0.0


class EndOfStream:
    """Remembers the last end-of-stream announced on the camera (set from zenoh's thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.last_sequence: int | None = None
        self.received_at = 0.0

    def set(self, last_sequence: int) -> None:
        with self._lock:
            self.last_sequence = last_sequence
            self.received_at = time.monotonic()

    def finished(self, learned_sequence: int, drain_seconds: float = 5.0) -> bool:
        """True once the last frame was learned, or ``drain_seconds`` after eos without it."""
        with self._lock:
            if self.last_sequence is None:
                return False
            return (learned_sequence >= self.last_sequence
                    or time.monotonic() - self.received_at > drain_seconds)


class LatestTopology:
    """The latest encoded topology and its attachment, served to late joiners."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._payload: bytes | None = None
        self._attachment: bytes | None = None

    def set(self, payload: bytes, attachment: bytes) -> None:
        with self._lock:
            self._payload, self._attachment = payload, attachment

    def reply(self, query: zenoh.Query) -> None:
        with self._lock:
            payload, attachment = self._payload, self._attachment
        if payload is not None:
            query.reply(query.key_expr, payload, encoding=ENCODING_TOPOLOGY, attachment=attachment)


class DuplicateLearnerError(ValueError):
    """Another learner already learns this camera."""


class LearnerInstances:
    """Every learner announces itself on ``gngdt/<cam>/learner/instance/<zenoh id>``; two on one
    camera would interleave their topologies, so a second one refuses to start, and of two that
    start at the same moment the one with the larger id stops."""

    def __init__(self, session: zenoh.Session, camera: str) -> None:
        self.camera = camera
        self.own_id = str(session.zid())
        self.conflict = threading.Event()
        self.other_id = ""
        others = [str(reply.ok.key_expr).rsplit("/", 1)[-1]
                  for reply in session.liveliness().get(learner_instance_key(camera), timeout=2.0)
                  if reply.ok is not None]
        if others:
            raise DuplicateLearnerError(
                f"another learner (zenoh id {others[0]}) already learns camera {camera!r}; "
                "stop it, or give this one another --cam")
        self._token = session.liveliness().declare_token(learner_instance_key(camera, self.own_id))
        self._subscriber = session.liveliness().declare_subscriber(
            learner_instance_key(camera), self._on_token, history=True)

    def _on_token(self, sample: zenoh.Sample) -> None:
        import zenoh

        other = str(sample.key_expr).rsplit("/", 1)[-1]
        if other == self.own_id or sample.kind != zenoh.SampleKind.PUT:
            return
        log.error("a second learner (zenoh id %s) learns camera %r too: their topologies "
                  "would interleave", other, self.camera)
        if other < self.own_id:
            self.other_id = other
            self.conflict.set()

    def close(self) -> None:
        self._subscriber.undeclare()
        self._token.undeclare()


def result_count(counters: Counters, result: FrameResult) -> int:
    """How many clouds have met ``result``'s outcome so far."""
    return {Outcome.LOST_TRACKING: counters.frames_lost_tracking,
            Outcome.POSE_REJECTED: counters.frames_pose_rejected,
            Outcome.OTHER_FRAME: counters.frames_other_frame}[result.outcome]


def payload_bytes(sample: zenoh.Sample, limit: int) -> bytes:
    """The sample's payload, refused (``MessageError``) before any copy when over ``limit``."""
    from gngdt.schemas.messages import MessageError

    size = len(sample.payload)
    if size > limit:
        raise MessageError(f"{size} bytes, more than the limit of {limit}")
    return sample.payload.to_bytes()


def attachment_bytes(sample: zenoh.Sample) -> bytes | None:
    attachment = sample.attachment
    if attachment is None or len(attachment) > 64:
        return None
    return attachment.to_bytes()


class LatestCalibration:
    """The camera's latest intrinsics (set from zenoh's thread), for tracking. A calibration
    that is malformed or cannot be a camera's is counted as malformed and never used (the one
    in use stays); it is said once until a good one comes."""

    def __init__(self, learner: FrameLearner) -> None:
        self.learner = learner
        self.intrinsics = None
        self._refusal_said = False

    def on_sample(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.images import calibration_to_intrinsics
        from gngdt.schemas.messages import MessageError

        try:
            self.intrinsics = calibration_to_intrinsics(
                payload_bytes(sample, MAX_CALIBRATION_BYTES))
            self._refusal_said = False
        except (MessageError, ValueError) as error:
            self.learner.counters.malformed_messages += 1
            if not self._refusal_said:
                log.warning("calibration refused, not used: %s (each one refused is counted "
                            "as malformed)", error)
                self._refusal_said = True


#: a cloud not learned is warned about the first time, then every this many of its kind
WARN_EVERY = {Outcome.LOST_TRACKING: 30, Outcome.POSE_REJECTED: 100, Outcome.OTHER_FRAME: 100}
WARNINGS = {Outcome.LOST_TRACKING: "camera not tracked, frame not learned",
            Outcome.POSE_REJECTED: "points message skipped",
            Outcome.OTHER_FRAME: "points message skipped"}


def warn_not_learned(result: FrameResult, count: int) -> None:
    """Warn about a cloud that was not learned (counted in the status): the first of its kind,
    then every `WARN_EVERY`th."""
    if count == 1 or count % WARN_EVERY[result.outcome] == 0:
        log.warning("%s (%d so far): %s", WARNINGS[result.outcome], count, result.problem)


class LearnerService:
    """One camera's learner on a zenoh session: its subscribers, publishers and queryable."""

    def __init__(self, session: zenoh.Session, camera: str, config: LearnerConfig,
                 learner: FrameLearner, checkpoint: Path | None = None,
                 pool_bytes: int | None = None) -> None:
        import zenoh

        self.camera = camera
        self.options = config.options
        self.learner = learner
        self.checkpoint = checkpoint
        self.end = EndOfStream()
        self.latest = LatestTopology()
        self.latencies = LatencyWindow()
        self.instances = LearnerInstances(session, camera)
        self.points = session.declare_subscriber(topic(camera, "points"),
                                                 zenoh.handlers.RingChannel(1))
        self._eos = session.declare_subscriber(topic(camera, "eos"), self._on_eos)
        self._topology = declare_publisher(session, topic(camera, "topology"),
                                           ENCODING_TOPOLOGY, latest_wins=True,
                                           pool_bytes=pool_bytes)
        self._status = declare_publisher(session, topic(camera, "learner/status"),
                                         ENCODING_STATUS, latest_wins=False)
        # latest-wins views: a consumer that never reads must not hold the learner back
        self._objects = declare_publisher(session, topic(camera, "objects"),
                                          ENCODING_SCENE_UPDATE, latest_wins=True,
                                          pool_bytes=pool_bytes)
        self._scene = declare_publisher(session, topic(camera, "scene"),
                                        ENCODING_SCENE_UPDATE, latest_wins=True,
                                        pool_bytes=pool_bytes)
        self._queryable = session.declare_queryable(topic(camera, "topology"), self.latest.reply)
        self._token = session.liveliness().declare_token(alive_key(camera, LEARNER))
        options = self.options
        self.budget = StepBudget(options.frame_time_share,
                                 min(options.min_samples_per_frame, options.samples_per_frame),
                                 options.samples_per_frame)
        self.calibration = LatestCalibration(learner)
        self._tracking: list = []  # the calibration subscriber and tf publisher (--track)
        if learner.tracking is not None:
            self._tracking = [
                session.declare_subscriber(topic(camera, "calibration"),
                                           self.calibration.on_sample),
                declare_publisher(session, topic(camera, "tf"), ENCODING_FRAME_TRANSFORM,
                                  latest_wins=False)]
        #: the last publication (its errors and cluster counts go into every status)
        self._published: Publication | None = None
        self._max_cloud_bytes = self.options.max_points * MAX_POINT_STRIDE_BYTES + 64 * 1024
        #: the last learned frame (stamp, positions, colours), kept to settle on at the end
        self.last_frame: tuple[FrameStamp, np.ndarray, np.ndarray | None] | None = None
        #: the last learned frame was not published yet (the budget put it off)
        self._unpublished = False
        self.learned_sequence = -1
        self._settled_end = 0.0  # the end of stream (its arrival time) already settled on
        self._frames_since_checkpoint = 0
        self._last_checkpoint = time.monotonic()
        #: clouds whose payload arrived through shared memory (a diagnostic, logged at the end)
        self.clouds_shared = 0

    def _on_eos(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.messages import MessageError
        from gngdt.schemas.status import decode_stream_end

        try:
            end = decode_stream_end(payload_bytes(sample, MAX_EOS_BYTES))
        except MessageError as error:
            self.learner.counters.malformed_messages += 1
            log.warning("malformed end-of-stream skipped: %s", error)
            return
        self.end.set(end.last_frame_sequence)

    def publish(self, stamp: FrameStamp, positions: np.ndarray, colors: np.ndarray | None,
                settled: str = "") -> float:
        """Publish the topology after learning a frame, its objects, (every
        ``scene_every_frames`` frames, and the settled last one) the scene, then the status;
        the latency in ms."""
        published = self.learner.publication(positions, colors, final=bool(settled))
        payload = topology_message(published, stamp).SerializeToString()
        attachment = stamp.to_attachment()
        latency_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        self._topology.put(payload, attachment=attachment)
        self.latest.set(payload, attachment)
        self._objects.put(objects_message(published, stamp).SerializeToString(),
                          attachment=attachment)
        every = self.options.scene_every_frames
        if every and (settled or published.figures.counters.frames_used % every == 1 % every):
            scene = scene_message(published, stamp)
            self._scene.put(scene.SerializeToString(), attachment=attachment)
        # the status last: a consumer that ends on the settled status has everything before it
        percentiles = (self.latencies.percentile(50), self.latencies.percentile(99))
        self._published = published
        status = status_message(published.figures, stamp, latency_ms, percentiles, published,
                                settled, self.budget.last)
        self._status.put(status.SerializeToString(), attachment=attachment)
        return latency_ms

    def handle(self, sample: zenoh.Sample, waited: bool = False) -> None:
        """Decode, learn and (when due) publish one points sample; a bad one is counted and
        skipped. ``waited``: the learner was idle until it came (it keeps up)."""
        started = time.perf_counter()
        learner = self.learner
        counters = learner.counters
        counters.frames_received += 1
        self.clouds_shared += through_shared_memory(sample)
        try:
            stamp, positions, colors, frame_id, pose = decode_points(
                payload_bytes(sample, self._max_cloud_bytes), attachment_bytes(sample),
                self.options.max_points)
            counters.note_sequence(stamp.sequence)
            received_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
            self.budget.arrived(stamp.sequence, stamp.capture_time_ns, waited)
            learning_before = counters.learning_seconds
            result = learner.learn(positions, colors, frame_id, pose, stamp.capture_time_ns,
                                   steps=self.budget.next().steps,
                                   camera=self.calibration.intrinsics)
        except ValueError as error:  # MessageError is a ValueError
            counters.malformed_messages += 1
            log.warning("points message skipped: %s", error)
            return
        if not result.learned:  # counted by the learner; the status says why
            warn_not_learned(result, result_count(counters, result))
            if result.outcome is not Outcome.OTHER_FRAME:
                self._publish_status(stamp)
            return
        if result.tracked:
            self._publish_pose(stamp, frame_id, result)
        learned_at = time.perf_counter()
        self.budget.learned(learner.last_steps, counters.learning_seconds - learning_before,
                            learned_at - started)
        self.last_frame = (stamp, positions, colors)
        self.learned_sequence = stamp.sequence
        self._unpublished = True
        if self.budget.publish_due(learned_at):
            latency_ms = self.publish_learned(learned_at)
            log.debug("frame %d: %d points, received after %.1f ms, topology after %.1f ms",
                      stamp.sequence, len(positions), received_ms, latency_ms)
        self._checkpoint_if_due()

    def publish_learned(self, now: float | None = None) -> float:
        """Publish the last learned frame (learned at ``now``, `time.perf_counter`; default
        now) and count the time it took in the budget; the latency in ms."""
        now = time.perf_counter() if now is None else now
        latency_ms = self.publish(*self.last_frame)
        self.budget.published(time.perf_counter() - now, now)
        self.latencies.add(latency_ms)
        self._unpublished = False
        return latency_ms

    def _publish_pose(self, stamp: FrameStamp, camera_frame: str, result: FrameResult) -> None:
        """The tracked camera's pose: ``odom`` -> the cloud's (camera) frame."""
        from gngdt.schemas.clouds import pose_to_transform

        transform = pose_to_transform(result.pose, result.frame_id, camera_frame,
                                      timestamp_ns=stamp.capture_time_ns)
        self._tracking[1].put(transform.SerializeToString(), attachment=stamp.to_attachment())

    def _publish_status(self, stamp: FrameStamp) -> None:
        """A status without a new topology (a frame that was not learned)."""
        latency_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        percentiles = (self.latencies.percentile(50), self.latencies.percentile(99))
        status = status_message(self.learner.figures(), stamp, latency_ms, percentiles,
                                self._published, "", self.budget.last)
        self._status.put(status.SerializeToString(), attachment=stamp.to_attachment())

    def _checkpoint_if_due(self) -> None:
        self._frames_since_checkpoint += 1
        if self.checkpoint is not None and (
            self._frames_since_checkpoint >= self.options.checkpoint_every_frames
            or time.monotonic() - self._last_checkpoint >= self.options.checkpoint_every_seconds
        ):
            checkpoints.save(self.learner, self.checkpoint)
            self._frames_since_checkpoint, self._last_checkpoint = 0, time.monotonic()

    def stream_over(self) -> bool:
        """Whether the stream ended and its last frame was learned; the first time, settle on
        that frame and publish the final network."""
        if not self.end.finished(self.learned_sequence):
            return False
        if self.last_frame is not None and self.end.received_at != self._settled_end:
            stamp, positions, colors = self.last_frame
            self.publish(stamp, positions, colors,
                         settled=self.learner.settle(positions, colors))
            self._settled_end = self.end.received_at
        return True

    def run(self, exit_on_eos: bool) -> int:
        """Learn until a stop signal, the stream's end (``exit_on_eos``) or a second learner on
        the camera; the exit code."""
        with lifecycle.graceful() as stop:
            waited = False  # idle since the last frame: the learner keeps up
            while not stop.is_set():
                if self.instances.conflict.is_set():
                    log.error("stopping: learner %s came first on camera %r",
                              self.instances.other_id, self.camera)
                    return 2
                sample = self.points.try_recv()
                if sample is not None:
                    self.handle(sample, waited)
                    waited = False
                    continue
                waited = True
                if self._unpublished:  # idle: what it learned is not left unpublished
                    self.publish_learned()
                    continue
                if self.stream_over() and exit_on_eos:
                    break
                time.sleep(0.002)
        return 0

    def close(self) -> None:
        """Save the last checkpoint and undeclare everything (the session stays open)."""
        if self.checkpoint is not None and self.learner.counters.frames_used > 0:
            checkpoints.save(self.learner, self.checkpoint)
        self._token.undeclare()
        self.instances.close()
        for entity in (self._queryable, self._eos, self.points, self._topology, self._status,
                       self._objects, self._scene, *self._tracking):
            entity.undeclare()
        if self.learner.counters.frames_received:
            log.info("%d of %d clouds arrived through shared memory", self.clouds_shared,
                     self.learner.counters.frames_received)


def serve(args: argparse.Namespace, config: LearnerConfig, learner: FrameLearner,
          session: zenoh.Session) -> int:
    """Learn on ``session`` until stopped; checkpoint on the way out."""
    service = LearnerService(session, args.cam, config, learner, args.checkpoint,
                             args.environment.shm_pool_bytes)
    log.info("learning from %s (%d steps per frame)", topic(args.cam, "points"),
             config.options.samples_per_frame)
    try:
        exit_code = service.run(args.exit_on_eos)
    finally:
        service.close()
    counters = learner.counters
    model = learner.model
    log.info("learned %d frames (%d dropped, %d malformed), %d nodes, %d steps",
             counters.frames_used, counters.frames_dropped, counters.malformed_messages,
             model.n_nodes_ if model else 0, model.n_steps_ if model else 0)
    return exit_code


def warm_up(config: LearnerConfig) -> None:
    """Compile (or load from numba's cache) every kernel the learner uses and encode each
    message once, before the first frame, logging each step (`gngdt run` shows them)."""
    from gngdt.core.learner.warm_up import logged_progress, sample_frame, warm_up_learner

    learner = warm_up_learner(config, logged_progress(log))
    positions, colors, _ = sample_frame()
    published = learner.publication(positions, colors)
    stamp = FrameStamp(0, 1)
    topology_message(published, stamp)
    objects_message(published, stamp)
    scene_message(published, stamp)
    status_message(published.figures, stamp, 0.0, (0.0, 0.0), published)
