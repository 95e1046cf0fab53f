"""Learn GNG-DT topologies from a camera's point clouds and publish them with their clusterings.

Latest frame wins: the points subscriber keeps only the newest cloud (a zenoh ring channel of
size 1), so when learning falls behind, stale frames are dropped (counted from sequence gaps) and
memory stays bounded.

The network lives in the frame of the first cloud it learns (its ``frame_id``): a cloud whose
pose places it in a fixed frame (``world``, ``map``) is learned there, pose applied, so a moving
camera builds one map; a cloud without a pose is learned in the camera frame as it is. A later
cloud in another frame is skipped, counted and warned about, naming both frames. The learner's
profile turns forgetting on (``LEARNER_MODEL_DEFAULTS``): nodes the camera could see but that no
longer stand for anything are removed, the out-of-view map is kept. Each status reports the
ghost share of the frame just learned (seen nodes farther than ``ghost_distance_m`` from it).

After each learned frame the learner publishes the topology (edges per property, the
clusterings ``pos``, ``col``, ``nor``, ``col+nor`` and ``segments`` with persistent cluster ids,
and persistent node ids), the objects (one per cluster of ``objects_from``, as a foxglove
SceneUpdate) and a status message, and every ``scene_every_frames`` frames the whole scene as a
foxglove SceneUpdate; a queryable on the topology key answers a late joiner with the latest
topology. Objects and scene are published latest-wins (congestion control DROP): a consumer that
cannot keep up misses updates, and never slows the learner down. The model is checkpointed
periodically and on SIGINT/SIGTERM, and resumed from the checkpoint on start.
"""

from __future__ import annotations

import argparse
import inspect
import json
import logging
import threading
import time
import tomllib
from collections import deque
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from schemas.wire import (
    DEFAULT_CAMERA,
    ENCODING_SCENE_UPDATE,
    ENCODING_STATUS,
    ENCODING_TOPOLOGY,
    FrameStamp,
    topic,
)
from services.plumbing import lifecycle
from services.plumbing.session import (
    ZenohSetupError,
    add_zenoh_arguments,
    declare_publisher,
    open_session,
)

if TYPE_CHECKING:
    import zenoh

    from gngdt_core.cluster_tracking import ClusterTracker
    from gngdt_core.objects import ObjectSet

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt learn                                          # camera "camera", paper defaults
  gngdt learn --params config/learner.toml --checkpoint runs/learner.npz
  gngdt learn --cam left --samples-per-frame 20000 --max-nodes 2000
"""

#: GNG-U's removal threshold the learner uses (see `GNGDT`); measured in issue 11's note
DEFAULT_UTILITY_K = 1000.0
#: share of each frame's steps rehearsed from the memory of earlier frames (see `GNGDT`);
#: measured in issue 11's note (issue-11-error.md)
DEFAULT_REPLAY_SHARE = 0.3
#: the learner's profile over GNGDT's defaults (the paper's): forgetting and rehearsal on, for a
#: camera that moves and a scene that changes. A params file's ``utility_k = 0`` turns
#: forgetting off, ``replay_share = 0`` rehearsal.
LEARNER_MODEL_DEFAULTS: dict[str, Any] = {"utility_k": DEFAULT_UTILITY_K,
                                          "replay_share": DEFAULT_REPLAY_SHARE}
#: settling after the stream ends: steps between checks, and the relative change of the
#: position error below which the network counts as settled
SETTLE_CHUNK = 20_000
SETTLED_CHANGE = 0.01

#: topologies published as edge sets, and clusterings (properties combined with "+")
EDGE_PROPERTIES = ("pos", "col", "nor")
CLUSTERINGS = ("pos", "col", "nor", "col+nor")
#: the local-convexity topology and the segmentation built on it (`gngdt_core.segmentation`)
CONVEXITY_PROPERTY = "cvx"
SEGMENTS = "segments"
#: clustering the objects come from when ``objects_from`` names one the learner does not publish
FALLBACK_OBJECTS_FROM = "pos"


@dataclass
class LearnerOptions:
    """Learner settings that are not GNG-DT constructor arguments (TOML keys of the same name)."""

    samples_per_frame: int = 10_000
    #: nodes in a connected component smaller than this get label -1 and are not counted
    min_cluster_size: int = 5
    checkpoint_every_frames: int = 30
    checkpoint_every_seconds: float = 30.0
    #: points of the frame sampled to compute the quantization error (eq. 17)
    quantization_sample: int = 2_000
    #: largest cloud accepted; a bigger one is counted as malformed before anything is allocated
    max_points: int = 2_000_000  # schemas.packing.MAX_CLOUD_POINTS (not imported: --help)
    #: when the stream ends, learning goes on with its last frame until the network is settled
    #: (node budget reached, quantization error steady) or this many more steps; 0: never
    settle_max_steps: int = 2_000_000
    seed: int | None = 0
    #: a node the sensor could see farther than this (metres) from the frame is a ghost
    ghost_distance_m: float = 0.05
    #: points of each frame the ghost share is measured against (0: not measured)
    ghost_sample: int = 10_000
    #: clustering whose clusters are published as objects ("pos" when it is not published)
    objects_from: str = "segments"
    #: a cluster is published as an object once seen in this many learned frames in a row
    #: (gngdt_core.objects.ObjectTracker's default too)
    object_confirm_frames: int = 5
    #: publish the scene (nodes, edges, clusters) every this many learned frames; 0: never
    scene_every_frames: int = 3

    def validate(self) -> None:
        """Raise ``ValueError`` naming the option for a wrong type or a non-positive value."""
        for item in fields(self):
            value = getattr(self, item.name)
            allowed = _OPTION_TYPES[item.name]
            if isinstance(value, bool) or not isinstance(value, allowed):
                raise ValueError(f"learner option {item.name} must be "
                                 f"{' or '.join(kind.__name__ for kind in allowed)}, "
                                 f"got {value!r}")
        for name in ("samples_per_frame", "min_cluster_size", "checkpoint_every_frames",
                     "quantization_sample", "max_points", "object_confirm_frames"):
            value = getattr(self, name)
            if value <= 0:
                raise ValueError(f"learner option {name} must be positive, got {value}")
        for name in ("checkpoint_every_seconds", "ghost_distance_m"):
            if getattr(self, name) <= 0:
                raise ValueError(f"learner option {name} must be positive")
        for name in ("settle_max_steps", "ghost_sample", "scene_every_frames"):
            if getattr(self, name) < 0:
                raise ValueError(f"learner option {name} must be >= 0")
        if not self.objects_from:
            raise ValueError("learner option objects_from must name a clustering")


#: accepted types of each option (TOML integers are accepted where floats are)
_OPTION_TYPES: dict[str, tuple[type, ...]] = {
    "samples_per_frame": (int,),
    "settle_max_steps": (int,),
    "min_cluster_size": (int,),
    "checkpoint_every_frames": (int,),
    "checkpoint_every_seconds": (int, float),
    "quantization_sample": (int,),
    "max_points": (int,),
    "seed": (int, type(None)),
    "ghost_distance_m": (int, float),
    "ghost_sample": (int,),
    "objects_from": (str,),
    "object_confirm_frames": (int,),
    "scene_every_frames": (int,),
}


@dataclass
class LearnerConfig:
    """GNG-DT constructor arguments, learner options and segmentation parameters."""

    model: dict[str, Any] = field(default_factory=lambda: dict(LEARNER_MODEL_DEFAULTS))
    options: LearnerOptions = field(default_factory=LearnerOptions)
    #: `SegmentationParams` keys (validated when loaded)
    segmentation: dict[str, Any] = field(default_factory=dict)
    #: `FrameSchedule` keys of a sensor profile's [frames] table (validated when loaded); with
    #: one, frames are learned through `gngdt_core.schedule.StreamLearner` (attention, scene cuts,
    #: ``steps_first_frame``), ``samples_per_frame`` steps per later frame
    frames: dict[str, Any] | None = None


def model_parameter_names() -> set[str]:
    """Names of the ``GNGDT`` constructor arguments a params file may set."""
    from gngdt_core import GNGDT

    # the seed is a learner option (``seed``, ``--seed``), so one key sets it
    excluded = {"self", "random_state"}
    return {name for name in inspect.signature(GNGDT.__init__).parameters if name not in excluded}


def read_toml(path: Path, name: str) -> dict[str, Any]:
    """The TOML document in ``path``; ValueError starting with ``name`` when it cannot be read
    or parsed (params files of `gngdt learn` and sensor profiles of `gngdt segment`)."""
    try:
        with open(path, "rb") as file:
            return tomllib.load(file)
    except OSError as error:
        raise ValueError(f"{name}: {error.strerror or error}") from error
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{name}: invalid TOML: {error}") from error


def load_params(path: Path | None) -> LearnerConfig:
    """Read a params TOML: GNG-DT constructor keys and learner options (flat, [gngdt],
    [learner]), segmentation parameters ([segmentation]) and a sensor profile's frame schedule
    ([frames]; its ``steps_per_frame`` and ``veil_ratio`` are `gngdt segment`'s and capture's,
    the learner's steps per frame stay ``samples_per_frame``).

    ``lambda`` is accepted for ``lambda_``. Unknown keys raise ``ValueError`` naming key and file.
    """
    config = LearnerConfig()
    if path is None:
        return config
    document = read_toml(path, f"--params {path}")
    flat: dict[str, Any] = {}
    for key, value in document.items():
        if isinstance(value, dict) and key in ("gngdt", "learner"):
            flat.update(value)
        elif isinstance(value, dict) and key in ("segmentation", "frames"):
            from gngdt_core.schedule import FrameSchedule
            from gngdt_core.segmentation import SegmentationParams

            schema = SegmentationParams if key == "segmentation" else FrameSchedule
            try:
                schema.from_dict(value)
            except (TypeError, ValueError) as error:
                raise ValueError(f"--params {path}: [{key}]: {error}") from error
            if key == "segmentation":
                config.segmentation = dict(value)
            else:
                config.frames = dict(value)
        else:
            flat[key] = value
    model_names = model_parameter_names()
    option_names = {item.name for item in fields(LearnerOptions)}
    for key, value in flat.items():
        name = "lambda_" if key == "lambda" else key
        if name in model_names:
            config.model[name] = value
        elif name in option_names:
            setattr(config.options, name, value)
        else:
            known = ", ".join(sorted(model_names | option_names))
            raise ValueError(f"--params {path}: unknown key {key!r} (known: {known})")
    try:
        config.options.validate()
    except ValueError as error:
        raise ValueError(f"--params {path}: {error}") from error
    return config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cam", default=DEFAULT_CAMERA, help="camera name in the topics")
    parser.add_argument("--params", type=Path, metavar="FILE.toml",
                        help="GNG-DT parameters and learner options; config/learner.toml "
                        "documents every key (installed with gngdt: `python -m gngdt_config` "
                        "prints where)")
    parser.add_argument("--checkpoint", type=Path, metavar="PATH",
                        help="checkpoint file (.npz): resumed from if present, saved periodically "
                        "and on shutdown")
    parser.add_argument("--samples-per-frame", type=int,
                        help="learning steps per frame (default 10000)")
    parser.add_argument("--max-nodes", type=int, help="node budget (default 1000)")
    parser.add_argument("--min-cluster-size", type=int,
                        help="smallest component counted as a cluster (default 5)")
    parser.add_argument("--checkpoint-every", type=int, metavar="FRAMES",
                        help="checkpoint every this many learned frames (default 30)")
    parser.add_argument("--seed", type=int, help="random seed of the model (default 0)")
    parser.add_argument("--objects-from", metavar="CLUSTERING",
                        help="clustering published as objects on gngdt/<cam>/objects (default "
                        "segments; pos when segments are not published; any of "
                        f"{', '.join(CLUSTERINGS)})")
    parser.add_argument("--object-confirm-frames", type=int, metavar="FRAMES",
                        help="a cluster is published as an object once seen in this many "
                        "learned frames in a row (default 5; 1: at once)")
    parser.add_argument("--scene-every", type=int, metavar="FRAMES",
                        help="publish the foxglove scene on gngdt/<cam>/scene every this many "
                        "learned frames (default 3; 0: never)")
    parser.add_argument("--exit-on-eos", action="store_true",
                        help="exit after learning the last frame of a stream (used by `gngdt run`)")
    add_zenoh_arguments(parser)


def config_from_args(args: argparse.Namespace) -> LearnerConfig:
    """The params file overridden by explicit command-line options."""
    config = load_params(args.params)
    overrides = {
        "samples_per_frame": args.samples_per_frame,
        "min_cluster_size": args.min_cluster_size,
        "checkpoint_every_frames": args.checkpoint_every,
        "seed": args.seed,
        "objects_from": args.objects_from,
        "object_confirm_frames": args.object_confirm_frames,
        "scene_every_frames": args.scene_every,
    }
    for name, value in overrides.items():
        if value is not None:
            setattr(config.options, name, value)
    if args.max_nodes is not None:
        config.model["max_nodes"] = args.max_nodes
    config.options.validate()
    return config


class LatencyWindow:
    """The last ``size`` frame-to-topology latencies (ms), for p50/p99."""

    def __init__(self, size: int = 1000) -> None:
        self._values: deque[float] = deque(maxlen=size)

    def add(self, latency_ms: float) -> None:
        self._values.append(latency_ms)

    def percentile(self, q: float) -> float:
        return float(np.percentile(np.fromiter(self._values, float), q)) if self._values else 0.0


#: counters saturate here (the status message's uint64 fields, the checkpoint's int64)
MAX_COUNTER = 2**63 - 1
#: frames one can drop between two received frames: a year at 30 fps; a larger jump in the
#: sequence is a new stream (a restarted or foreign capture), not frames lost
MAX_SEQUENCE_GAP = 30 * 3600 * 24 * 365


@dataclass
class Counters:
    """What the learner has seen, published in every status (and kept in checkpoints)."""

    frames_received: int = 0
    frames_used: int = 0
    frames_dropped: int = 0
    malformed_messages: int = 0
    #: clouds skipped because their frame is not the one the network is learned in
    frames_other_frame: int = 0
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


def counters_from_metadata(path: Path, saved: Any) -> Counters:
    """The counters kept in a checkpoint's metadata, type-checked (``CheckpointError``)."""
    from gngdt_io.checkpoints import CheckpointError

    if not isinstance(saved, dict):
        raise CheckpointError(f"checkpoint {path}: counters are not a mapping")
    values: dict[str, Any] = {}
    for item in fields(Counters):
        if item.name not in saved:
            continue
        value = saved[item.name]
        expected = float if item.type in ("float", float) else int
        if isinstance(value, bool) or not isinstance(value, int | float) or (
                expected is int and not isinstance(value, int)):
            raise CheckpointError(
                f"checkpoint {path}: counter {item.name} is {value!r}, expected a number")
        low = -1 if item.name == "last_sequence" else 0
        if not low <= value <= MAX_COUNTER:
            raise CheckpointError(
                f"checkpoint {path}: counter {item.name} is {value!r}, outside {low}..2**63-1")
        values[item.name] = expected(value)
    return Counters(**values)


class OtherFrameError(ValueError):
    """A cloud is in another frame than the one the network is learned in."""


@dataclass
class Ghosts:
    """The ghost measure of the last learned frame (see `gngdt_core.metrics.ghost_nodes`)."""

    seen_nodes: int = 0
    ghost_share: float = 0.0


@dataclass
class LearnedFrame:
    """What one learned frame shows: edges (E, 2) int64 per property, cluster labels (N,) int32
    per clustering, and per label of each clustering its persistent id (K,) int64 and whether
    its track is confirmed (K,) bool (`ClusterTracker.confirmed_`)."""

    edges: dict[str, np.ndarray]
    labels: dict[str, np.ndarray]
    cluster_ids: dict[str, np.ndarray]
    confirmed: dict[str, np.ndarray]


class Learner:
    """One GNG-DT model fed frame by frame; builds the topology, objects, scene and status.

    ``frame_id``: the frame the network is learned in, set by the first cloud (None before).
    """

    def __init__(self, camera: str, config: LearnerConfig, model: Any | None = None,
                 counters: Counters | None = None, frame_id: str | None = None) -> None:
        from gngdt_core import GNGDT
        from gngdt_core.schedule import FrameSchedule, StreamLearner
        from gngdt_core.segmentation import SegmentationParams

        self.camera = camera
        self.options = config.options
        if model is None:
            model_args = {"random_state": config.options.seed, **config.model}
            model = GNGDT(**model_args)
        self.model = model
        self.segmentation = SegmentationParams.from_dict(config.segmentation)
        #: with a sensor profile's schedule: attention, scene cuts, a first frame learned longer
        self.stream: StreamLearner | None = None
        if config.frames is not None:
            schedule = FrameSchedule.from_dict(
                {**config.frames, "steps_per_frame": config.options.samples_per_frame})
            self.stream = StreamLearner(config.model, self.segmentation, schedule,
                                        config.options.seed)
            if model.n_nodes_ > 0:  # resumed: carry the checkpoint's network on
                self.stream.model_ = model
        #: the segmentation of the last learned frame (None: compute when publishing)
        self.last_segmentation: Any = None
        self.counters = counters or Counters()
        self.latencies = LatencyWindow()
        self.frame_id = frame_id
        #: the pose of the last cloud learned (None: it was in the network's frame as it is)
        self.last_pose: np.ndarray | None = None
        self.ghosts = Ghosts()
        self._rng = np.random.default_rng(config.options.seed)
        self._trackers: dict[str, ClusterTracker] = {}

    def learn(self, positions: np.ndarray, colors: np.ndarray | None, frame_id: str = "",
              pose: np.ndarray | None = None) -> None:
        """Learn one cloud: (N, 3) f32 m, (N, 3) u8, in its own (camera) frame; ``pose``
        (4, 4) maps it into ``frame_id`` — ``samples_per_frame`` steps, or through the sensor
        profile's schedule (which may start a new network on a new scene). Raises
        `OtherFrameError` (counted) for a cloud in another frame than the network's."""
        frame_id = frame_id or self.camera
        if self.frame_id is None:
            log.info("learning in frame %r%s", frame_id,
                     " (clouds carry camera poses)" if pose is not None else "")
            self.frame_id = frame_id
        elif frame_id != self.frame_id:
            self.counters.frames_other_frame += 1
            raise OtherFrameError(
                f"cloud in frame {frame_id!r}, but this network is learned in {self.frame_id!r} "
                f"(a capture without poses, or with another fixed frame, than the first one; "
                f"start the learner afresh to learn in {frame_id!r})")
        self.last_pose = pose
        started = time.perf_counter()
        if self.stream is None:
            self.model.partial_fit(positions, colors, n_steps=self.options.samples_per_frame,
                                   camera_pose=pose)
            self.last_segmentation = None
            steps = self.options.samples_per_frame
        else:
            in_range = self.stream.in_depth_range(positions)
            learned = self.stream.learn_frame(positions[in_range],
                                              None if colors is None else colors[in_range],
                                              camera_pose=pose)
            if learned.from_scratch and self.model.n_nodes_:
                log.info("frame %d shows a new scene: learning a new network",
                         self.counters.frames_used)
                for tracker in self._trackers.values():
                    tracker.forget()  # new nodes, new ids: no cluster carries over
            self.model = self.stream.model_
            self.last_segmentation = learned.segmentation
            steps = learned.steps
        self.counters.learning_seconds += time.perf_counter() - started
        self.counters.learning_steps = min(self.counters.learning_steps + steps, MAX_COUNTER)
        self.counters.frames_used += 1
        self.ghosts = self.measure_ghosts(positions, pose)

    def measure_ghosts(self, positions: np.ndarray, pose: np.ndarray | None) -> Ghosts:
        """Seen and ghost nodes against ``ghost_sample`` random points of the frame."""
        from gngdt_core.metrics import ghost_nodes

        count = min(len(positions), self.options.ghost_sample)
        if count == 0 or self.model.n_nodes_ == 0:
            return Ghosts()
        chosen = positions[self._rng.choice(len(positions), size=count, replace=False)]
        margin = getattr(self.model, "view_depth_margin", 0.05)
        seen, ghost = ghost_nodes(self.model.positions_, chosen, pose,
                                  self.options.ghost_distance_m, margin)
        return Ghosts(int(seen.sum()), float(ghost.sum() / seen.sum()) if seen.any() else 0.0)

    def placed(self, positions: np.ndarray) -> np.ndarray:
        """Points of the last learned cloud (its own frame) in the network's frame."""
        pose = self.last_pose
        if pose is None:
            return positions
        return np.asarray(positions, dtype=np.float64) @ pose[:3, :3].T + pose[:3, 3]

    def quantization_error(self, positions: np.ndarray, colors: np.ndarray | None) -> dict:
        """Eq. 17 on a sample of the last learned cloud (``positions`` in its own frame)."""
        count = min(len(positions), self.options.quantization_sample)
        if count == 0 or colors is None:
            return {}
        chosen = self._rng.choice(len(positions), size=count, replace=False)
        errors = self.model.quantization_error(self.placed(positions[chosen]), colors[chosen])
        return {name: float(value) for name, value in errors.items()}

    def learned_frame(self) -> LearnedFrame:
        """Edges and clusterings of the model now, each cluster with its persistent id (kept from
        the previous call by node membership)."""
        from gngdt_core.cluster_tracking import ClusterTracker

        model = self.model
        min_size = self.options.min_cluster_size
        segmentation = self.last_segmentation or model.segmentation(self.segmentation)
        edges = {prop: model.edges(prop) for prop in EDGE_PROPERTIES}
        edges[CONVEXITY_PROPERTY] = edges["pos"][segmentation.convex]
        labels = {name: model.clusters(*name.split("+"), min_size=min_size)
                  for name in CLUSTERINGS}
        labels[SEGMENTS] = segmentation.labels
        node_ids = model.node_ids_
        cluster_ids, confirmed = {}, {}
        for name, values in labels.items():
            tracker = self._trackers.setdefault(
                name, ClusterTracker(confirm_frames=self.options.object_confirm_frames))
            cluster_ids[name] = tracker.update(node_ids, values)
            confirmed[name] = tracker.confirmed_
        return LearnedFrame(edges=edges, labels=labels, cluster_ids=cluster_ids,
                            confirmed=confirmed)

    def topology(self, stamp: FrameStamp, quantization_error: dict[str, float],
                 learned: LearnedFrame | None = None) -> Any:
        """The current ``gngdt.Topology`` (protobuf message)."""
        from schemas.packing import encode_topology

        model = self.model
        learned = learned or self.learned_frame()
        return encode_topology(
            positions=model.positions_,
            colors=model.colors_,
            normals=model.normals_,
            errors=model.errors_,
            edges=learned.edges,
            clusterings=learned.labels,
            steps=int(model.n_steps_),
            frame_sequence=stamp.sequence,
            timestamp_ns=stamp.capture_time_ns,
            frame_id=self.frame_id or self.camera,
            quantization_error=quantization_error,
            node_ids=model.node_ids_,
            cluster_ids=learned.cluster_ids,
        )

    def objects_clustering(self, learned: LearnedFrame) -> str:
        """The clustering the objects come from: ``objects_from``, or "pos" without it."""
        wanted = self.options.objects_from
        return wanted if wanted in learned.labels else FALLBACK_OBJECTS_FROM

    def objects(self, learned: LearnedFrame) -> ObjectSet:
        """One object per confirmed cluster of at least ``min_cluster_size`` nodes of the objects
        clustering, ids persistent."""
        from gngdt_core.objects import describe_objects, object_labels

        name = self.objects_clustering(learned)
        model = self.model
        labels = object_labels(learned.labels[name], learned.confirmed[name],
                               self.options.min_cluster_size)
        return describe_objects(model.positions_, model.colors_, model.normals_, labels,
                                learned.cluster_ids[name])

    def objects_update(self, stamp: FrameStamp, objects: ObjectSet) -> Any:
        """The objects as a ``foxglove.SceneUpdate``, coloured as the logger colours clusters."""
        from schemas.cluster_colors import id_colors
        from schemas.scene import objects_to_scene_update

        return objects_to_scene_update(
            ids=objects.ids, centers=objects.centers, quaternions_xyzw=objects.quaternions_xyzw,
            sizes=objects.sizes, colors=id_colors(objects.ids), node_counts=objects.node_counts,
            centroids=objects.centroids, mean_colors=objects.colors, normals=objects.normals,
            timestamp_ns=stamp.capture_time_ns, frame_id=self.frame_id or self.camera)

    def scene_update(self, stamp: FrameStamp, learned: LearnedFrame) -> Any:
        """Nodes in their learned colours and every clustering's edges coloured by cluster, as a
        ``foxglove.SceneUpdate``."""
        from schemas.cluster_colors import clustering_edges, node_colors
        from schemas.scene import topology_to_scene_update

        positions = self.model.positions_
        layers = {}
        for name, labels in learned.labels.items():
            pairs = clustering_edges(name, learned.edges, labels)
            layers[name] = (pairs, node_colors(labels, learned.cluster_ids[name],
                                               self.options.min_cluster_size))
        pos_edges = learned.edges["pos"]
        spacing = (float(np.median(np.linalg.norm(
            positions[pos_edges[:, 0]] - positions[pos_edges[:, 1]], axis=1)))
            if len(pos_edges) else 0.02)
        return topology_to_scene_update(
            positions=positions, colors=np.clip(np.rint(self.model.colors_), 0, 255),
            node_size=0.5 * spacing, edge_layers=layers, timestamp_ns=stamp.capture_time_ns,
            frame_id=self.frame_id or self.camera)

    def settle(self, positions: np.ndarray, colors: np.ndarray | None) -> str:
        """Learn the stream's last frame on until the network is settled: the node budget
        reached and eq. 17's position error changing by less than ``SETTLED_CHANGE`` over
        ``SETTLE_CHUNK`` steps, or ``settle_max_steps`` more steps (0: none). Returns how it
        stopped (the final status says it, and the logger waits for it)."""
        limit = self.options.settle_max_steps
        sample = self.placed(positions[self._rng.choice(len(positions),
                                                        min(len(positions), 5_000),
                                                        replace=False)])
        steps = 0
        previous = self.model.quantization_error(sample)["pos"]
        started = time.perf_counter()
        while steps < limit:
            chunk = min(SETTLE_CHUNK, limit - steps)
            if self.stream is None:
                self.model.partial_fit(positions, colors, n_steps=chunk,
                                       camera_pose=self.last_pose)
            else:
                self.stream.refine(positions, colors, chunk, camera_pose=self.last_pose)
            steps += chunk
            error = self.model.quantization_error(sample)["pos"]
            change = abs(previous - error) / previous if previous > 0 else 0.0
            previous = error
            if self.model.n_nodes_ >= self.model.max_nodes and change < SETTLED_CHANGE:
                reason = (f"settled after {steps:,} more steps on the last frame: node budget "
                          f"reached, position error changed {change:.2%} over the last {chunk:,}")
                break
        else:
            reason = (f"stopped after {steps:,} more steps on the last frame (settle_max_steps): "
                      f"{self.model.n_nodes_} of {self.model.max_nodes} nodes")
        self.counters.learning_seconds += time.perf_counter() - started
        self.counters.learning_steps = min(self.counters.learning_steps + steps, MAX_COUNTER)
        self.last_segmentation = None
        self.ghosts = self.measure_ghosts(positions, self.last_pose)  # the settled network's
        log.info("%s", reason)
        return reason

    def status(self, stamp: FrameStamp, latency_ms: float, topology: Any,
               settled: str = "") -> Any:
        """The ``gngdt.LearnerStatus`` after publishing ``topology``; ``settled``: how learning
        on the stream's last frame stopped."""
        from schemas.packing import encode_status

        counters = self.counters
        seconds = counters.learning_seconds
        return encode_status(
            timestamp_ns=stamp.capture_time_ns,
            frame_sequence=stamp.sequence,
            frame_id=self.camera,
            steps=int(self.model.n_steps_),
            steps_per_second=counters.learning_steps / seconds if seconds > 0 else 0.0,
            nodes=int(self.model.n_nodes_),
            frames_received=counters.frames_received,
            frames_used=counters.frames_used,
            frames_dropped=counters.frames_dropped,
            malformed_messages=counters.malformed_messages,
            latency_ms=latency_ms,
            latency_p50_ms=self.latencies.percentile(50),
            latency_p99_ms=self.latencies.percentile(99),
            quantization_error=dict(topology.quantization_error),
            cluster_counts={c.name: c.cluster_count for c in topology.clusterings},
            seen_nodes=self.ghosts.seen_nodes,
            ghost_share=self.ghosts.ghost_share,
            ghost_distance_m=self.options.ghost_distance_m,
            nodes_forgotten=int(getattr(self.model, "n_forgotten_", 0)),
            frames_other_frame=counters.frames_other_frame,
            settled=settled,
        )

    def save(self, path: Path) -> bool:
        """Checkpoint to ``path``; a failed write (disk full, permissions) is logged, not fatal:
        the learner goes on and the previous checkpoint, replaced atomically, stays intact."""
        from gngdt_io.checkpoints import save_checkpoint

        counters = {item.name: getattr(self.counters, item.name) for item in fields(Counters)}
        try:
            save_checkpoint(path, self.model.get_state(),
                            {"camera": self.camera, "counters": counters,
                             "frame_id": self.frame_id})
        except OSError as error:
            log.error("checkpoint %s not written: %s", path, error)
            return False
        log.debug("checkpoint %s: %d nodes, %d steps", path, self.model.n_nodes_,
                  self.model.n_steps_)
        return True

    @classmethod
    def resume(cls, path: Path, camera: str, config: LearnerConfig) -> Learner:
        """A learner restored from ``path`` (raises ``CheckpointError`` when it is corrupt)."""
        from gngdt_core import GNGDT
        from gngdt_io.checkpoints import CheckpointError, load_checkpoint

        state, metadata = load_checkpoint(path)
        saved_camera = metadata.get("camera", camera)
        if saved_camera != camera:
            raise CheckpointError(
                f"checkpoint {path} holds what camera {saved_camera!r} learned, not {camera!r}; "
                f"resume it with --cam {saved_camera} or give this camera its own --checkpoint")
        try:
            model = GNGDT.from_state(state)
        except (KeyError, ValueError, TypeError) as error:
            raise CheckpointError(f"checkpoint {path}: not a GNG-DT state ({error})") from error
        counters = counters_from_metadata(path, metadata.get("counters", {}))
        counters.last_sequence = -1  # a new capture restarts its sequence numbers
        saved_params = json.loads(str(state["params"]))
        ignored = sorted(name for name, value in config.model.items()
                         if saved_params.get(name) != value)
        if ignored:  # the learned network carries its parameters; changing them mid-life is not
            log.warning("resuming %s with its own parameters; ignoring the requested %s", path,
                        ", ".join(f"{name}={config.model[name]!r}" for name in ignored))
        frame_id = metadata.get("frame_id")
        if frame_id is not None and not isinstance(frame_id, str):
            raise CheckpointError(f"checkpoint {path}: frame_id is {frame_id!r}, not a name")
        log.info("resumed from %s: %d nodes, %d steps, in frame %r", path, model.n_nodes_,
                 model.n_steps_, frame_id)
        return cls(camera, config, model=model, counters=counters, frame_id=frame_id)


def finite_points(
    positions: np.ndarray, colors: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Drop points with a NaN/inf coordinate (a foreign publisher may send them)."""
    from gngdt_core.sampling import finite_rows

    finite = finite_rows(positions)
    if finite is None:
        return positions, colors
    return positions[finite], None if colors is None else colors[finite]


class PointsMessage(NamedTuple):
    """One decoded ``points`` sample: positions (N, 3) float32 metres in the cloud's own
    (camera) frame, colors (N, 3) uint8, the frame they are placed in and the (4, 4) pose that
    places them there (None: the identity, the points are in ``frame_id`` as they are)."""

    stamp: FrameStamp
    positions: np.ndarray
    colors: np.ndarray
    frame_id: str
    pose: np.ndarray | None


def decode_points(
    payload: bytes, attachment: bytes | None, max_points: int = LearnerOptions.max_points,
    now_ns: int | None = None,
) -> PointsMessage:
    """The learner's decode path for one ``points`` sample.

    positions: N >= 1 finite points. Raises ``ValueError`` (``MessageError`` for the payload)
    for a missing/malformed attachment, a capture time more than a day from ``now_ns``
    (default: this clock), an undecodable or oversized cloud (``max_points``, checked before
    allocation), a cloud without colour fields (DESIGN's points carry red, green, blue: a
    colourless model could learn nothing else) or without a single finite point, and a pose
    that is not a rigid transform (non-unit quaternion, NaN), naming the frame.
    """
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    from schemas.packing import MessageError, cloud_pose, msg_to_cloud, parse_message

    stamp = FrameStamp.from_attachment(attachment)
    stamp.check_clock(time.time_ns() if now_ns is None else now_ns)
    message = parse_message(PointCloud, payload)
    # views into the payload: learning samples only samples_per_frame of its points
    positions, colors = msg_to_cloud(message, max_points=max_points, copy=False)
    if colors is None:
        raise MessageError("cloud has no red/green/blue fields; the learner needs colour")
    positions, colors = finite_points(positions, colors)
    if len(positions) == 0:
        raise MessageError("no finite points in the cloud")
    pose = cloud_pose(message)
    return PointsMessage(stamp, positions, colors, message.frame_id,
                         None if np.array_equal(pose, np.eye(4)) else pose)


def warm_up(config: LearnerConfig) -> None:
    """Run every model and message operation once on random points, so that numba compiles (or
    loads its cache) and modules load before the first frame instead of adding to its latency."""
    from gngdt_core import GNGDT

    rng = np.random.default_rng(0)
    positions = rng.random((500, 3), dtype=np.float32)
    colors = rng.integers(0, 256, (500, 3), dtype=np.uint8)
    positions[:, 2] += 1.0  # in front of the camera, as a depth camera's points are
    model = GNGDT(**{**config.model, "random_state": 0})
    pose = np.eye(4)
    pose[:3, 3] = 0.1
    model.partial_fit(positions, colors, n_steps=2_000, camera_pose=pose)
    model.quantization_error(positions, colors)
    learner = Learner("warm-up", config, model=model)
    learner.measure_ghosts(positions, pose)
    learned = learner.learned_frame()
    stamp = FrameStamp(0, 1)
    learner.topology(stamp, {}, learned)
    learner.objects_update(stamp, learner.objects(learned))
    learner.scene_update(stamp, learned)


def warn_other_frame(error: OtherFrameError, count: int) -> None:
    """Warn about clouds in another frame: the first, then every 100th (counted in status)."""
    if count == 1 or count % 100 == 0:
        log.warning("points message skipped (%d so far): %s", count, error)


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


def main(args: argparse.Namespace) -> int:
    from gngdt_io.checkpoints import CheckpointError, CheckpointLock

    lock = None
    try:
        config = config_from_args(args)
        topic(args.cam, "points")
        if args.checkpoint is not None:
            lock = CheckpointLock(args.checkpoint).acquire()
            clean_checkpoint_directory(args.checkpoint)
        if args.checkpoint is not None and args.checkpoint.exists():
            learner = Learner.resume(args.checkpoint, args.cam, config)
        else:
            learner = Learner(args.cam, config)
        started = time.monotonic()
        log.info("preparing the learning kernels (the first run on a machine compiles them "
                 "with numba, ~20 s; later runs load them from its cache)")
        warm_up(config)
        log.info("kernels ready in %.1f s", time.monotonic() - started)
        return serve(args, config, learner)
    except (ValueError, CheckpointError) as error:
        log.error("%s", error)
        return 2
    finally:
        if lock is not None:
            lock.release()


def clean_checkpoint_directory(path: Path) -> None:
    """Remove the temporaries a killed learner left beside ``path`` (under its lock)."""
    from gngdt_io.checkpoints import remove_stale_temporaries

    removed = remove_stale_temporaries(path)
    if removed:
        log.warning("removed %d stale checkpoint temporaries left by an interrupted write: %s",
                    len(removed), ", ".join(item.name for item in removed))


class DuplicateLearnerError(ValueError):
    """Another learner already learns this camera."""


class LearnerInstances:
    """Every learner announces itself on ``gngdt/<cam>/learner/instance/<zenoh id>``; two on one
    camera would interleave their topologies, so a second one refuses to start, and of two that
    start at the same moment the one with the larger id stops."""

    def __init__(self, session: zenoh.Session, camera: str) -> None:
        self.camera = camera
        self.own_id = str(session.zid())
        self._prefix = f"gngdt/{camera}/learner/instance"
        self.conflict = threading.Event()
        self.other_id = ""
        others = [str(reply.ok.key_expr).rsplit("/", 1)[-1]
                  for reply in session.liveliness().get(f"{self._prefix}/*", timeout=2.0)
                  if reply.ok is not None]
        if others:
            raise DuplicateLearnerError(
                f"another learner (zenoh id {others[0]}) already learns camera {camera!r}; "
                "stop it, or give this one another --cam")
        self._token = session.liveliness().declare_token(f"{self._prefix}/{self.own_id}")
        self._subscriber = session.liveliness().declare_subscriber(
            f"{self._prefix}/*", self._on_token, history=True)

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


def _payload_bytes(sample: zenoh.Sample, limit: int) -> bytes:
    """The sample's payload, refused (``MessageError``) before any copy when over ``limit``."""
    from schemas.packing import MessageError

    size = len(sample.payload)
    if size > limit:
        raise MessageError(f"{size} bytes, more than the limit of {limit}")
    return sample.payload.to_bytes()


def _attachment_bytes(sample: zenoh.Sample) -> bytes | None:
    attachment = sample.attachment
    if attachment is None or len(attachment) > 64:
        return None
    return attachment.to_bytes()


#: bytes a stream-end message may take (a real one is under 200)
MAX_EOS_BYTES = 64 * 1024
#: bytes per point a foreign cloud layout may use (gngdt's own uses 15)
MAX_POINT_STRIDE_BYTES = 64


def serve(args: argparse.Namespace, config: LearnerConfig, learner: Learner) -> int:
    """Subscribe, learn and publish until stopped, the end of the stream (``--exit-on-eos``) or
    a second learner on the camera; checkpoint on the way out."""
    import zenoh

    from schemas.packing import MessageError, decode_stream_end

    counters = learner.counters
    end = EndOfStream()
    latest = LatestTopology()

    def on_eos(sample: zenoh.Sample) -> None:
        try:
            end.set(decode_stream_end(_payload_bytes(sample, MAX_EOS_BYTES)).last_frame_sequence)
        except MessageError as error:
            counters.malformed_messages += 1
            log.warning("malformed end-of-stream skipped: %s", error)

    try:
        session = open_session(args)
    except ZenohSetupError as error:
        log.error("%s", error)
        return 1
    try:
        instances = LearnerInstances(session, args.cam)
    except DuplicateLearnerError:
        session.close()
        raise
    points = session.declare_subscriber(topic(args.cam, "points"), zenoh.handlers.RingChannel(1))
    eos_subscriber = session.declare_subscriber(topic(args.cam, "eos"), on_eos)
    topology_publisher = declare_publisher(session, topic(args.cam, "topology"),
                                           ENCODING_TOPOLOGY, latest_wins=True)
    status_publisher = declare_publisher(session, topic(args.cam, "learner/status"),
                                         ENCODING_STATUS, latest_wins=False)
    # latest-wins views: a consumer that never reads must not hold the learner back
    objects_publisher = declare_publisher(session, topic(args.cam, "objects"),
                                          ENCODING_SCENE_UPDATE, latest_wins=True)
    scene_publisher = declare_publisher(session, topic(args.cam, "scene"),
                                        ENCODING_SCENE_UPDATE, latest_wins=True)
    queryable = session.declare_queryable(topic(args.cam, "topology"), latest.reply)
    token = session.liveliness().declare_token(f"gngdt/{args.cam}/learner/alive")
    log.info("learning from %s (%d steps per frame)", topic(args.cam, "points"),
             config.options.samples_per_frame)
    max_cloud_bytes = config.options.max_points * MAX_POINT_STRIDE_BYTES + 64 * 1024

    def publish(stamp: FrameStamp, positions: np.ndarray, colors: np.ndarray | None,
                settled: str = "") -> float:
        """Publish the topology and status after learning a frame, then its objects and (every
        ``scene_every_frames`` frames, and the settled last one) the scene; the latency in ms."""
        learned = learner.learned_frame()
        topology = learner.topology(stamp, learner.quantization_error(positions, colors),
                                    learned)
        payload = topology.SerializeToString()
        attachment = stamp.to_attachment()
        latency_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        topology_publisher.put(payload, attachment=attachment)
        latest.set(payload, attachment)
        status = learner.status(stamp, latency_ms, topology, settled)
        status_publisher.put(status.SerializeToString(), attachment=attachment)
        objects = learner.objects_update(stamp, learner.objects(learned))
        objects_publisher.put(objects.SerializeToString(), attachment=attachment)
        scene_every = config.options.scene_every_frames
        if scene_every and (settled or counters.frames_used % scene_every == 1 % scene_every):
            scene = learner.scene_update(stamp, learned)
            scene_publisher.put(scene.SerializeToString(), attachment=attachment)
        return latency_ms

    frames_since_checkpoint = 0
    last_checkpoint = time.monotonic()
    learned_sequence = -1
    #: the last learned frame (stamp, positions, colours), kept to settle on at the stream's end
    last_frame: tuple[FrameStamp, np.ndarray, np.ndarray | None] | None = None
    settled_end = 0.0  # the end of stream (its arrival time) already settled on
    exit_code = 0
    try:
        with lifecycle.graceful() as stop:
            while not stop.is_set():
                if instances.conflict.is_set():
                    log.error("stopping: learner %s came first on camera %r", instances.other_id,
                              args.cam)
                    exit_code = 2
                    break
                sample = points.try_recv()
                if sample is None:
                    if end.finished(learned_sequence):
                        if last_frame is not None and end.received_at != settled_end:
                            # the stream's last frame: learn it on until the network settles
                            publish(*last_frame, settled=learner.settle(*last_frame[1:]))
                            settled_end = end.received_at
                        if args.exit_on_eos:
                            break
                    time.sleep(0.002)
                    continue
                counters.frames_received += 1
                try:
                    stamp, positions, colors, frame_id, pose = decode_points(
                        _payload_bytes(sample, max_cloud_bytes), _attachment_bytes(sample),
                        config.options.max_points)
                    counters.note_sequence(stamp.sequence)
                    received_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
                    # ValueError: e.g. colours missing mid-stream, or a cloud in another frame
                    learner.learn(positions, colors, frame_id, pose)
                except OtherFrameError as error:  # counted by the learner, warned sparingly
                    warn_other_frame(error, counters.frames_other_frame)
                    continue
                except ValueError as error:  # MessageError is a ValueError
                    counters.malformed_messages += 1
                    log.warning("points message skipped: %s", error)
                    continue
                latency_ms = publish(stamp, positions, colors)
                learner.latencies.add(latency_ms)
                last_frame = (stamp, positions, colors)
                learned_sequence = stamp.sequence
                log.debug("frame %d: %d points, received after %.1f ms, topology after %.1f ms",
                          stamp.sequence, len(positions), received_ms, latency_ms)
                frames_since_checkpoint += 1
                if args.checkpoint is not None and (
                    frames_since_checkpoint >= config.options.checkpoint_every_frames
                    or time.monotonic() - last_checkpoint
                    >= config.options.checkpoint_every_seconds
                ):
                    learner.save(args.checkpoint)
                    frames_since_checkpoint, last_checkpoint = 0, time.monotonic()
    finally:
        if args.checkpoint is not None and counters.frames_used > 0:
            learner.save(args.checkpoint)
        token.undeclare()
        instances.close()
        for entity in (queryable, eos_subscriber, points, objects_publisher, scene_publisher):
            entity.undeclare()
        time.sleep(0.1)  # let the last BLOCK puts reach the router
        session.close()
    log.info("learned %d frames (%d dropped, %d malformed), %d nodes, %d steps",
             counters.frames_used, counters.frames_dropped, counters.malformed_messages,
             learner.model.n_nodes_, learner.model.n_steps_)
    return exit_code
