"""Learn GNG-DT topologies from a camera's point clouds and publish them with their clusterings.

Latest frame wins: the points subscriber keeps only the newest cloud (a zenoh ring channel of
size 1), so when learning falls behind, stale frames are dropped (counted from sequence gaps) and
memory stays bounded. After each learned frame the learner publishes the topology (edges per
property, the clusterings ``pos``, ``col``, ``nor``, ``col+nor`` with persistent cluster ids, and
persistent node ids), the objects (one per cluster of ``objects_from``, as a foxglove
SceneUpdate) and a status message, and every ``scene_every_frames`` frames the whole scene as a
foxglove SceneUpdate; a queryable on the topology key answers a late joiner with the latest
topology. Objects and scene are published latest-wins (congestion control DROP): a consumer that
cannot keep up misses updates, and never slows the learner down. The model is
checkpointed periodically and on SIGINT/SIGTERM, and resumed from the checkpoint on start.
"""

from __future__ import annotations

import argparse
import inspect
import json
import logging
import signal
import threading
import time
import tomllib
from collections import deque
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from schemas.wire import (
    DEFAULT_CAMERA,
    ENCODING_SCENE_UPDATE,
    ENCODING_STATUS,
    ENCODING_TOPOLOGY,
    FrameStamp,
    topic,
)
from services.zenoh_session import ZenohSetupError, add_zenoh_arguments, open_session

if TYPE_CHECKING:
    import zenoh

    from gngdt_core.objects import ObjectSet
    from gngdt_core.tracking import ClusterTracker

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt learn                                          # camera "camera", paper defaults
  gngdt learn --params config/learner.toml --checkpoint runs/learner.npz
  gngdt learn --cam left --samples-per-frame 20000 --max-nodes 2000
"""

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
    max_points: int = 2_000_000
    seed: int | None = 0
    #: clustering whose clusters are published as objects ("pos" when it is not published)
    objects_from: str = "segments"
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
                     "quantization_sample", "max_points"):
            value = getattr(self, name)
            if value <= 0:
                raise ValueError(f"learner option {name} must be positive, got {value}")
        if self.checkpoint_every_seconds <= 0:
            raise ValueError("learner option checkpoint_every_seconds must be positive")
        if self.scene_every_frames < 0:
            raise ValueError("learner option scene_every_frames must be >= 0 (0: never)")
        if not self.objects_from:
            raise ValueError("learner option objects_from must name a clustering")


#: accepted types of each option (TOML integers are accepted where floats are)
_OPTION_TYPES: dict[str, tuple[type, ...]] = {
    "samples_per_frame": (int,),
    "min_cluster_size": (int,),
    "checkpoint_every_frames": (int,),
    "checkpoint_every_seconds": (int, float),
    "quantization_sample": (int,),
    "max_points": (int,),
    "seed": (int, type(None)),
    "objects_from": (str,),
    "scene_every_frames": (int,),
}


@dataclass
class LearnerConfig:
    """GNG-DT constructor arguments, learner options and segmentation parameters."""

    model: dict[str, Any] = field(default_factory=dict)
    options: LearnerOptions = field(default_factory=LearnerOptions)
    #: `SegmentationParams` keys (validated when loaded)
    segmentation: dict[str, Any] = field(default_factory=dict)


def model_parameter_names() -> set[str]:
    """Names of the ``GNGDT`` constructor arguments a params file may set."""
    from gngdt_core import GNGDT

    # the seed is a learner option (``seed``, ``--seed``), so one key sets it
    excluded = {"self", "random_state"}
    return {name for name in inspect.signature(GNGDT.__init__).parameters if name not in excluded}


def load_params(path: Path | None) -> LearnerConfig:
    """Read a params TOML: GNG-DT constructor keys and learner options (flat, [gngdt],
    [learner]), segmentation parameters ([segmentation]); a sensor profile's [frames] table
    (for `gngdt segment`) is checked and otherwise not used here.

    ``lambda`` is accepted for ``lambda_``. Unknown keys raise ``ValueError`` naming key and file.
    """
    config = LearnerConfig()
    if path is None:
        return config
    try:
        with open(path, "rb") as file:
            document = tomllib.load(file)
    except OSError as error:
        raise ValueError(f"--params {path}: {error.strerror}") from error
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"--params {path}: invalid TOML: {error}") from error
    flat: dict[str, Any] = {}
    for key, value in document.items():
        if isinstance(value, dict) and key in ("gngdt", "learner"):
            flat.update(value)
        elif isinstance(value, dict) and key in ("segmentation", "frames"):
            from gngdt_core.frame_segmenter import FrameSchedule
            from gngdt_core.segmentation import SegmentationParams

            schema = SegmentationParams if key == "segmentation" else FrameSchedule
            try:
                schema.from_dict(value)
            except (TypeError, ValueError) as error:
                raise ValueError(f"--params {path}: [{key}]: {error}") from error
            if key == "segmentation":
                config.segmentation = dict(value)
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
                        help="GNG-DT parameters and learner options (see config/learner.toml)")
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


@dataclass
class Counters:
    """What the learner has seen, published in every status (and kept in checkpoints)."""

    frames_received: int = 0
    frames_used: int = 0
    frames_dropped: int = 0
    malformed_messages: int = 0
    learning_seconds: float = 0.0
    last_sequence: int = -1

    def note_sequence(self, sequence: int) -> None:
        """Count the frames skipped since the last one; a lower sequence is a new stream."""
        if self.last_sequence >= 0 and sequence > self.last_sequence + 1:
            self.frames_dropped += sequence - self.last_sequence - 1
        self.last_sequence = sequence


def counters_from_metadata(path: Path, saved: Any) -> Counters:
    """The counters kept in a checkpoint's metadata, type-checked (``CheckpointError``)."""
    from services.checkpoint import CheckpointError

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
        values[item.name] = expected(value)
    return Counters(**values)


@dataclass
class LearnedFrame:
    """What one learned frame shows: edges (E, 2) int64 per property, cluster labels (N,) int32
    per clustering, and the persistent id (K,) int64 of each label of each clustering."""

    edges: dict[str, np.ndarray]
    labels: dict[str, np.ndarray]
    cluster_ids: dict[str, np.ndarray]


class Learner:
    """One GNG-DT model fed frame by frame; builds the topology, objects, scene and status."""

    def __init__(self, camera: str, config: LearnerConfig, model: Any | None = None,
                 counters: Counters | None = None) -> None:
        from gngdt_core import GNGDT
        from gngdt_core.segmentation import SegmentationParams

        self.camera = camera
        self.options = config.options
        if model is None:
            model_args = {"random_state": config.options.seed, **config.model}
            model = GNGDT(**model_args)
        self.model = model
        self.segmentation = SegmentationParams.from_dict(config.segmentation)
        self.counters = counters or Counters()
        self.latencies = LatencyWindow()
        self._rng = np.random.default_rng(config.options.seed)
        self._trackers: dict[str, ClusterTracker] = {}

    def learn(self, positions: np.ndarray, colors: np.ndarray | None) -> None:
        """Run ``samples_per_frame`` learning steps on one cloud: (N, 3) f32 m, (N, 3) u8."""
        started = time.perf_counter()
        self.model.partial_fit(positions, colors, n_steps=self.options.samples_per_frame)
        self.counters.learning_seconds += time.perf_counter() - started
        self.counters.frames_used += 1

    def quantization_error(self, positions: np.ndarray, colors: np.ndarray | None) -> dict:
        count = min(len(positions), self.options.quantization_sample)
        if count == 0 or colors is None:
            return {}
        chosen = self._rng.choice(len(positions), size=count, replace=False)
        errors = self.model.quantization_error(positions[chosen], colors[chosen])
        return {name: float(value) for name, value in errors.items()}

    def learned_frame(self) -> LearnedFrame:
        """Edges and clusterings of the model now, each cluster with its persistent id (kept from
        the previous call by node membership)."""
        from gngdt_core.tracking import ClusterTracker

        model = self.model
        min_size = self.options.min_cluster_size
        segmentation = model.segmentation(self.segmentation)
        edges = {prop: model.edges(prop) for prop in EDGE_PROPERTIES}
        edges[CONVEXITY_PROPERTY] = edges["pos"][segmentation.convex]
        labels = {name: model.clusters(*name.split("+"), min_size=min_size)
                  for name in CLUSTERINGS}
        labels[SEGMENTS] = segmentation.labels
        node_ids = model.node_ids_
        cluster_ids = {}
        for name, values in labels.items():
            tracker = self._trackers.setdefault(name, ClusterTracker())
            cluster_ids[name] = tracker.update(node_ids, values)
        return LearnedFrame(edges=edges, labels=labels, cluster_ids=cluster_ids)

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
            frame_id=self.camera,
            quantization_error=quantization_error,
            node_ids=model.node_ids_,
            cluster_ids=learned.cluster_ids,
        )

    def objects_clustering(self, learned: LearnedFrame) -> str:
        """The clustering the objects come from: ``objects_from``, or "pos" without it."""
        wanted = self.options.objects_from
        return wanted if wanted in learned.labels else FALLBACK_OBJECTS_FROM

    def objects(self, learned: LearnedFrame) -> ObjectSet:
        """One object per cluster of at least ``min_cluster_size`` nodes of the objects
        clustering, ids persistent."""
        from gngdt_core.objects import describe_objects, drop_small

        name = self.objects_clustering(learned)
        model = self.model
        labels = drop_small(learned.labels[name], self.options.min_cluster_size)
        return describe_objects(model.positions_, model.colors_, model.normals_, labels,
                                learned.cluster_ids[name])

    def objects_update(self, stamp: FrameStamp, objects: ObjectSet) -> Any:
        """The objects as a ``foxglove.SceneUpdate``, coloured as the logger colours clusters."""
        from schemas.scene import objects_to_scene_update
        from services.display import id_colors

        return objects_to_scene_update(
            ids=objects.ids, centers=objects.centers, quaternions_xyzw=objects.quaternions_xyzw,
            sizes=objects.sizes, colors=id_colors(objects.ids), node_counts=objects.node_counts,
            centroids=objects.centroids, mean_colors=objects.colors, normals=objects.normals,
            timestamp_ns=stamp.capture_time_ns, frame_id=self.camera)

    def scene_update(self, stamp: FrameStamp, learned: LearnedFrame) -> Any:
        """Nodes in their learned colours and every clustering's edges coloured by cluster, as a
        ``foxglove.SceneUpdate``."""
        from schemas.scene import topology_to_scene_update
        from services.display import clustering_edges, node_colors

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
            frame_id=self.camera)

    def status(self, stamp: FrameStamp, latency_ms: float, topology: Any) -> Any:
        """The ``gngdt.LearnerStatus`` after publishing ``topology``."""
        from schemas.packing import encode_status

        counters = self.counters
        seconds = counters.learning_seconds
        return encode_status(
            timestamp_ns=stamp.capture_time_ns,
            frame_sequence=stamp.sequence,
            frame_id=self.camera,
            steps=int(self.model.n_steps_),
            steps_per_second=(counters.frames_used * self.options.samples_per_frame / seconds
                              if seconds > 0 else 0.0),
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
        )

    def save(self, path: Path) -> bool:
        """Checkpoint to ``path``; a failed write (disk full, permissions) is logged, not fatal:
        the learner goes on and the previous checkpoint, replaced atomically, stays intact."""
        from services.checkpoint import save_checkpoint

        counters = {item.name: getattr(self.counters, item.name) for item in fields(Counters)}
        try:
            save_checkpoint(path, self.model.get_state(),
                            {"camera": self.camera, "counters": counters})
        except OSError as error:
            log.error("checkpoint %s not written: %s", path, error)
            return False
        log.info("checkpoint %s: %d nodes, %d steps", path, self.model.n_nodes_,
                 self.model.n_steps_)
        return True

    @classmethod
    def resume(cls, path: Path, camera: str, config: LearnerConfig) -> Learner:
        """A learner restored from ``path`` (raises ``CheckpointError`` when it is corrupt)."""
        from gngdt_core import GNGDT
        from services.checkpoint import CheckpointError, load_checkpoint

        state, metadata = load_checkpoint(path)
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
        log.info("resumed from %s: %d nodes, %d steps", path, model.n_nodes_, model.n_steps_)
        return cls(camera, config, model=model, counters=counters)


def finite_points(
    positions: np.ndarray, colors: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Drop points with a NaN/inf coordinate (a foreign publisher may send them)."""
    from gngdt_core.sampling import finite_rows

    finite = finite_rows(positions)
    if finite is None:
        return positions, colors
    return positions[finite], None if colors is None else colors[finite]


def decode_points(
    payload: bytes, attachment: bytes | None, max_points: int = LearnerOptions.max_points
) -> tuple[FrameStamp, np.ndarray, np.ndarray]:
    """The learner's decode path for one ``points`` sample: stamp, finite positions, colours.

    positions: (N, 3) float32 metres, N >= 1; colors: (N, 3) uint8. Raises ``ValueError``
    (``MessageError`` for the payload) for a missing/malformed attachment, an undecodable or
    oversized cloud (``max_points``, checked before allocation), a cloud without colour fields
    (DESIGN's points carry red, green, blue: a colourless model could learn nothing else) or
    without a single finite point.
    """
    from schemas.packing import MessageError, msg_to_cloud

    stamp = FrameStamp.from_attachment(attachment)
    # views into the payload: learning samples only samples_per_frame of its points
    positions, colors = msg_to_cloud(payload, max_points=max_points, copy=False)
    if colors is None:
        raise MessageError("cloud has no red/green/blue fields; the learner needs colour")
    positions, colors = finite_points(positions, colors)
    if len(positions) == 0:
        raise MessageError("no finite points in the cloud")
    return stamp, positions, colors


def warm_up(config: LearnerConfig) -> None:
    """Run every model and message operation once on random points, so that numba compiles (or
    loads its cache) and modules load before the first frame instead of adding to its latency."""
    from gngdt_core import GNGDT

    rng = np.random.default_rng(0)
    positions = rng.random((500, 3), dtype=np.float32)
    colors = rng.integers(0, 256, (500, 3), dtype=np.uint8)
    model = GNGDT(**{**config.model, "random_state": 0})
    model.partial_fit(positions, colors, n_steps=2_000)
    model.quantization_error(positions, colors)
    learner = Learner(DEFAULT_CAMERA, config, model=model)
    learned = learner.learned_frame()
    stamp = FrameStamp(0, 0)
    learner.topology(stamp, {}, learned)
    learner.objects_update(stamp, learner.objects(learned))
    learner.scene_update(stamp, learned)


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
    import zenoh

    from schemas.packing import MessageError, decode_stream_end
    from services.checkpoint import CheckpointError

    try:
        config = config_from_args(args)
        topic(args.cam, "points")
        if args.checkpoint is not None and args.checkpoint.exists():
            learner = Learner.resume(args.checkpoint, args.cam, config)
        else:
            learner = Learner(args.cam, config)
        warm_up(config)
    except (ValueError, CheckpointError) as error:
        log.error("%s", error)
        return 2

    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())

    counters = learner.counters
    end = EndOfStream()
    latest = LatestTopology()

    def on_eos(sample: zenoh.Sample) -> None:
        try:
            end.set(decode_stream_end(sample.payload.to_bytes()).last_frame_sequence)
        except MessageError as error:
            counters.malformed_messages += 1
            log.warning("malformed end-of-stream skipped: %s", error)

    try:
        session = open_session(args)
    except ZenohSetupError as error:
        log.error("%s", error)
        return 1
    block = zenoh.CongestionControl.BLOCK
    points = session.declare_subscriber(topic(args.cam, "points"), zenoh.handlers.RingChannel(1))
    eos_subscriber = session.declare_subscriber(topic(args.cam, "eos"), on_eos)
    topology_publisher = session.declare_publisher(
        topic(args.cam, "topology"), encoding=ENCODING_TOPOLOGY, congestion_control=block)
    status_publisher = session.declare_publisher(
        topic(args.cam, "learner/status"), encoding=ENCODING_STATUS, congestion_control=block)
    # latest-wins views: a consumer that never reads must not hold the learner back
    drop = zenoh.CongestionControl.DROP
    objects_publisher = session.declare_publisher(
        topic(args.cam, "objects"), encoding=ENCODING_SCENE_UPDATE, congestion_control=drop)
    scene_publisher = session.declare_publisher(
        topic(args.cam, "scene"), encoding=ENCODING_SCENE_UPDATE, congestion_control=drop)
    queryable = session.declare_queryable(topic(args.cam, "topology"), latest.reply)
    token = session.liveliness().declare_token(f"gngdt/{args.cam}/learner/alive")
    log.info("learning from %s (%d steps per frame)", topic(args.cam, "points"),
             config.options.samples_per_frame)

    frames_since_checkpoint = 0
    last_checkpoint = time.monotonic()
    learned_sequence = -1
    try:
        while not stop.is_set():
            sample = points.try_recv()
            if sample is None:
                if args.exit_on_eos and end.finished(learned_sequence):
                    break
                time.sleep(0.002)
                continue
            counters.frames_received += 1
            try:
                stamp, positions, colors = decode_points(
                    sample.payload.to_bytes(),
                    sample.attachment.to_bytes() if sample.attachment is not None else None,
                    config.options.max_points)
                counters.note_sequence(stamp.sequence)
                received_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
                learner.learn(positions, colors)  # ValueError: e.g. colours missing mid-stream
            except ValueError as error:  # MessageError is a ValueError
                counters.malformed_messages += 1
                log.warning("points message skipped: %s", error)
                continue
            learned = learner.learned_frame()
            topology = learner.topology(stamp, learner.quantization_error(positions, colors),
                                        learned)
            payload = topology.SerializeToString()
            attachment = stamp.to_attachment()
            latency_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
            topology_publisher.put(payload, attachment=attachment)
            latest.set(payload, attachment)
            learner.latencies.add(latency_ms)
            status = learner.status(stamp, latency_ms, topology)
            status_publisher.put(status.SerializeToString(), attachment=attachment)
            objects = learner.objects_update(stamp, learner.objects(learned))
            objects_publisher.put(objects.SerializeToString(), attachment=attachment)
            scene_every = config.options.scene_every_frames
            if scene_every and counters.frames_used % scene_every == 1 % scene_every:
                scene = learner.scene_update(stamp, learned)
                scene_publisher.put(scene.SerializeToString(), attachment=attachment)
            learned_sequence = stamp.sequence
            log.debug("frame %d: %d points, received after %.1f ms, topology after %.1f ms",
                      stamp.sequence, len(positions), received_ms, latency_ms)
            frames_since_checkpoint += 1
            if args.checkpoint is not None and (
                frames_since_checkpoint >= config.options.checkpoint_every_frames
                or time.monotonic() - last_checkpoint >= config.options.checkpoint_every_seconds
            ):
                learner.save(args.checkpoint)
                frames_since_checkpoint, last_checkpoint = 0, time.monotonic()
    finally:
        if args.checkpoint is not None and counters.frames_used > 0:
            learner.save(args.checkpoint)
        token.undeclare()
        for entity in (queryable, eos_subscriber, points, objects_publisher, scene_publisher):
            entity.undeclare()
        time.sleep(0.1)  # let the last BLOCK puts reach the router
        session.close()
    log.info("learned %d frames (%d dropped, %d malformed), %d nodes, %d steps",
             counters.frames_used, counters.frames_dropped, counters.malformed_messages,
             learner.model.n_nodes_, learner.model.n_steps_)
    return 0
