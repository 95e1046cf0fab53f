"""The learner's per-frame policy: one GNG-DT network fed cloud by cloud, and what each learned
frame shows (edges, clusterings with persistent ids, objects, ghosts).

The same class runs inside the learner process (`gngdt.services.learner`, which adds zenoh, wire
messages and checkpoints) and in `gngdt eval recording` (which replays a recording through it), so
what is evaluated is what is deployed. Pure computation: clouds in, network and labels out.

The network lives in the frame of the first cloud it learns (its ``frame_id``): a cloud whose pose
places it in a fixed frame (``world``, ``map``) is learned there, pose applied, so a moving camera
builds one map; a cloud without a pose is learned in the camera frame as it is, or, with ``track``,
placed by aligning it to the map (`gngdt.core.odometry.camera_tracking`, frame ``odom``; a cloud
whose alignment fails is not learned). A later cloud in another frame is not learned
(`Outcome.OTHER_FRAME`, counted). A posed cloud is learned only when its pose passes
`gngdt.core.odometry.pose_checks` (within the workspace, moving as a camera can, agreeing with the
depth of an earlier frame); else not (`Outcome.POSE_REJECTED`, counted). `learn` says what became
of each cloud (`FrameResult`); `publication` gives everything the services publish after a learned
frame (`Publication`), `figures` the learner's running figures. A map in a fixed frame grows with
the world: unless the profile says otherwise it has one node per ``resolution_m`` cell of surface
seen (`LEARNER_WORLD_DEFAULTS`); a camera-frame map keeps the node budget ``max_nodes``. With a
frame schedule (a sensor profile's ``[frames]`` table) frames go through `StreamLearner`
(attention, scene cuts, a first frame learned longer); without one, ``samples_per_frame`` steps of
`GNGDT.partial_fit` each (or the steps the caller's time budget gives,
`gngdt.core.learner.frame_budget`).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar

import numpy as np

from gngdt.core.clustering import CLUSTERINGS, CONVEXITY, EDGE_PROPERTIES, POS, SEGMENTS
from gngdt.core.gas.model import GNGDT
from gngdt.core.learner.results import (
    Counters,
    FrameResult,
    Ghosts,
    LearnedFrame,
    LearnerFigures,
    Outcome,
    Publication,
)
from gngdt.core.learner.stream_learner import FrameSchedule, StreamLearner
from gngdt.core.metrics import ghost_nodes
from gngdt.core.objects.object_set import ObjectFinder, ObjectSet
from gngdt.core.odometry.camera_tracking import TRACKED_FRAME, CameraTracking
from gngdt.core.odometry.map_odometry import TrackerParams
from gngdt.core.odometry.pose_checks import PoseChecker, PoseLimits
from gngdt.core.parameters import Flag, Interval, OneOf, Settings, param
from gngdt.core.segmentation.network import SegmentationParams
from gngdt.core.sensor.depth import NOT_A_SCENE, implausible_start
from gngdt.core.sensor.geometry import CameraIntrinsics, apply_pose

log = logging.getLogger(__name__)

#: the learner's profile over GNGDT's defaults (the paper's): forgetting and rehearsal on, for a
#: camera that moves and a scene that changes (measured in issue 11's note). A params file's
#: ``utility_k = 0`` turns forgetting off, ``replay_share = 0`` rehearsal.
LEARNER_MODEL_DEFAULTS: dict[str, Any] = {"utility_k": 1000.0, "replay_share": 0.3}
#: ... and for a map in a fixed frame (posed or tracked clouds), where a profile does not set
#: them: the map grows with the surface seen, one node per cell of ``resolution_m``, up to
#: ``max_nodes`` (the memory cap). A camera-frame map keeps GNG-DT's ``max_nodes`` budget.
LEARNER_WORLD_DEFAULTS: dict[str, Any] = {"resolution_m": 0.1, "max_nodes": 20_000}
#: settling after the stream ends: steps between checks, and the relative change of the
#: position error below which the network counts as settled
SETTLE_CHUNK = 20_000
SETTLED_CHANGE = 0.01
#: largest cloud a learner accepts by default (the wire's own limit, schemas' MAX_CLOUD_POINTS);
#: not capture's point cap (``--max-points``), which thins a frame's cloud
DEFAULT_MAX_CLOUD_POINTS = 2_000_000

def _pose_limit(name: str) -> Any:
    """A learner option ``pose_<name>`` declared as `PoseLimits` declares ``name``."""
    item = next(item for item in fields(PoseLimits) if item.name == name)
    return param(item.default, item.metadata["constraint"], item.metadata["doc"])


@dataclass(frozen=True)
class LearnerOptions(Settings):
    """The learner's options that are not GNG-DT constructor arguments (``[learner]`` keys)."""

    WHAT: ClassVar[str] = "learner option"

    samples_per_frame: int = param(10_000, Interval(int, 1),
                                   "learning steps per frame (with a frame schedule: per later "
                                   "frame of a stream)")
    min_cluster_size: int = param(5, Interval(int, 1),
                                  "nodes in a connected component smaller than this get label "
                                  "-1 and are not counted")
    checkpoint_every_frames: int = param(30, Interval(int, 1),
                                         "checkpoint every this many learned frames")
    checkpoint_every_seconds: float = param(30.0, Interval(float, 0.0, closed="neither"),
                                            "... or every this many seconds")
    quantization_sample: int = param(2_000, Interval(int, 1),
                                     "points of each frame used for the quantization error")
    max_cloud_points: int = param(DEFAULT_MAX_CLOUD_POINTS, Interval(int, 1),
                            "largest cloud accepted; a bigger one is refused (counted as "
                            "malformed) before anything is allocated")
    settle_max_steps: int = param(2_000_000, Interval(int, 0),
                                  "when the stream ends, learning goes on with its last frame "
                                  "until the network is settled, at most this many more steps "
                                  "and never more than one frame's (samples_per_frame); 0: "
                                  "never")
    seed: int | None = param(0, Interval(int, 0, optional=True), "random seed of the model")
    ghost_distance_m: float = param(0.05, Interval(float, 0.0, closed="neither"),
                                    "status: a node the sensor could see farther than this "
                                    "(metres) from the frame is a ghost")
    ghost_sample: int = param(10_000, Interval(int, 0),
                              "status: points of each frame the ghost share is measured on "
                              "(0: not measured)")
    objects_from: str = param(SEGMENTS.name, OneOf(tuple(CLUSTERINGS)),
                              "clustering whose clusters are published as objects")
    object_confirm_frames: int = param(5, Interval(int, 1),
                                       "a cluster is an object once seen in this many "
                                       "publications (`publish_every_s`) in a row")
    # measured: publishing (segmentation, clusters, ids, ghosts, messages) cost as much as the
    # learning itself; a view at 10 Hz is what viewers and planners take (docs/performance.md)
    publish_every_s: float = param(0.1, Interval(float, 0.0),
                                   "publish what was learned (topology, objects, scene, status) "
                                   "at most this often, in seconds of the stream's own clock "
                                   "(the frames' sensor times: every third frame at 30 fps, the "
                                   "same frames on every replay of a file); the last frame of a "
                                   "stream, and one the stream stalls after, are always "
                                   "published; 0: after every learned frame")
    scene_every_frames: int = param(3, Interval(int, 0),
                                    "publish the foxglove scene every this many publications; "
                                    "0: never")
    pose_workspace_m: float = _pose_limit("workspace_m")
    pose_workspace_around: str = _pose_limit("workspace_around")
    pose_rotation_tolerance: float = _pose_limit("rotation_tolerance")
    pose_max_speed_m_s: float = _pose_limit("max_speed_m_s")
    pose_max_turn_deg_s: float = _pose_limit("max_turn_deg_s")
    pose_max_residual: float = _pose_limit("max_residual")
    # off by default: on the walk it learned more frames with fewer steps each, and ended
    # farther from k-means, quiet and busy (docs/moving-camera.md, "Keeping up")
    frame_time_share: float = param(0.0, Interval(float, 0.0, 1.0),
                                    "live learner: share of the time between two frames it may "
                                    "spend on a frame; a frame gets the learning steps that fit "
                                    "(within min_samples_per_frame..samples_per_frame) and is "
                                    "published less often when busy; 0 (default): "
                                    "samples_per_frame steps of every frame taken")
    min_samples_per_frame: int = param(1_000, Interval(int, 1),
                                       "fewest learning steps of a frame under the time budget "
                                       "(at most samples_per_frame)")
    first_frame_steps: int = param(200_000, Interval(int, 1),
                                   "steps of the first frame of a map in a fixed frame (posed or "
                                   "tracked clouds): the map starts settled, and the next frame "
                                   "is tracked against it; a camera-frame map's first frame "
                                   "takes samples_per_frame")
    track: bool = param(False, Flag(),
                        "estimate the camera pose of clouds that come without one by aligning "
                        "each to the map (a [tracker] table tunes it); lost frames are not "
                        "learned")

    def pose_limits(self) -> PoseLimits:
        """The `PoseLimits` of the ``pose_*`` options."""
        return PoseLimits(**{item.name: getattr(self, f"pose_{item.name}")
                             for item in fields(PoseLimits)})


@dataclass(frozen=True)
class LearnerConfig:
    """Everything a `FrameLearner` is built from: GNG-DT constructor arguments (``model``), the
    learner's options, segmentation parameters and, from a sensor profile, a frame schedule
    (None: ``samples_per_frame`` steps of `GNGDT.partial_fit` per frame)."""

    model: dict[str, Any] = field(default_factory=lambda: dict(LEARNER_MODEL_DEFAULTS))
    options: LearnerOptions = field(default_factory=LearnerOptions)
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)
    schedule: FrameSchedule | None = None
    tracker: TrackerParams = field(default_factory=TrackerParams)

    def __post_init__(self) -> None:
        if self.options.track and self.schedule is not None:
            raise ValueError("track: a frame schedule ([frames] table) starts a new network at "
                             "every scene cut, which a tracked map cannot follow; use a profile "
                             "without [frames] to track")
        # one setting for the steps of a later frame: the learner's samples_per_frame
        steps = self.options.samples_per_frame
        if self.schedule is not None and self.schedule.steps_per_frame != steps:
            object.__setattr__(self, "schedule", replace(self.schedule, steps_per_frame=steps))


class FrameLearner:
    """One GNG-DT network fed frame by frame, and what each learned frame shows.

    ``frame_id``: the frame the network is learned in, set by the first cloud (None before).
    ``model``: the network (with a frame schedule, None until the first frame is learned).
    """

    def __init__(self, camera: str, config: LearnerConfig, model: GNGDT | None = None,
                 counters: Counters | None = None, frame_id: str | None = None) -> None:
        self.camera = camera
        self.config = config
        self.options = config.options
        seed = config.options.seed
        #: with a sensor profile's schedule: attention, scene cuts, a first frame learned longer
        self.stream: StreamLearner | None = None
        if config.schedule is not None:
            self.stream = StreamLearner(config.model, config.segmentation, config.schedule, seed)
            if model is not None and model.n_nodes_ > 0:  # resumed: carry its network on
                self.stream.model_ = model
        elif model is None:
            model = GNGDT(**{"random_state": seed, **config.model})
            model.check_params()  # a bad parameter is refused now, not at the first frame
        self._model = model
        #: the network's parameters are settled (a resumed network keeps its own)
        self._model_chosen = model is not None and model.n_steps_ > 0
        #: the segmentation of the last learned frame (None: compute when asked)
        self.last_segmentation: Any = None
        self.counters = counters or Counters()
        self.frame_id = frame_id
        #: the pose of the last cloud learned (None: it was in the network's frame as it is)
        self.last_pose: np.ndarray | None = None
        self._ghosts = Ghosts()
        #: the last learned frame (points, pose) whose ghosts are not measured yet
        self._ghost_frame: tuple[np.ndarray, np.ndarray | None] | None = None
        #: checks every posed cloud before it is learned
        self.poses = PoseChecker(config.options.pose_limits())
        self._rng = np.random.default_rng(seed)
        # what is published draws its own samples: how often a learner publishes (the load may
        # decide) never changes what it learns
        self._analysis_rng = np.random.default_rng(None if seed is None else (seed, 1))
        self._object_finders = {name: ObjectFinder(name, config.options.min_cluster_size,
                                              config.options.object_confirm_frames)
                          for name in CLUSTERINGS}
        #: the camera tracking of unposed clouds (``track``; None: off)
        self.tracking = CameraTracking(config.tracker) if config.options.track else None
        #: frames the tracker lost, by why
        self.lost_reasons: Counter[str] = Counter()
        if self.tracking is not None and model is not None and model.n_nodes_ > 0:
            self.tracking.update_map(model, None)  # resumed: track against its map
        #: the steps the last learned frame got
        self.last_steps = 0

    @property
    def model(self) -> GNGDT | None:
        if self.stream is not None and self.stream.model_ is not None:
            return self.stream.model_
        return self._model

    def learn(self, positions: np.ndarray, colors: np.ndarray | None, frame_id: str = "",
              pose: np.ndarray | None = None, stamp_ns: int | None = None,
              steps: int | None = None, camera: CameraIntrinsics | None = None,
              located: FrameResult | None = None) -> FrameResult:
        """Learn one cloud: (N, 3) f32 m, (N, 3) u8, in its own (camera) frame; ``pose``
        (4, 4) maps it into ``frame_id``; ``stamp_ns`` its capture time. ``steps``: learning
        steps of this frame (default ``samples_per_frame``; a frame learned from scratch takes
        its own). ``camera``: the intrinsics the cloud was deprojected with (tracking needs
        them); ``located``: where `locate` found it already (tracked elsewhere, e.g. in the
        tracker's thread). Returns what became of it: learned, or not (its camera could not be
        tracked, its pose was refused, or it is in another frame than the network's: each
        counted); a tracked pose is the tracker's to judge."""
        tracked = self.tracking is not None and pose is None
        if tracked:
            located = located or self.locate(positions, colors, camera, stamp_ns)
            if not located.posed:
                return located
            pose, frame_id = located.pose, TRACKED_FRAME
        frame_id = frame_id or self.camera
        if self.frame_id is not None and frame_id != self.frame_id:
            return self._not_learned(Outcome.OTHER_FRAME, (
                f"cloud in frame {frame_id!r}, but this network is learned in {self.frame_id!r} "
                f"(a capture without poses, or with another fixed frame, than the first one; "
                f"start the learner afresh to learn in {frame_id!r})"))
        if pose is not None and not tracked:
            verdict = self.poses.check(positions, pose, stamp_ns)
            if not verdict.accepted:
                return self._not_learned(Outcome.POSE_REJECTED, verdict.problem)
        if self.frame_id is None:
            log.info("learning in frame %r%s", frame_id,
                     " (clouds carry camera poses)" if pose is not None else "")
            self.frame_id = frame_id
        if self._choose_model(pose is not None):
            steps = self.options.first_frame_steps
        self.last_pose = pose
        started = time.perf_counter()
        steps = self.options.samples_per_frame if steps is None else int(steps)
        if self.stream is None:
            self.model.partial_fit(positions, colors, n_steps=steps, camera_pose=pose)
            self.last_segmentation = None
        else:
            steps = self._learn_scheduled(positions, colors, pose, steps)
        self.counters.add_learning(time.perf_counter() - started, steps)
        self.counters.frames_used += 1
        self.last_steps = steps
        self._ghost_frame = (positions, pose)  # measured when asked (`ghosts`)
        if tracked:  # the tracker aligns the next frames to the map as it is now
            self.tracking.update_map(self.model, pose)
        return FrameResult(Outcome.LEARNED, pose, frame_id, tracked, "", steps,
                           located.novelty if tracked else 0.0)

    @property
    def ghosts(self) -> Ghosts:
        """The ghost measure of the last learned frame, taken when first asked for (a learner
        that publishes every few frames measures only those: ~6 ms at 3,000 nodes)."""
        if self._ghost_frame is not None:
            self._ghosts = self.measure_ghosts(*self._ghost_frame)
            self._ghost_frame = None
        return self._ghosts

    @ghosts.setter
    def ghosts(self, value: Ghosts) -> None:
        self._ghosts, self._ghost_frame = value, None

    def locate(self, positions: np.ndarray, colors: np.ndarray | None,
               camera: CameraIntrinsics | None, stamp_ns: int | None = None) -> FrameResult:
        """Where the camera of an unposed cloud was (``track``), against the map as it was
        after the last learned frame (so it may run in another thread while the map learns):
        `Outcome.POSED` with the pose in ``odom``, or `Outcome.LOST_TRACKING` and why (each
        counted). `learn` takes the result (``located``)."""
        located = self.tracking.locate(positions, colors, camera, stamp_ns)
        problem, reason = located.problem, located.problem
        if located.first and (implausible := implausible_start(positions, camera)):
            self.tracking.reset()  # the next cloud may start the map instead
            problem, reason = implausible, NOT_A_SCENE
        if located.pose is None or (located.first and problem):
            self.lost_reasons[reason] += 1
            return self._not_learned(Outcome.LOST_TRACKING, problem)
        self.counters.count(Outcome.POSED)
        novelty = 1.0 if located.result is None else 1.0 - located.result.overlap
        return FrameResult(Outcome.POSED, located.pose, TRACKED_FRAME, True, novelty=novelty)

    def _not_learned(self, outcome: Outcome, problem: str) -> FrameResult:
        self.counters.count(outcome)
        return FrameResult(outcome, problem=problem)

    def _choose_model(self, fixed_frame: bool) -> bool:
        """Before the first frame: a map in a fixed frame grows with the world
        (`LEARNER_WORLD_DEFAULTS` under the profile's own values). True when this frame starts
        such a map (it is learned for ``first_frame_steps``)."""
        if self._model_chosen:
            return False
        self._model_chosen = True
        if not fixed_frame:
            return False
        params = {**LEARNER_WORLD_DEFAULTS, **self.config.model}
        if self.stream is not None:  # a frame schedule learns a first frame its own way
            self.stream.model_params = params
            return False
        self._model = GNGDT(**{"random_state": self.options.seed, **params})
        return True

    def _learn_scheduled(self, positions: np.ndarray, colors: np.ndarray | None,
                         pose: np.ndarray | None, steps: int) -> int:
        """One frame through the schedule (``steps`` for a later frame); the steps it took."""
        in_range = self.stream.in_depth_range(positions)
        had_nodes = self.model is not None and self.model.n_nodes_ > 0
        outcome = self.stream.learn_frame(positions[in_range],
                                          None if colors is None else colors[in_range],
                                          camera_pose=pose, steps=steps)
        if outcome.from_scratch and had_nodes:
            log.info("frame %d shows a new scene: learning a new network",
                     self.counters.frames_used)
            for finder in self._object_finders.values():
                finder.ids.forget()  # new nodes, new ids: no cluster carries over
        self.last_segmentation = outcome.segmentation
        return outcome.steps

    def measure_ghosts(self, positions: np.ndarray, pose: np.ndarray | None) -> Ghosts:
        """Seen and ghost nodes against ``ghost_sample`` random points of the frame."""
        count = min(len(positions), self.options.ghost_sample)
        model = self.model
        if count == 0 or model is None or model.n_nodes_ == 0:
            return Ghosts()
        chosen = positions[self._analysis_rng.choice(len(positions), size=count, replace=False)]
        seen, ghost = ghost_nodes(model.positions_, chosen, pose,
                                  self.options.ghost_distance_m, model.view_depth_margin,
                                  model.node_spacing())
        return Ghosts(int(seen.sum()), float(ghost.sum() / seen.sum()) if seen.any() else 0.0)

    def placed(self, positions: np.ndarray) -> np.ndarray:
        """Points of the last learned cloud (its own frame) in the network's frame."""
        return positions if self.last_pose is None else apply_pose(positions, self.last_pose)

    def quantization_error(self, positions: np.ndarray, colors: np.ndarray | None) -> dict:
        """Eq. 17 on a sample of the last learned cloud (``positions`` in its own frame)."""
        count = min(len(positions), self.options.quantization_sample)
        if count == 0 or colors is None:
            return {}
        chosen = self._analysis_rng.choice(len(positions), size=count, replace=False)
        errors = self.model.quantization_error(self.placed(positions[chosen]), colors[chosen])
        return {name: float(value) for name, value in errors.items()}

    def learned_frame(self) -> LearnedFrame:
        """Edges and clusterings of the network now, each cluster with its persistent id (kept
        from the previous call by node membership)."""
        model = self.model
        segmentation = self.last_segmentation or model.segmentation(self.config.segmentation)
        edges = {prop: model.edges(prop) for prop in EDGE_PROPERTIES}
        edges[CONVEXITY] = edges[POS][segmentation.convex]
        labels = {}
        for name, clustering in CLUSTERINGS.items():
            labels[name] = (segmentation.labels if clustering.is_segmentation
                            else model.clusters(*clustering.topologies,
                                                min_size=self.options.min_cluster_size))
        cluster_ids, confirmed = {}, {}
        for name, values in labels.items():
            finder = self._object_finders[name]
            cluster_ids[name] = finder.label_ids(model.node_ids_, values)
            confirmed[name] = finder.ids.confirmed_
        # roles are judged only for the objects' clustering (they take a few ms)
        roles = segmentation.roles if CLUSTERINGS[self.options.objects_from].is_segmentation \
            else None
        return LearnedFrame(edges=edges, labels=labels, cluster_ids=cluster_ids,
                            confirmed=confirmed, segment_roles=roles)

    def objects(self, learned: LearnedFrame, final: bool = False) -> ObjectSet:
        """One object per confirmed cluster of at least ``min_cluster_size`` nodes of the
        ``objects_from`` clustering, ids persistent. ``final``: the stream is over and the network
        will not change any more, so every cluster of that size is an object, confirmed or not
        (confirmation only keeps a growing network's flickering fragments out; a stream of a few
        frames would otherwise end without a single object)."""
        name = self.options.objects_from
        return self._object_finders[name].objects(self.model, learned.labels[name],
                                            learned.cluster_ids[name], confirmed_only=not final,
                                            roles=learned.segment_roles)

    def figures(self) -> LearnerFigures:
        """The learner's figures now (what its status message carries)."""
        model = self.model
        steps, nodes = (int(model.n_steps_), int(model.n_nodes_)) if model is not None else (0, 0)
        tracking = ""
        if self.tracking is not None:
            tracking = f"lost: {self.tracking.problem}" if self.tracking.problem else "tracked"
        return LearnerFigures(
            frame_id=self.camera, counters=replace(self.counters), steps=steps, nodes=nodes,
            nodes_forgotten=int(getattr(model, "n_forgotten_", 0)), frame_steps=self.last_steps,
            ghosts=self.ghosts, ghost_distance_m=self.options.ghost_distance_m,
            pose_problem=self.poses.last_problem, tracking=tracking,
            lost_reasons=dict(self.lost_reasons))

    def publication(self, positions: np.ndarray, colors: np.ndarray | None,
                    final: bool = False) -> Publication:
        """Everything the services publish after the last learned frame (``positions``,
        ``colors``: that cloud, in its own frame, for eq. 17's error); ``final``: the stream is
        over (every cluster of the objects' clustering is an object, see `objects`)."""
        model = self.model
        learned = self.learned_frame()
        return Publication(
            frame_id=self.frame_id or self.camera, positions=model.positions_,
            colors=model.colors_, normals=model.normals_, errors=model.errors_,
            node_ids=model.node_ids_, steps=int(model.n_steps_), learned=learned,
            objects=self.objects(learned, final=final),
            quantization_error=self.quantization_error(positions, colors),
            min_cluster_size=self.options.min_cluster_size, figures=self.figures())

    def settle(self, positions: np.ndarray, colors: np.ndarray | None) -> str:
        """Learn the stream's last frame on until the network is settled: the node budget
        reached and eq. 17's position error changing by less than ``SETTLED_CHANGE`` over
        ``SETTLE_CHUNK`` steps, or the settling budget spent: ``settle_max_steps``, and never
        more than a normal frame's share (``samples_per_frame``), so that the last view does not
        outweigh the stream (a moving camera's map would bend toward it). Returns how it
        stopped (the final status says it, and the logger waits for it)."""
        limit = min(self.options.settle_max_steps, self.options.samples_per_frame)
        model = self.model
        sample = self.placed(positions[self._rng.choice(len(positions),
                                                        min(len(positions), 5_000),
                                                        replace=False)])
        steps = 0
        previous = model.quantization_error(sample)[POS]
        started = time.perf_counter()
        reason = ""
        while steps < limit and not reason:
            chunk = min(SETTLE_CHUNK, limit - steps)
            if self.stream is None:
                model.partial_fit(positions, colors, n_steps=chunk, camera_pose=self.last_pose)
            else:
                self.stream.refine(positions, colors, chunk, camera_pose=self.last_pose)
            steps += chunk
            error = model.quantization_error(sample)[POS]
            change = abs(previous - error) / previous if previous > 0 else 0.0
            previous = error
            if model.n_nodes_ >= model.max_nodes and change < SETTLED_CHANGE:
                reason = (f"settled after {steps:,} more steps on the last frame: node budget "
                          f"reached, position error changed {change:.2%} over the last {chunk:,}")
        reason = reason or (f"stopped after {steps:,} more steps on the last frame (at most a "
                            f"frame's): {model.n_nodes_} of {model.max_nodes} nodes")
        self.counters.add_learning(time.perf_counter() - started, steps)
        self.last_segmentation = None
        self.ghosts = self.measure_ghosts(positions, self.last_pose)  # the settled network's
        log.info("%s", reason)
        return reason
