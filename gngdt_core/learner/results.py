"""What the learner's per-frame policy gives back: each cloud's fate (`FrameResult`), its
running figures (`Counters`, `LearnerFigures`) and, after a learned frame, everything the
services publish (`Publication`: the network, its topologies and clusterings with persistent
ids, its objects). The services encode messages from these alone; they never reach into the
learner. Pure data.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from gngdt.core.objects.object_set import ObjectSet

log = logging.getLogger(__name__)

#: counters saturate here (the status message's uint64 fields, the checkpoint's int64)
MAX_COUNTER = 2**63 - 1
#: frames one can drop between two received frames: a year at 30 fps; a larger jump in the
#: sequence is a new stream (a restarted or foreign capture), not frames lost
MAX_SEQUENCE_GAP = 30 * 3600 * 24 * 365


class Outcome(StrEnum):
    """What became of one cloud given to `FrameLearner.learn`."""

    LEARNED = "learned"
    #: its camera was tracked (``track``), but the frame was not learned (another was)
    POSED = "posed"
    #: its camera could not be tracked (``track``): not learned
    LOST_TRACKING = "lost tracking"
    #: its pose is out of bounds or contradicts its depth (`gngdt.core.odometry.pose_checks`)
    POSE_REJECTED = "pose rejected"
    #: it is in another frame than the one the network is learned in
    OTHER_FRAME = "other frame"


@dataclass(frozen=True)
class FrameResult:
    """One cloud's fate: ``outcome``; ``pose`` (4, 4) the camera-to-``frame_id`` pose it was
    placed with (given, or the tracker's estimate when ``tracked``; None: learned in the
    network's frame as it is, or not placed); ``problem`` why it was not learned ("" when it
    was); ``steps`` the learning steps it got; ``novelty``: of a tracked frame, the share of
    its view the map did not cover (1 - the alignment's overlap)."""

    outcome: Outcome
    pose: np.ndarray | None = None
    frame_id: str = ""
    tracked: bool = False
    problem: str = ""
    steps: int = 0
    novelty: float = 0.0

    @property
    def learned(self) -> bool:
        return self.outcome is Outcome.LEARNED

    @property
    def posed(self) -> bool:
        """It has a pose to be learned at (learned, or tracked and not learned yet)."""
        return self.outcome in (Outcome.LEARNED, Outcome.POSED)


@dataclass
class Counters:
    """What the learner has seen, published in every status (and kept in checkpoints)."""

    frames_received: int = 0
    frames_used: int = 0
    frames_dropped: int = 0
    malformed_messages: int = 0
    #: clouds skipped because their frame is not the one the network is learned in
    frames_other_frame: int = 0
    #: posed clouds skipped because their pose was out of bounds or contradicted their depth
    frames_pose_rejected: int = 0
    #: clouds not learned because their camera could not be tracked (``track``)
    frames_lost_tracking: int = 0
    #: clouds whose camera was tracked (``track``), learned or not
    frames_posed: int = 0
    learning_seconds: float = 0.0
    #: learning steps run in ``learning_seconds`` (frames differ: a new scene learns longer)
    learning_steps: int = 0
    last_sequence: int = -1

    def note_sequence(self, sequence: int) -> None:
        """Count the frames skipped since the last one; a lower sequence, or a jump no camera
        could make (``MAX_SEQUENCE_GAP``), is a new stream, not dropped frames."""
        gap = sequence - self.last_sequence - 1
        if self.last_sequence >= 0 and 0 < gap <= MAX_SEQUENCE_GAP:
            self.frames_dropped = min(self.frames_dropped + gap, MAX_COUNTER)
        elif self.last_sequence >= 0 and gap > MAX_SEQUENCE_GAP:
            log.warning("frame sequence jumped from %d to %d; taken as a new stream",
                        self.last_sequence, sequence)
        self.last_sequence = sequence

    def add_learning(self, seconds: float, steps: int) -> None:
        self.learning_seconds += seconds
        self.learning_steps = min(self.learning_steps + steps, MAX_COUNTER)

    def count(self, outcome: Outcome) -> None:
        """Count one cloud that was not learned, by why (a posed one: tracked)."""
        name = {Outcome.OTHER_FRAME: "frames_other_frame",
                Outcome.POSE_REJECTED: "frames_pose_rejected",
                Outcome.LOST_TRACKING: "frames_lost_tracking",
                Outcome.POSED: "frames_posed"}[outcome]
        setattr(self, name, min(getattr(self, name) + 1, MAX_COUNTER))


@dataclass(frozen=True)
class Ghosts:
    """The ghost measure of the last learned frame (see `gngdt.core.metrics.ghost_nodes`)."""

    seen_nodes: int = 0
    ghost_share: float = 0.0


@dataclass(frozen=True)
class LearnerFigures:
    """The learner's figures now, as its status message carries them: ``counters`` (a copy),
    the network's steps, nodes and nodes forgotten, the steps the last learned frame got, the
    ghost measure, why the last rejected pose was rejected, and the camera tracking's state
    ("" not tracking, "tracked" or "lost: <why>")."""

    frame_id: str
    counters: Counters
    steps: int
    nodes: int
    nodes_forgotten: int
    frame_steps: int
    ghosts: Ghosts
    ghost_distance_m: float
    pose_problem: str
    tracking: str
    #: frames lost by the tracker, by why ("little overlap", "no calibration", ...)
    lost_reasons: dict[str, int]

    @property
    def steps_per_second(self) -> float:
        seconds = self.counters.learning_seconds
        return self.counters.learning_steps / seconds if seconds > 0 else 0.0


@dataclass(frozen=True)
class LearnedFrame:
    """What one learned frame shows: edges (E, 2) int64 per topology, cluster labels (N,) int32
    per clustering, and per label of each clustering its persistent id (K,) int64 and whether
    it is confirmed (K,) bool (`ClusterIds.confirmed_`); ``segment_roles``: (K,) int8 role of
    each segment (`gngdt.core.segmentation.supports`), judged when the objects are segments."""

    edges: dict[str, np.ndarray]
    labels: dict[str, np.ndarray]
    cluster_ids: dict[str, np.ndarray]
    confirmed: dict[str, np.ndarray]
    segment_roles: np.ndarray | None = None


@dataclass(frozen=True)
class Publication:
    """Everything the services publish after a learned frame, in the network's frame
    ``frame_id``: nodes (positions (N, 3) float64 metres, colours (N, 3) float64 0-255, normals
    (N, 3), errors (N,), persistent ``node_ids`` (N,) int64), the steps learned so far, the
    frame's topologies and clusterings (`LearnedFrame`), its objects, eq. 17's error on a
    sample of the frame, the smallest cluster counted, and the learner's figures."""

    frame_id: str
    positions: np.ndarray
    colors: np.ndarray
    normals: np.ndarray
    errors: np.ndarray
    node_ids: np.ndarray
    steps: int
    learned: LearnedFrame
    objects: ObjectSet
    quantization_error: dict[str, float]
    min_cluster_size: int
    figures: LearnerFigures
