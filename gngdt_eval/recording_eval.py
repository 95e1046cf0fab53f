"""Score a recording offline: replay it frame by frame through each method, as the learner would.

No zenoh: frames are read from the MCAP file, deprojected with the capture service's
``Deprojector`` (same valid-pixel rule), and each frame's points are learned with
``partial_fit(points, colors, n_steps=samples_per_frame, camera_pose=pose)``, exactly the
learner's per-frame call: with the recording's camera poses the network is learned in the fixed
frame (``world_frame``), without them in the camera frame. After every frame we measure the
quantization errors on that frame's points, the node count, the clusters per topology and, where
the recording has ground-truth labels, the adjusted Rand index of each clustering (each point
takes its winner node's cluster), plus the metrics over time of :mod:`gngdt.eval.dynamics`
(ghost share, old-place nodes of changed objects, and with poses the error against k-means on
the world seen so far). On the last frame the references are computed on the same points: k-means
with as many centres as nodes, a voxel grid downsampled to as many points, and DBSCAN of the raw
points.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.core.clustering import COL, POS, SEGMENTS
from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig
from gngdt.core.sensor.geometry import apply_pose
from gngdt.eval.dynamics import (
    CameraView,
    DynamicsSettings,
    DynamicsTracker,
    scene_changes,
)
from gngdt.eval.paper_common import METHOD_NAMES, PAPER_PARAMETERS
from gngdt.eval.paper_methods import clusterings_of, make_model
from gngdt.eval.recording_report import render_markdown, write_plots
from gngdt.eval.report import mean_std, write_report
from gngdt.io.deproject import RUN_POINT_CAP, CloudOptions, FrameToCloud
from gngdt.schemas.clouds import wire_pose

log = logging.getLogger(__name__)

#: ground-truth label of pixels with no surface (never scored)
NO_LABEL = 0


@dataclass(frozen=True)
class RecordingSettings:
    """How a recording is replayed and scored."""

    methods: tuple[str, ...] = ("GNG-DT", "GNG", "GNG-W")
    trials: int = 1
    #: the live learner's defaults, so a replay learns what ``gngdt run`` would
    samples_per_frame: int = field(default_factory=lambda: _learner_default("samples_per_frame"))
    #: node budget (None: the learner's: GNG-DT's max_nodes for a camera-frame map; a map in a
    #: fixed frame grows with the surface seen; the baselines take GNG-DT's max_nodes)
    max_nodes: int | None = None
    #: GNG-DT's resolution_m (None: the learner's: 0.1 m for a map in a fixed frame; 0: off)
    resolution_m: float | None = None
    #: clusters with fewer nodes are not counted (label -1)
    min_cluster_size: int = field(default_factory=lambda: _learner_default("min_cluster_size"))
    #: a cluster is an object once seen in this many frames in a row (object identity scores)
    object_confirm_frames: int = field(
        default_factory=lambda: _learner_default("object_confirm_frames"))
    #: stop after this many frames (None = all)
    max_frames: int | None = None
    min_depth_m: float = CloudOptions.min_depth_m
    max_depth_m: float = CloudOptions.max_depth_m
    #: each frame's cloud is a uniform random subset of at most this many points, drawn as
    #: `gngdt run`'s capture draws it (so both learn the same clouds); 0: every point
    max_points: int = RUN_POINT_CAP
    #: random subset of the last frame's points used to fit k-means and run DBSCAN
    reference_points: int = 20_000
    dbscan_min_samples: int = 10
    #: None = 1.5 x the median distance to the min_samples-th neighbour
    dbscan_eps: float | None = None
    #: GNG-DT's forgetting (None: off, as the paper); default: the learner's profile
    utility_k: float | None = field(default_factory=lambda: _learner_model_default("utility_k"))
    #: GNG-DT's rehearsal of earlier frames (0: off, as the paper); default: the learner's
    replay_share: float = field(default_factory=lambda: _learner_model_default("replay_share"))
    #: learn in the recording's fixed frame when it has camera poses (False: camera frame)
    world_frame: bool = True
    #: GNG-DT: after the last frame, learn it on until settled as ``gngdt run``'s learner does
    #: at a stream's end (a last record, marked settled); off: every record is a frame as learned
    settle: bool = False
    #: the metrics over time (ghost distance, world sample, k-means every N frames)
    dynamics: DynamicsSettings = field(default_factory=DynamicsSettings)

    def __post_init__(self) -> None:
        for name in (
            "trials",
            "samples_per_frame",
            "min_cluster_size",
            "object_confirm_frames",
            "reference_points",
            "dbscan_min_samples",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.max_nodes is not None and self.max_nodes < 2:
            raise ValueError(f"max_nodes must be >= 2, got {self.max_nodes}")
        if self.max_frames is not None and self.max_frames < 1:
            raise ValueError(f"max_frames must be >= 1, got {self.max_frames}")
        if self.max_points < 0:
            raise ValueError(f"max_points must be >= 0 (0: every point), got {self.max_points}")
        for method in self.methods:
            if method not in METHOD_NAMES.values():
                raise ValueError(f"methods: unknown {method!r}")


def _learner_model_default(name: str) -> Any:
    from gngdt.core.learner.frame_learner import LEARNER_MODEL_DEFAULTS

    return LEARNER_MODEL_DEFAULTS.get(name)


def _learner_default(name: str) -> Any:
    from gngdt.core.learner.frame_learner import LearnerOptions

    return getattr(LearnerOptions(), name)


def _gngdt_default(name: str) -> Any:
    from gngdt.core import GNGDT

    return getattr(GNGDT, name)


@dataclass
class FramePoints:
    """One frame as the learner sees it.

    camera_positions: (N, 3) float32 metres, camera frame (what the learner receives);
    positions: (N, 3) the same points in the model's frame (the fixed frame with a pose, else
    the camera frame); colors: (N, 3) uint8; labels: (N,) int64 ground-truth segment ids (0 =
    none) or None for real recordings; pose: (4, 4) camera-to-world or None; view: the frame's
    depth image and pose, for the metrics over time (None without a pose).
    """

    index: int
    positions: np.ndarray
    colors: np.ndarray
    labels: np.ndarray | None
    camera_positions: np.ndarray | None = None
    pose: np.ndarray | None = None
    view: CameraView | None = None
    #: the frame the points are learned in (the pose's fixed frame, else the camera's)
    frame_id: str = "camera"
    #: capture time, nanoseconds (the learner's pose checks take the camera's speed from it)
    timestamp_ns: int | None = None


def frame_points(path: Path, settings: RecordingSettings) -> Iterator[FramePoints]:
    """Frames of the recording deprojected like the capture service does (labels with them)."""
    from gngdt.io.mcap.reader import read_frames
    from gngdt.io.sources.base import DEFAULT_MAX_SKEW_MS

    to_cloud = FrameToCloud(CloudOptions(settings.min_depth_m, settings.max_depth_m,
                                         max_points=settings.max_points or None))
    # colour and depth paired as capture pairs them, so a ROS 2 bag replays here as it does live
    frames = read_frames(path, max_skew_ns=round(DEFAULT_MAX_SKEW_MS * 1e6),
                         fixed_frame="auto" if settings.world_frame else None)
    for count, frame in enumerate(frames):
        if settings.max_frames is not None and count >= settings.max_frames:
            return
        positions, colors, pixels = to_cloud.with_pixels(frame)
        labels = (None if frame.labels is None
                  else frame.labels.reshape(-1).take(pixels).astype(np.int64))
        if frame.pose is None:
            yield FramePoints(frame.index, positions, colors, labels, positions,
                              timestamp_ns=frame.timestamp_ns)
            continue
        pose = wire_pose(frame.pose.matrix)  # as the learner reads it from the cloud
        k = frame.intrinsics
        view = CameraView(frame.depth / 1000.0, k.fx, k.fy, k.cx, k.cy, pose)
        yield FramePoints(frame.index, apply_pose(positions, pose), colors, labels, positions,
                          pose, view, frame.pose.frame_id, frame.timestamp_ns)


def deproject_labels(deproject: Any, depth: np.ndarray, labels: np.ndarray, intrinsics: Any):
    """(N,) int64 per-point labels: the labels image at the pixels the deprojector keeps, in
    its order (a `Deprojector` without a point cap: every valid pixel)."""
    _, _, pixels = deproject.with_pixels(depth, None, intrinsics)
    return np.asarray(labels).reshape(-1).take(pixels).astype(np.int64)


class FrameNotLearned(ValueError):
    """The learner did not learn a frame (its pose was refused, its camera not tracked)."""


class MethodReplay:
    """One method learning a recording frame by frame. GNG-DT learns through the learner's own
    per-frame policy (`FrameLearner`, as ``gngdt learn`` does: its defaults, its clusterings
    and segments, and at the end its settling on the last frame); the paper's baselines GNG and
    GNG-W learn ``samples_per_frame`` steps of ``partial_fit`` per frame."""

    def __init__(self, method: str, trial: int, settings: RecordingSettings) -> None:
        self.method = method
        self.settings = settings
        self.learner: FrameLearner | None = None
        if method == "GNG-DT":
            self.learner = FrameLearner("eval", learner_config(settings, trial))
            self.model = self.learner.model
        else:
            self.model = make_model(method, settings.max_nodes or _gngdt_default("max_nodes"),
                                    random_state=trial)

    def learn(self, points: FramePoints) -> dict[str, np.ndarray]:
        """Learn one frame; each clustering's node labels after it."""
        settings = self.settings
        if self.learner is None:
            self.model.partial_fit(points.camera_positions, points.colors,
                                   n_steps=settings.samples_per_frame, camera_pose=points.pose)
            return {"+".join(props): np.asarray(self.model.clusters(
                *props, min_size=settings.min_cluster_size))
                for props in clusterings_of(self.method, 3)}
        result = self.learner.learn(points.camera_positions, points.colors, points.frame_id,
                                    points.pose, points.timestamp_ns)
        if not result.learned:  # counted by the learner, as live
            raise FrameNotLearned(result.problem)
        self.model = self.learner.model
        return self.learner.learned_frame().labels

    def settle(self, last: FramePoints) -> tuple[str, dict[str, np.ndarray]] | None:
        """GNG-DT: learn the last frame on until settled, as the learner does at a stream's
        end; how it stopped and each clustering's node labels after it (None: a baseline)."""
        if self.learner is None:
            return None
        reason = self.learner.settle(last.camera_positions, last.colors)
        return reason, self.learner.learned_frame().labels


def learner_config(settings: RecordingSettings, trial: int) -> LearnerConfig:
    """The learner's configuration a replay of ``settings`` learns with (seed ``trial``)."""
    from gngdt.core.learner.frame_learner import LearnerConfig, LearnerOptions

    options = LearnerOptions(samples_per_frame=settings.samples_per_frame,
                             min_cluster_size=settings.min_cluster_size,
                             object_confirm_frames=settings.object_confirm_frames, seed=trial)
    model = {"utility_k": settings.utility_k, "replay_share": settings.replay_share}
    for name in ("max_nodes", "resolution_m"):
        if getattr(settings, name) is not None:
            model[name] = getattr(settings, name)
    return LearnerConfig(model=model, options=options)


def replay(path: Path, method: str, trial: int, settings: RecordingSettings) -> dict[str, Any]:
    """One method, one seed, every frame: per-frame metrics and the final model's topology."""
    from gngdt.eval.identity import IdentityScore
    from gngdt.io.mcap.reader import recording_metadata

    run = MethodReplay(method, trial, settings)
    identity = IdentityScore(settings.min_cluster_size, settings.object_confirm_frames)
    frames: list[dict[str, Any]] = []
    last: FramePoints | None = None
    tracker: DynamicsTracker | None = None
    for points in frame_points(path, settings):
        if len(points.positions) == 0:
            log.warning("%s: frame %d has no valid depth; skipped", path, points.index)
            continue
        if tracker is None:
            changes = scene_changes(recording_metadata(path))
            tracker = DynamicsTracker(settings.dynamics, changes, posed=points.pose is not None)
        tracker.before_learning(points.index, points.positions, points.labels)
        started = time.perf_counter()
        try:
            labels = run.learn(points)
        except FrameNotLearned as error:
            log.warning("%s: frame %d not learned: %s", path, points.index, error)
            continue
        record = _frame_record(run.model, points, labels, identity,
                               time.perf_counter() - started)
        record["dynamics"] = tracker.after_learning(
            run.model, points.index, points.camera_positions, points.positions, points.pose,
            points.view)
        every = settings.dynamics.reference_every
        if every > 0 and len(frames) % every == every - 1:
            record["dynamics"].update(tracker.world_reference(run.model))
        frames.append(record)
        last = points
    if last is None or tracker is None:
        raise ValueError(f"{path}: no frame with valid depth to learn from")
    settled = run.settle(last) if settings.settle else None
    if settled is not None:
        started = time.perf_counter()
        record = _frame_record(run.model, last, settled[1], identity,
                               time.perf_counter() - started)
        record.update(settled=settled[0], dynamics=dict(frames[-1]["dynamics"]))
        frames.append(record)
    if "world_qe_pos" not in frames[-1]["dynamics"]:  # the last frame is always a reference
        frames[-1]["dynamics"].update(tracker.world_reference(run.model))
    return {"method": method, "trial": trial, "frames": frames, "model": run.model, "last": last,
            "changes": tracker.summary(), "posed": last.pose is not None,
            "identity": identity.summary()}


def _frame_record(model: Any, points: FramePoints, labels: dict[str, np.ndarray],
                  identity: Any, learn_seconds: float) -> dict[str, Any]:
    """The metrics of one learned frame; ``labels``: node labels per clustering (scored against
    the ground truth where the frame has it, and tracked for object identity)."""
    from gngdt.core import adjusted_rand_index, cluster_count

    error = model.quantization_error(points.positions, points.colors)
    record: dict[str, Any] = {
        "frame": points.index, "points": len(points.positions), "nodes": int(model.n_nodes_),
        "steps": int(model.n_steps_), "learn_seconds": learn_seconds,
        "qe_pos": float(error[POS]), "qe_col": float(error[COL]), "clusters": {},
    }
    labelled = None if points.labels is None else points.labels != NO_LABEL
    has_truth = labelled is not None and bool(labelled.any())
    winners = model.predict(points.positions[labelled]) if labelled is not None else None
    if labelled is not None:
        record["ari"] = {}
    for name, node_labels in labels.items():
        if name != SEGMENTS.name:  # segments are scored as objects (identity), not counted
            record["clusters"][name] = cluster_count(node_labels)
        identity.update(name, model.node_ids_, node_labels, winners if has_truth else None,
                        points.labels[labelled] if has_truth else None)
        if has_truth and name != SEGMENTS.name:
            record["ari"][name] = float(
                adjusted_rand_index(points.labels[labelled], node_labels[winners]))
    return record


def references(
    last: FramePoints, gngdt_model: Any | None, node_counts: set[int], settings: RecordingSettings
) -> dict[str, Any]:
    """k-means and voxel grid at each node count, DBSCAN ARI beside GNG-DT's, on the last frame."""
    from gngdt.core import adjusted_rand_index, cluster_count
    from gngdt.eval.baselines import dbscan_labels, kmeans_reference, voxel_grid_reference

    positions = last.positions.astype(np.float64)
    colors = last.colors.astype(np.float64)
    result: dict[str, Any] = {"frame": last.index, "points": len(positions), "by_nodes": {}}
    for nodes in sorted(node_counts):
        kmeans = kmeans_reference(positions, colors, nodes, fit_points=settings.reference_points)
        voxels = voxel_grid_reference(positions, colors, nodes)
        result["by_nodes"][nodes] = {
            "kmeans": {"qe": kmeans.quantization_error, **kmeans.details},
            "voxel_grid": {"qe": voxels.quantization_error, **voxels.details},
        }
    rng = np.random.default_rng(0)
    subset = np.arange(len(positions))
    if last.labels is not None:
        subset = subset[last.labels != NO_LABEL]
    if len(subset) > settings.reference_points:
        subset = np.sort(rng.choice(subset, size=settings.reference_points, replace=False))
    if len(subset) > settings.dbscan_min_samples:
        started = time.perf_counter()
        labels, eps = dbscan_labels(
            positions[subset], eps=settings.dbscan_eps, min_samples=settings.dbscan_min_samples
        )
        dbscan: dict[str, Any] = {
            "eps_m": eps,
            "min_samples": settings.dbscan_min_samples,
            "points": len(subset),
            "clusters": cluster_count(labels),
            "noise_fraction": float(np.mean(labels < 0)),
            "seconds": time.perf_counter() - started,
        }
        if last.labels is not None:
            truth = last.labels[subset]
            dbscan["ari"] = float(adjusted_rand_index(truth, labels))
            if gngdt_model is not None:
                winners = gngdt_model.predict(positions[subset])
                dbscan["gngdt_ari_same_points"] = {
                    "+".join(props): float(
                        adjusted_rand_index(
                            truth,
                            np.asarray(
                                gngdt_model.clusters(*props, min_size=settings.min_cluster_size)
                            )[winners],
                        )
                    )
                    for props in clusterings_of("GNG-DT", 3)
                }
        result["dbscan"] = dbscan
    return result


def evaluate_recording(
    path: str | Path, settings: RecordingSettings, out_dir: str | Path, progress: bool = True
) -> dict[str, Any]:
    """Replay ``path`` through every method and trial; write ``recording.md/.json`` + PNGs."""
    from gngdt.eval.progress import ProgressBar

    path, out_dir = Path(path), Path(out_dir)
    if not path.is_file():
        raise ValueError(f"recording: {path} does not exist")
    started = time.perf_counter()
    runs = []
    bar = ProgressBar(len(settings.methods) * settings.trials, "replays") if progress else None
    for method in settings.methods:
        for trial in range(settings.trials):
            runs.append(replay(path, method, trial, settings))
            if bar:
                bar.advance()
    if bar:
        bar.close()

    first_gngdt = next((r for r in runs if r["method"] == "GNG-DT"), None)
    node_counts = {int(r["model"].n_nodes_) for r in runs if r["trial"] == 0}
    refs = references(runs[0]["last"], first_gngdt and first_gngdt["model"], node_counts, settings)
    summary = summarise_runs(runs, refs)
    plots = write_plots(runs, refs, summary, path, out_dir, settings.min_cluster_size,
                        settings.dynamics.ghost_distance_m)
    data = {
        "recording": str(path),
        "settings": asdict(settings),
        "parameters": PAPER_PARAMETERS,
        "wall_seconds": time.perf_counter() - started,
        "labelled": runs[0]["last"].labels is not None,
        "posed": runs[0]["posed"],
        "summary": summary,
        "references": refs,
        "runs": [{"method": r["method"], "trial": r["trial"], "frames": r["frames"],
                  "identity": r["identity"]} for r in runs],
        "plots": [p.name for p in plots],
    }
    write_report(out_dir, "recording", render_markdown(data, plots), data)
    return data


def summarise_runs(runs: list[dict[str, Any]], refs: dict[str, Any]) -> dict[str, Any]:
    """Final-frame figures per method (mean ± std over trials) and the ratio to k-means."""
    summary: dict[str, Any] = {}
    for method in dict.fromkeys(r["method"] for r in runs):
        finals = [r["frames"][-1] for r in runs if r["method"] == method]
        entry: dict[str, Any] = {
            "frames": len(next(r for r in runs if r["method"] == method)["frames"]),
            "qe_pos": mean_std(f["qe_pos"] for f in finals),
            "qe_col": mean_std(f["qe_col"] for f in finals),
            "nodes": mean_std(f["nodes"] for f in finals),
            "clusters": {
                n: mean_std(f["clusters"][n] for f in finals) for n in finals[0]["clusters"]
            },
            "learn_seconds_per_frame": mean_std(
                f["learn_seconds"] for r in runs if r["method"] == method for f in r["frames"]
            ),
        }
        if "ari" in finals[0]:
            entry["ari"] = {n: mean_std(f["ari"][n] for f in finals) for n in finals[0]["ari"]}
        entry["identity"] = _identity_summary([r["identity"] for r in runs
                                               if r["method"] == method])
        nodes = round(entry["nodes"]["mean"])
        reference = refs["by_nodes"].get(nodes)
        if reference is not None:
            entry["ratio_to_kmeans_pos"] = (
                entry["qe_pos"]["mean"] / reference["kmeans"]["qe"][POS]
            )
            entry["ratio_to_voxel_grid_pos"] = (
                entry["qe_pos"]["mean"] / reference["voxel_grid"]["qe"][POS]
            )
        entry["over_time"] = summarise_over_time([r for r in runs if r["method"] == method])
        summary[method] = entry
    return summary


def _identity_summary(per_trial: list[dict[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """Per clustering: mean ± std over trials of tracks_kept and id_kept, total id switches."""
    result = {}
    for name in per_trial[0]:
        scores = [trial[name] for trial in per_trial]
        result[name] = {
            "tracks_kept": mean_std(s["tracks_kept"] for s in scores
                                    if s["tracks_kept"] is not None),
            "id_kept": mean_std(s["id_kept"] for s in scores if s["id_kept"] is not None),
            "id_switches": sum(s["id_switches"] for s in scores),
            "id_comparisons": sum(s["id_comparisons"] for s in scores),
        }
    return result


def summarise_over_time(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The metrics over time of one method's trials: steady state (the second half of the
    frames) of the ghost and stale shares, the largest node count, the last world reference, and
    frames until each changed object's old-place nodes were gone (mean ± std over trials)."""
    def dynamics(run: dict[str, Any]) -> list[dict[str, Any]]:
        return [frame["dynamics"] for frame in run["frames"]]

    def steady(run: dict[str, Any]) -> list[dict[str, Any]]:
        records = dynamics(run)
        return records[len(records) // 2 :]

    result: dict[str, Any] = {
        "ghost_share_steady": mean_std(np.mean([d["ghost_share"] for d in steady(r)])
                                       for r in runs),
        "ghost_share_steady_max": mean_std(max(d["ghost_share"] for d in steady(r))
                                           for r in runs),
        "stale_share_steady": mean_std(np.mean([d["stale_share"] for d in steady(r)])
                                       for r in runs),
        "nodes_max": mean_std(max(f["nodes"] for f in r["frames"]) for r in runs),
        "forgotten": mean_std(dynamics(r)[-1]["forgotten"] for r in runs),
    }
    last = dynamics(runs[0])[-1]
    for key in ("world_qe_pos", "world_kmeans_qe_pos", "world_ratio_to_kmeans",
                "out_of_view_qe_pos", "in_view_qe_pos", "out_of_view_nodes"):
        if key in last:
            result[key] = mean_std(dynamics(r)[-1][key] for r in runs)
    changes: dict[str, Any] = {}
    for name, change in runs[0]["changes"].items():
        gone = [r["changes"][name]["frames_until_gone"] for r in runs]
        changes[name] = {
            "kind": change["kind"],
            "start_frame": change["start_frame"],
            "settled_frame": change["settled_frame"],
            "old_place_nodes_at_change": change["old_place_nodes_at_change"],
            "frames_until_gone": (mean_std(gone) if all(g is not None for g in gone) else None),
            "gone_in_trials": sum(g is not None for g in gone),
        }
    result["changes"] = changes
    return result
