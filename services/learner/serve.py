"""The learner on zenoh: subscribe to a camera's clouds, learn each through the `FrameLearner`,
publish what it learned, answer late joiners, checkpoint, stop at the stream's end when asked.

Latest frame wins: the points subscriber keeps only the newest cloud (a `FrameQueue` of one), so
when learning falls behind, stale frames are dropped (counted from sequence gaps) and memory stays
bounded; a capture reading a file sends one frame at a time, each once the learner
acknowledged the one before (``learner/ack``). With ``--track`` every frame is posed as it arrives,
in the tracker's own thread (`gngdt.services.learner.tracking`), and the learner learns the frames
that add most to the map. What was learned is published at most every ``publish_every_s`` of
the stream's own clock (the frames' stamps choose which), and the stream's last frame settled.
With ``frame_time_share`` > 0 (off by default) each frame gets the
learning steps that fit in that share of the time between frames, and what was learned is published
less often when publishing would not fit (`gngdt.core.learner.frame_budget`; the status reports the
budget). Objects and scene are published latest-wins (congestion control DROP): a consumer that
cannot keep up misses updates, and never slows the learner down. With ``--track`` the learner also
reads the camera's calibration, and publishes each tracked cloud's camera pose on
``gngdt/<cam>/tf``.
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
from gngdt.core.learner.keyframes import choose_keyframe
from gngdt.core.learner.results import Counters, FrameResult, Outcome, Publication
from gngdt.schemas.wire import (
    ENCODING_FRAME_ACK,
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
from gngdt.services.learner.inbound import (
    MAX_EOS_BYTES,
    Arrival,
    EndOfStream,
    LatestCalibration,
    Received,
    arrive,
    payload_bytes,
)
from gngdt.services.learner.messages import (
    PointsMessage,
    decode_points,
    objects_message,
    scene_message,
    status_message,
    topology_message,
)
from gngdt.services.learner.tracking import (
    MAX_MAP_AGE_S,
    TRACKER_BACKLOG,
    FrameQueue,
    Handover,
    Tracked,
    TrackerThread,
)
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.session import declare_publisher

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

#: a stream that sent nothing for this long (seconds of this machine's clock) has its last
#: learned frame published, if its own clock did not publish it (a camera that stopped); a
#: replay paced by the learner sends its next frame sooner, so its publications stay the ones
#: its clock chose
STALLED_STREAM_S = 1.0
#: an idle learner looks at its other duties (a stop, the stream's end, a frame left
#: unpublished) at least this often (seconds); a frame wakes it at once
IDLE_WAIT_S = 0.01
#: the outcome a malformed cloud is acknowledged with
MALFORMED = "malformed"
#: why a cloud was not learned, as much as an acknowledgement carries
MAX_PROBLEM_CHARS = 500


class LatencyWindow:
    """The last ``size`` frame-to-topology latencies (ms), for p50/p99."""

    def __init__(self, size: int = 1000) -> None:
        self._values: deque[float] = deque(maxlen=size)

    def add(self, latency_ms: float) -> None:
        self._values.append(latency_ms)

    def percentile(self, q: float) -> float:
        return float(np.percentile(np.fromiter(self._values, float), q)) if self._values else 0.0


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
                 instances: LearnerInstances | None = None,
                 pool_bytes: int | None = None) -> None:
        self.camera = camera
        self.options = config.options
        self.learner = learner
        self.checkpoint = checkpoint
        self.end = EndOfStream()
        self.latest = LatestTopology()
        self.latencies = LatencyWindow()
        self.instances = instances or LearnerInstances(session, camera)
        #: with tracking, every frame goes to the tracker thread (`start`); else latest wins
        max_points = self.options.max_cloud_points
        self.frames = (FrameQueue(max_points) if learner.tracking is not None
                       else FrameQueue(max_points, capacity=1))
        self.handover = Handover()
        #: frames tracked and handed over, not learned or acknowledged yet; when one last was
        self._candidates: list[Tracked] = []
        self._map_learned_at = 0.0
        self.points = session.declare_subscriber(topic(camera, "points"), self.frames.put)
        self.tracker: TrackerThread | None = None
        self._eos = session.declare_subscriber(topic(camera, "eos"), self._on_eos)
        self._topology = declare_publisher(session, topic(camera, "topology"),
                                           ENCODING_TOPOLOGY, latest_wins=True,
                                           pool_bytes=pool_bytes)
        # the settled network is the last word: nothing newer supersedes it, so it must arrive
        self._settled_topology = declare_publisher(session, topic(camera, "topology"),
                                                   ENCODING_TOPOLOGY, latest_wins=False)
        self._status = declare_publisher(session, topic(camera, "learner/status"),
                                         ENCODING_STATUS, latest_wins=False)
        self._ack = declare_publisher(session, topic(camera, "learner/ack"), ENCODING_FRAME_ACK,
                                      latest_wins=False)
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
                                 options.samples_per_frame,
                                 publish_every_s=options.publish_every_s)
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
        #: the last learned frame (stamp, positions, colours, sensor time ns), kept to settle on
        self.last_frame: tuple[FrameStamp, np.ndarray, np.ndarray | None, int] | None = None
        #: when (`time.perf_counter`) the last learned frame was learned, if not published yet
        #: (the budget put it off): published if the stream stalls (`STALLED_STREAM_S`)
        self._unpublished: float | None = None
        #: publications so far (the scene goes with every ``scene_every_frames``-th)
        self._publications = 0
        #: the last frame learned, and the last one done with (learned or not)
        self.learned_sequence = self.handled_sequence = -1
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
        payload = topology_message(published, stamp, bool(settled)).SerializeToString()
        attachment = stamp.to_attachment()
        latency_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        (self._settled_topology if settled else self._topology).put(payload,
                                                                    attachment=attachment)
        self.latest.set(payload, attachment)
        self._objects.put(objects_message(published, stamp).SerializeToString(),
                          attachment=attachment)
        every = self.options.scene_every_frames
        # the scene (~27 ms at 3,000 nodes) only for someone who takes it: `gngdt log` without
        # --mcap or --foxglove does not subscribe to it
        due = every and self._publications % every == 0
        self._publications += 1
        if every and (settled or (due and self._scene.matching_status.matching)):
            scene = scene_message(published, stamp)
            self._scene.put(scene.SerializeToString(), attachment=attachment)
        # the status last: a consumer that ends on the settled status has everything before it
        percentiles = (self.latencies.percentile(50), self.latencies.percentile(99))
        self._published = published
        status = status_message(published.figures, stamp, latency_ms, percentiles, published,
                                settled, self.budget.last)
        self._status.put(status.SerializeToString(), attachment=attachment)
        return latency_ms

    def handle(self, received: Received, waited: bool = False) -> None:
        """Decode, learn and (when due) publish one points sample (no tracking), then
        acknowledge it. ``waited``: the learner was idle until it came (it keeps up)."""
        self.take(Tracked(arrive(received, self.options.max_cloud_points), None), waited)

    def take(self, tracked: Tracked, waited: bool = False, learn: bool = True) -> None:
        """One frame done with: learned (``learn``) and published when due, or not (a bad one
        counted and skipped, a tracked one not chosen), then acknowledged (a capture reading a
        file waits for that before its next frame)."""
        arrival = tracked.arrival
        self.learner.counters.frames_received += 1
        self.clouds_shared += arrival.shared
        if arrival.cloud is None:
            self.learner.counters.malformed_messages += 1
            log.warning("points message skipped: %s", arrival.problem)
            outcome, problem = MALFORMED, arrival.problem
        elif not learn or (tracked.located is not None and not tracked.located.posed):
            outcome, problem = self._not_taken(arrival, tracked.located)
        else:
            outcome, problem = self._learn(arrival.cloud, waited, tracked.located)
        if arrival.stamp is not None:
            self._acknowledge(arrival.stamp, outcome, problem)
            self.handled_sequence = max(self.handled_sequence, arrival.stamp.sequence)

    def _not_taken(self, arrival: Arrival, located: FrameResult | None) -> tuple[str, str]:
        """A frame not learned: lost by the tracker (said, with a status), or posed and passed
        over for another."""
        self.learner.counters.note_sequence(arrival.stamp.sequence)
        if located is None or located.posed:
            return Outcome.POSED, ""
        warn_not_learned(located, result_count(self.learner.counters, located))
        self._publish_status(arrival.stamp)
        return located.outcome, located.problem

    def _learn(self, cloud: PointsMessage, waited: bool,
               located: FrameResult | None) -> tuple[str, str]:
        """Learn one decoded cloud (where the tracker found it: ``located``) and publish what
        was learned when due; its outcome and, when not learned, why."""
        started = time.perf_counter()
        learner = self.learner
        counters = learner.counters
        stamp = cloud.stamp
        counters.note_sequence(stamp.sequence)
        received_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        self.budget.arrived(stamp.sequence, stamp.capture_time_ns, waited)
        learning_before = counters.learning_seconds
        result = learner.learn(cloud.positions, cloud.colors, cloud.frame_id, cloud.pose,
                               cloud.sensor_ns, steps=self.budget.next().steps,
                               camera=self.calibration.intrinsics, located=located)
        if not result.learned:  # counted by the learner; the status says why
            warn_not_learned(result, result_count(counters, result))
            if result.outcome is not Outcome.OTHER_FRAME:
                self._publish_status(stamp)
            return result.outcome, result.problem
        if result.tracked and located is None:  # tracked here, not by the tracker thread
            self._publish_pose(Arrival(stamp, cloud), result)
        learned_at = time.perf_counter()
        self.budget.learned(learner.last_steps, counters.learning_seconds - learning_before,
                            learned_at - started)
        self.last_frame = (stamp, cloud.positions, cloud.colors, cloud.sensor_ns)
        self.learned_sequence = stamp.sequence
        self._unpublished = learned_at
        if self.budget.publish_due(learned_at, cloud.sensor_ns):
            latency_ms = self.publish_learned(learned_at)
            log.debug("frame %d: %d points, received after %.1f ms, topology after %.1f ms",
                      stamp.sequence, len(cloud.positions), received_ms, latency_ms)
        self._checkpoint_if_due()
        return result.outcome, ""

    def take_tracked(self) -> bool:
        """The frames the tracker handed over: while the tracker keeps up (`TRACKER_BACKLOG`),
        learn the one that adds most to the map and acknowledge every one; whether it did."""
        self._candidates += self.handover.take()
        behind = (len(self.frames) > TRACKER_BACKLOG
                  and time.monotonic() - self._map_learned_at < MAX_MAP_AGE_S
                  and not self.learner.tracking.waiting_for_map)  # the tracker waits for it
        if not self._candidates or behind:
            return False
        frames, self._candidates = self._candidates, []
        last_pose = self.learner.last_pose if self.learner.counters.frames_used else None
        chosen = choose_keyframe(
            [frame.located.pose if frame.located is not None and frame.located.posed
             else frame.arrival.cloud.pose if frame.arrival.cloud is not None else None
             for frame in frames],
            [0.0 if frame.located is None else frame.located.novelty for frame in frames],
            last_pose)
        for index, frame in enumerate(frames):
            self.take(frame, waited=False, learn=index == chosen)
        self._map_learned_at = time.monotonic()
        return True

    def _acknowledge(self, stamp: FrameStamp, outcome: str, problem: str) -> None:
        from gngdt.schemas.status import encode_frame_ack

        ack = encode_frame_ack(timestamp_ns=time.time_ns(), frame_sequence=stamp.sequence,
                               outcome=outcome, problem=problem[:MAX_PROBLEM_CHARS])
        self._ack.put(ack.SerializeToString(), attachment=stamp.to_attachment())

    def publish_learned(self, now: float | None = None) -> float:
        """Publish the last learned frame (learned at ``now``, `time.perf_counter`; default
        now) and count the time it took in the budget; the latency in ms."""
        now = time.perf_counter() if now is None else now
        stamp, positions, colors, sensor_ns = self.last_frame
        latency_ms = self.publish(stamp, positions, colors)
        self.budget.published(time.perf_counter() - now, now, sensor_ns)
        self.latencies.add(latency_ms)
        self._unpublished = None
        return latency_ms

    def _publish_pose(self, arrival: Arrival, result: FrameResult) -> None:
        """A tracked camera's pose: ``odom`` -> the cloud's (camera) frame (from the tracker's
        thread too)."""
        from gngdt.schemas.clouds import pose_to_transform

        stamp = arrival.stamp
        transform = pose_to_transform(result.pose, result.frame_id, arrival.cloud.frame_id,
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
        if not self.end.finished(self.handled_sequence):
            return False
        if self.last_frame is not None and self.end.received_at != self._settled_end:
            stamp, positions, colors, _ = self.last_frame
            self.publish(stamp, positions, colors,
                         settled=self.learner.settle(positions, colors))
            self._settled_end = self.end.received_at
            self._unpublished = None  # the settled network is the last word
        return True

    def run(self, exit_on_eos: bool) -> int:
        """Learn until a stop signal, the stream's end (``exit_on_eos``) or a second learner on
        the camera; the exit code."""
        self.start()
        with lifecycle.graceful() as stop:
            waited = False  # idle since the last frame: the learner keeps up
            while not stop.is_set():
                if self.instances.conflict.is_set():
                    log.error("stopping: learner %s came first on camera %r",
                              self.instances.other_id, self.camera)
                    return 2
                if self.tracker is not None:
                    if self.tracker.failure is not None:
                        raise RuntimeError("the tracker thread failed") from self.tracker.failure
                    if self.take_tracked():
                        waited = False
                        continue
                else:
                    received = self.frames.get(0.0)
                    if received is not None:
                        self.handle(received, waited)
                        waited = False
                        continue
                waited = True
                if self._unpublished is not None and (  # what it learned is not left unpublished
                        time.perf_counter() - self._unpublished >= STALLED_STREAM_S):
                    self.publish_learned()
                    continue
                if self.stream_over() and exit_on_eos:
                    break
                # idle until there is something to do (a frame, or one tracked), not polling
                if self.tracker is not None:
                    self.handover.wait(IDLE_WAIT_S)
                else:
                    self.frames.wait(IDLE_WAIT_S)
        return 0

    def start(self) -> None:
        """With tracking: the tracker thread, posing every frame as it comes."""
        if self.learner.tracking is not None and self.tracker is None:
            self.tracker = TrackerThread(self.learner, self.frames, self.handover,
                                         lambda: self.calibration.intrinsics, self._publish_pose)
            self.tracker.start()

    def close(self) -> None:
        """Stop the tracker, save the last checkpoint and undeclare everything (the session
        stays open)."""
        if self.tracker is not None:
            self.tracker.stop()
        if self.checkpoint is not None and self.learner.counters.frames_used > 0:
            checkpoints.save(self.learner, self.checkpoint)
        self._token.undeclare()
        self.instances.close()
        for entity in (self._queryable, self._eos, self.points, self._topology,
                       self._settled_topology, self._status, self._ack, self._objects,
                       self._scene, *self._tracking):
            entity.undeclare()
        if self.learner.counters.frames_received:
            log.info("%d of %d clouds arrived through shared memory", self.clouds_shared,
                     self.learner.counters.frames_received)


def serve(args: argparse.Namespace, config: LearnerConfig, learner: FrameLearner,
          session: zenoh.Session, instances: LearnerInstances | None = None) -> int:
    """Learn on ``session`` (as the learner ``instances`` announced, if it was) until stopped;
    checkpoint on the way out."""
    service = LearnerService(session, args.cam, config, learner, args.checkpoint, instances,
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
    from gngdt.schemas.clouds import cloud_to_wire

    learner = warm_up_learner(config, logged_progress(log))
    positions, colors, _ = sample_frame()
    # a decoded cloud's points are a read-only strided view, for which numba compiles the
    # finite check (decoding's and learning's) a variant of its own
    wire = cloud_to_wire(positions, colors, timestamp_ns=1, frame_id="warm-up", pose=None)
    decode_points(bytes(wire), FrameStamp(0, time.time_ns()).to_attachment())
    published = learner.publication(positions, colors)
    stamp = FrameStamp(0, 1)
    topology_message(published, stamp)
    objects_message(published, stamp)
    scene_message(published, stamp)
    status_message(published.figures, stamp, 0.0, (0.0, 0.0), published)
