"""Camera tracking without given poses (issue 27): our frame-to-map tracker against Open3D's
RGB-D odometry, in the same run.

**Ours** is the learner's own per-frame policy with ``track`` (`FrameLearner`, as ``gngdt
learn --track`` runs it, with the learner's map: resolution 0.1 m): the first frame starts the
map (the learner's ``first_frame_steps``), then every frame is put back on its pixels from the
calibration (`organize`), aligned to the map (`gngdt.core.odometry.map_odometry`) and, when tracked,
learned at the pose found (``--steps`` steps; lost frames are not learned). **The peer** is Open3D's
``compute_rgbd_odometry`` (hybrid photometric + geometric term, default options but the same
depth range as ours), frame to frame, each frame started from the last motion; its poses are
chained. Both start at the first frame's true pose.

Synthetic walks: the virtual Kinect's scenes (``tabletop_walk``: a 3.2 m walk past a table and
back; ``tabletop``: a 40-degree arc around it) with its sensor model (depth noise growing with
depth squared, disparity steps, holes at edges and grazing angles), made harder here
(`Degradation`, ``--clean`` turns it off): missing depth in blobs (dark, shiny or IR-absorbing
patches) up to ``missing_share`` of the image, speckle dropouts, an 8-pixel invalid band on the
left as registered Kinect depth has, colour noise and a per-frame exposure gain.

TUM: the three shared fr1/xyz frames (``../shared/data/rgbd/tum_fr1_xyz_dvo_examples``, real
Kinect, ground truth from the motion-capture system): each ordered pair (a, b) is one relative
pose — ours learns a map of a and tracks b from a's pose; the peer aligns b to a. These frames
were not used to choose any parameter.

Printed per walk and method: ATE RMSE (after a rigid Horn alignment of the whole trajectory, as
TUM's evaluate_ate; and anchored: no alignment, both from the true first pose), RPE between
consecutive frames (translation and rotation RMSE, and worst), lost frames, frames per second
(ours: the whole per-frame loop — deprojection, map surface, tracking, learning; tracking alone
in brackets; the peer: its odometry call). Then the ghost share (`gngdt.core.metrics
.ghost_nodes`, seen nodes farther than 5 cm from the frame; steady state: the second half of the
frames, mean and worst frame) of maps learned with tracked poses, with the true poses, and with
no poses (camera frame).

    python benchmarks/bench_tracking.py [--quick] [--scenes ...] [--no-peer] [--clean]
                                        [--seed N] [--ablations]
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gngdt.core.gas.model import GNGDT
from gngdt.core.kernels import odometry as OK
from gngdt.core.learner.frame_learner import (
    LEARNER_MODEL_DEFAULTS,
    LEARNER_WORLD_DEFAULTS,
    FrameLearner,
    LearnerConfig,
    LearnerOptions,
)
from gngdt.core.metrics import ghost_nodes
from gngdt.core.odometry.map_odometry import MapOdometry, TrackerParams
from gngdt.core.odometry.map_surface import MapSurface
from gngdt.core.sensor.geometry import rigid_inverse
from gngdt.eval.open3d_peer import load_open3d
from gngdt.io.deproject import Deprojector
from gngdt.io.frame import Frame
from gngdt.io.images import iter_image_frames, load_camera
from gngdt.io.pose_files import load_poses
from gngdt.io.synth.render import render_scene

#: scene -> frames rendered at 30 fps (the walk: out and back; the arc: half its period)
SCENES = {"tabletop_walk": 240, "tabletop": 180}
TUM = Path(__file__).resolve().parents[2] / "shared/data/rgbd/tum_fr1_xyz_dvo_examples"
#: the map the tracker reads: the learner's, in a fixed frame (forgetting, rehearsal, and
#: one node per 0.1 m cell of surface seen)
MAP_PARAMS = {**LEARNER_WORLD_DEFAULTS, **LEARNER_MODEL_DEFAULTS}
#: --ablations: name -> (tracker parameters, map parameters; "first_frame_steps": the learner's)
ABLATIONS: dict[str, tuple[dict, dict]] = {
    "no plane memory": ({"plane_memory": 0}, {}),
    "no node-level robust weight": ({"node_robust": 0.0}, {}),
    "no maturity weight": ({"maturity_points": 0.0}, {}),
    "no spread weight": ({"spread_weighting": False}, {}),
    "no colour": ({"color_weight": 0.0}, {}),
    "inverse-variance weights": ({"inverse_variance": True}, {}),
    "first frame 400,000 steps (track-research)": ({}, {"first_frame_steps": 400_000}),
    "map resolution 0.05 m": ({}, {"resolution_m": 0.05}),
    "fixed budget 1000 nodes (no resolution)": ({}, {"resolution_m": 0, "max_nodes": 1000}),
    "fixed budget 4000 nodes, lambda 50 (track-research)": (
        {}, {"resolution_m": 0, "max_nodes": 4000, "lambda_": 50}),
}
#: a busy learner drops up to this many frames after each it takes (`busy_learner`)
BUSY_DROPS = 8
#: depth range used by both methods, metres
DEPTH_RANGE = (0.3, 6.0)
GHOST_SAMPLE = 10_000


@dataclass(frozen=True)
class Degradation:
    """What is done to the virtual Kinect's frames to look more like a real sensor's."""

    #: share of the pixels lost in blobs (patches ~5-20 % of the image wide)
    missing_share: float = 0.15
    #: share of the remaining pixels lost one by one
    speckle: float = 0.02
    #: invalid columns on the left (registered Kinect depth)
    band_px: int = 8
    #: colour noise sigma, 0-255 units (the renderer's own)
    color_noise: float = 3.0
    #: per-frame exposure gain drawn from 1 +- this
    gain: float = 0.05

    def describe(self) -> str:
        return (f"missing depth in blobs {self.missing_share:.0%} + speckle {self.speckle:.0%} "
                f"+ {self.band_px} px left band; colour noise sigma {self.color_noise:g}, "
                f"exposure gain +-{self.gain:.0%} per frame")


def degrade(frame: Frame, degradation: Degradation, rng: np.random.Generator) -> Frame:
    """``frame`` with depth holes and colour changes (see `Degradation`)."""
    import cv2

    height, width = frame.depth.shape
    depth = frame.depth.copy()
    if degradation.missing_share > 0:
        coarse = rng.random((8, 10)).astype(np.float32)  # smooth field: holes come in blobs
        field_ = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
        depth[field_ < np.quantile(field_, degradation.missing_share)] = 0
    depth[rng.random(depth.shape) < degradation.speckle] = 0
    depth[:, : degradation.band_px] = 0
    gain = 1.0 + degradation.gain * (2.0 * rng.random() - 1.0)
    color = np.clip(frame.color.astype(np.float32) * gain, 0, 255).astype(np.uint8)
    return replace(frame, depth=depth, color=color)


def render(scene: str, frames: int, degradation: Degradation | None, seed: int) -> list[Frame]:
    rng = np.random.default_rng(seed)
    noise = degradation.color_noise if degradation else 0.0
    return [degrade(frame, degradation, rng) if degradation else frame
            for frame in render_scene(scene, frames, seed=seed, color_noise=noise)]


# ------------------------------------------------------------------------------------ metrics

def horn_alignment(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(4, 4) rigid transform best mapping ``estimated`` (N, 3) onto ``truth`` (N, 3) (Horn /
    Umeyama without scale, as TUM's evaluate_ate)."""
    mu_e, mu_t = estimated.mean(axis=0), truth.mean(axis=0)
    u, _, vt = np.linalg.svd((truth - mu_t).T @ (estimated - mu_e))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    transform = np.eye(4)
    transform[:3, :3] = u @ d @ vt
    transform[:3, 3] = mu_t - transform[:3, :3] @ mu_e
    return transform


def ate(estimated: list[np.ndarray], truth: list[np.ndarray]) -> tuple[float, float]:
    """(aligned, anchored) translation RMSE, metres."""
    e = np.array([p[:3, 3] for p in estimated])
    t = np.array([p[:3, 3] for p in truth])
    align = horn_alignment(e, t)
    aligned = e @ align[:3, :3].T + align[:3, 3]
    rmse = lambda a: float(np.sqrt(np.mean(np.sum((a - t) ** 2, axis=1))))  # noqa: E731
    return rmse(aligned), rmse(e)


def rpe(estimated: list[np.ndarray], truth: list[np.ndarray]) -> dict[str, float]:
    """Relative pose error between consecutive frames: translation (metres) and rotation
    (degrees), RMSE and worst."""
    moves, turns = [], []
    for k in range(1, len(truth)):
        true_step = rigid_inverse(truth[k - 1]) @ truth[k]
        our_step = rigid_inverse(estimated[k - 1]) @ estimated[k]
        moved, turned = OK.motion_size(true_step, our_step)
        moves.append(moved)
        turns.append(turned)
    moves, turns = np.array(moves), np.array(turns)
    return {"t_rmse": float(np.sqrt(np.mean(moves ** 2))), "t_max": float(moves.max()),
            "r_rmse": float(np.sqrt(np.mean(turns ** 2))), "r_max": float(turns.max())}


# ------------------------------------------------------------------------------------ methods

@dataclass
class Run:
    """One method's trajectory over one sequence."""

    poses: list[np.ndarray] = field(default_factory=list)
    lost: list[bool] = field(default_factory=list)
    seconds: float = 0.0
    track_seconds: float = 0.0
    ghost: list[float] = field(default_factory=list)
    reasons: dict[str, int] = field(default_factory=dict)
    #: stage -> seconds per frame (ours: deproject, track and learn, track alone)
    stages: dict[str, list[float]] = field(default_factory=dict)
    #: nodes of the map at the end (ours)
    nodes: int = 0

    def lap(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.stages.setdefault(stage, []).append(now - since)
        return now


def new_map(seed: int, **overrides) -> GNGDT:
    return GNGDT(**dict(MAP_PARAMS, **overrides), random_state=seed)


def new_learner(seed: int, steps: int, track: bool, tracker: dict | None = None,
                map_overrides: dict | None = None, first_steps: int | None = None
                ) -> FrameLearner:
    """The learner's per-frame policy, with ``track`` as `gngdt learn --track`."""
    overrides = dict(map_overrides or {})
    first = overrides.pop("first_frame_steps", first_steps)
    options = LearnerOptions(samples_per_frame=steps, seed=seed, track=track,
                             **({} if first is None else {"first_frame_steps": first}))
    model = {**LEARNER_MODEL_DEFAULTS, **overrides}
    return FrameLearner("camera", LearnerConfig(model=model, options=options,
                                                tracker=TrackerParams(**(tracker or {}))))


def ghost_share(model: GNGDT, camera_points: np.ndarray, pose: np.ndarray | None,
                rng: np.random.Generator) -> float:
    if len(camera_points) > GHOST_SAMPLE:
        camera_points = camera_points[rng.choice(len(camera_points), GHOST_SAMPLE,
                                                 replace=False)]
    seen, ghost = ghost_nodes(model.positions_, camera_points, pose)
    return float(ghost.sum() / seen.sum()) if seen.any() else 0.0


def run_ours(frames: list[Frame], steps: int, seed: int, first_steps: int,
             tracker: dict | None = None, map_overrides: dict | None = None,
             stamped: bool = True) -> Run:
    """The learner with tracking (see the module docstring); ``stamped``: frames carry their
    capture time (else the tracker predicts one motion per frame)."""
    deproject = Deprojector(*DEPTH_RANGE)
    learner = new_learner(seed, steps, True, tracker, map_overrides, first_steps)
    start = frames[0].pose.matrix  # ours is anchored at the true first pose, as the peer
    rng = np.random.default_rng(seed)
    run = Run()
    for index, frame in enumerate(frames):
        started = time.perf_counter()
        points, colors = deproject(frame.depth, frame.color, frame.intrinsics)
        lap = run.lap("deproject", started) if index else started
        learned = learner.learn(points, colors, "camera", None,
                                frame.timestamp_ns if stamped else None,
                                camera=frame.intrinsics)
        result = learner.tracking.last
        if index > 0:
            run.lap("track and learn", lap)
            run.stages.setdefault("track", []).append(result.seconds)
            run.seconds += time.perf_counter() - started
            run.track_seconds += result.seconds
        if not learned:
            run.reasons[result.reason] = run.reasons.get(result.reason, 0) + 1
        pose = start @ learner.tracking.odometry.pose_
        run.poses.append(pose)
        run.lost.append(not learned)
        run.ghost.append(ghost_share(learner.model, points, rigid_inverse(start) @ pose, rng))
    run.nodes = learner.model.n_nodes_
    return run


def run_mapping(frames: list[Frame], posed: bool, steps: int, seed: int,
                first_steps: int) -> Run:
    """A map learned with the true poses (``posed``) or none (camera frame): its ghost share."""
    deproject = Deprojector(*DEPTH_RANGE)
    learner = new_learner(seed, steps, False, first_steps=first_steps)
    rng = np.random.default_rng(seed)
    run = Run()
    for frame in frames:
        points, colors = deproject(frame.depth, frame.color, frame.intrinsics)
        pose = frame.pose.matrix if posed else None
        learner.learn(points, colors, "world" if posed else "camera", pose)
        run.ghost.append(ghost_share(learner.model, points, pose, rng))
    run.nodes = learner.model.n_nodes_
    return run


class Open3DOdometry:
    """Open3D's RGB-D odometry, frame to frame (the peer)."""

    def __init__(self, o3d) -> None:
        self.o3d = o3d
        self.option = o3d.pipelines.odometry.OdometryOption()
        self.option.depth_min, self.option.depth_max = DEPTH_RANGE

    def image(self, frame: Frame):
        o3d = self.o3d
        return o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(frame.color)),
            o3d.geometry.Image(np.ascontiguousarray(frame.depth, dtype=np.uint16)),
            depth_scale=1000.0, depth_trunc=DEPTH_RANGE[1], convert_rgb_to_intensity=True)

    def relative(self, source: Frame, target: Frame, init: np.ndarray
                 ) -> tuple[bool, np.ndarray]:
        """(success, target_from_source (4, 4))."""
        o3d = self.o3d
        i = source.intrinsics
        camera = o3d.camera.PinholeCameraIntrinsic(i.width, i.height, i.fx, i.fy, i.cx, i.cy)
        success, motion, _ = o3d.pipelines.odometry.compute_rgbd_odometry(
            self.image(source), self.image(target), camera, init,
            o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm(), self.option)
        return bool(success), np.asarray(motion)

    def run(self, frames: list[Frame]) -> Run:
        run = Run(poses=[frames[0].pose.matrix], lost=[False])
        velocity = np.eye(4)
        for previous, frame in itertools.pairwise(frames):
            started = time.perf_counter()
            success, motion = self.relative(frame, previous, velocity)
            run.seconds += time.perf_counter() - started
            if not success:
                motion = np.eye(4)
                run.reasons["failed"] = run.reasons.get("failed", 0) + 1
            velocity = motion
            run.poses.append(run.poses[-1] @ motion)
            run.lost.append(not success)
        run.track_seconds = run.seconds
        return run


# ------------------------------------------------------------------------------------ report

def trajectory_line(name: str, run: Run, truth: list[np.ndarray]) -> str:
    aligned, anchored = ate(run.poses, truth)
    errors = rpe(run.poses, truth)
    frames = len(truth) - 1
    fps = frames / run.seconds if run.seconds else math.inf
    tracking = frames / run.track_seconds if run.track_seconds else math.inf
    lost = sum(run.lost)
    reasons = ", ".join(f"{k}: {v}" for k, v in sorted(run.reasons.items()))
    return (f"  {name:<40} {aligned * 1000:7.1f} {anchored * 1000:8.1f} "
            f"{errors['t_rmse'] * 1000:7.2f} {errors['t_max'] * 1000:7.1f} "
            f"{errors['r_rmse']:7.3f} {errors['r_max']:6.2f} {lost:5d} "
            f"{fps:6.1f} ({tracking:5.1f})" + (f"  [{reasons}]" if reasons else ""))


def ghost_line(name: str, run: Run) -> str:
    steady = np.array(run.ghost[len(run.ghost) // 2:])
    return f"  {name:<34} {steady.mean():7.2%} {steady.max():7.2%}"


def walk(scene: str, frames: int, args: argparse.Namespace, o3d) -> None:
    degradation = None if args.clean else Degradation()
    started = time.perf_counter()
    sequence = render(scene, frames, degradation, args.seed)
    missing = np.mean([np.mean(f.depth == 0) for f in sequence])
    print(f"\n{scene}: {frames} frames 640x480 rendered in {time.perf_counter() - started:.0f} s"
          f"; {degradation.describe() if degradation else 'virtual Kinect as is'}; "
          f"{missing:.0%} of the depth missing")
    truth = [f.pose.matrix for f in sequence]
    steps = np.array([OK.motion_size(a, b) for a, b in itertools.pairwise(truth)])
    print(f"  true motion between frames: up to {steps[:, 0].max() * 1000:.0f} mm and "
          f"{steps[:, 1].max():.2f} deg; path {steps[:, 0].sum():.2f} m")
    print(f"  {'method':<40} {'ATE mm':>7} {'anchored':>8} {'RPE mm':>7} {'max':>7} "
          f"{'RPE deg':>7} {'max':>6} {'lost':>5} {'fps':>6} (track)")
    ours = run_ours(sequence, args.steps, args.seed, args.first_steps)
    print(trajectory_line("ours (the learner, --track)", ours, truth), flush=True)
    print("  ours per frame, median ms: " + ", ".join(
        f"{stage} {np.median(times) * 1000:.1f}" for stage, times in ours.stages.items())
        + f"; map at the end: {ours.nodes} nodes")
    busy_learner(sequence, truth, args)
    if args.ablations:
        for name, (tracker, overrides) in ABLATIONS.items():
            variant = run_ours(sequence, args.steps, args.seed, args.first_steps, tracker,
                               overrides)
            print(trajectory_line(f"- {name}", variant, truth), flush=True)
        return
    if o3d is not None:
        peer = Open3DOdometry(o3d).run(sequence)
        print(trajectory_line("Open3D RGB-D odometry", peer, truth), flush=True)
    print(f"  {'ghost share of the map (steady state)':<34} {'mean':>7} {'worst':>7}")
    print(ghost_line("learned with tracked poses", ours))
    print(ghost_line("learned with true poses",
                     run_mapping(sequence, True, args.steps, args.seed, args.first_steps)))
    print(ghost_line("learned with no poses (camera frame)",
                     run_mapping(sequence, False, args.steps, args.seed, args.first_steps)),
          flush=True)


def busy_learner(sequence: list[Frame], truth: list[np.ndarray],
                 args: argparse.Namespace) -> None:
    """Ours on the frames a busy live learner takes: after each, the next 1-8 are dropped
    (drawn at random), with the frames' stamps (the motion continued over the time since the
    last tracked frame) and without (one frame's motion: the baseline); the first three are
    taken (a motion is known before the first drop), then also the first drop."""
    rng = np.random.default_rng(args.seed)
    taken = [0, 1, 2]
    while (following := taken[-1] + 1 + int(rng.integers(1, BUSY_DROPS + 1))) < len(sequence):
        taken.append(following)
    early = [0, *taken[3:]]  # frames 1 and 2 dropped too: no motion known at the first drop
    for name, frames, stamped in (("busy learner: with stamps", taken, True),
                                  ("- one motion per frame", taken, False),
                                  ("- frames 1 and 2 dropped too", early, True)):
        run = run_ours([sequence[i] for i in frames], args.steps, args.seed, args.first_steps,
                       stamped=stamped)
        print(trajectory_line(f"{name} ({len(frames)} frames)", run,
                              [truth[i] for i in frames]), flush=True)


def tum(args: argparse.Namespace, o3d) -> None:
    if not TUM.is_dir():
        print(f"\nTUM: {TUM} not found, skipped")
        return
    camera = load_camera(TUM, "redwood")
    frames = list(iter_image_frames(TUM, "redwood", camera=camera))
    truth = load_poses(TUM / "poses").matrices
    missing = np.mean([np.mean(f.depth == 0) for f in frames])
    print(f"\nTUM fr1/xyz ({len(frames)} real Kinect frames, {missing:.0%} of the depth missing; "
          "lens distortion not corrected, for either method): relative pose a -> b")
    print(f"  {'pair':<6} {'true mm':>8} {'true deg':>8} | {'ours mm':>8} {'deg':>6} "
          f"{'lost':>5} {'ms':>5} | {'Open3D mm':>9} {'deg':>6} {'ms':>5}")
    deproject = Deprojector(*DEPTH_RANGE)
    rows = []
    for a in range(len(frames)):
        for b in range(len(frames)):
            if a == b:
                continue
            true_step = rigid_inverse(truth[a]) @ truth[b]
            moved, turned = OK.motion_size(np.eye(4), true_step)
            model = new_map(args.seed)
            points, colors = deproject(frames[a].depth, frames[a].color, frames[a].intrinsics)
            model.partial_fit(points, colors, n_steps=args.first_steps, camera_pose=truth[a])
            odometry = MapOdometry(min_depth_m=DEPTH_RANGE[0], max_depth_m=DEPTH_RANGE[1])
            odometry.reset(truth[a])
            started = time.perf_counter()
            result = odometry.track(deproject.organized(frames[b].depth, frames[b].intrinsics),
                                    frames[b].color, MapSurface.from_model(model))
            ours_ms = (time.perf_counter() - started) * 1000
            ours = OK.motion_size(true_step, rigid_inverse(truth[a]) @ result.pose)
            line = (f"  {a}->{b:<3} {moved * 1000:8.1f} {turned:8.2f} | {ours[0] * 1000:8.1f} "
                    f"{ours[1]:6.2f} {result.reason or 'no':>5} {ours_ms:5.0f} |")
            row = [moved, turned, ours[0], ours[1]]
            if o3d is not None:
                started = time.perf_counter()
                success, motion = Open3DOdometry(o3d).relative(frames[b], frames[a], np.eye(4))
                peer_ms = (time.perf_counter() - started) * 1000
                peer = OK.motion_size(true_step, motion)
                line += f" {peer[0] * 1000:9.1f} {peer[1]:6.2f} {peer_ms:5.0f}"
                line += "" if success else " (failed)"
                row += [peer[0], peer[1]]
            rows.append(row)
            print(line, flush=True)
    rows = np.array(rows)
    line = (f"  {'RMSE':<6} {'':>8} {'':>8} | {np.sqrt(np.mean(rows[:, 2] ** 2)) * 1000:8.1f} "
            f"{np.sqrt(np.mean(rows[:, 3] ** 2)):6.2f} {'':>5} {'':>5} |")
    if rows.shape[1] > 4:
        line += (f" {np.sqrt(np.mean(rows[:, 4] ** 2)) * 1000:9.1f} "
                 f"{np.sqrt(np.mean(rows[:, 5] ** 2)):6.2f}")
    print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES))
    parser.add_argument("--frames", type=int, default=None, help="frames per scene")
    parser.add_argument("--quick", action="store_true",
                        help="the walk one way only (120 frames), and TUM")
    parser.add_argument("--no-peer", action="store_true", help="skip Open3D")
    parser.add_argument("--no-tum", action="store_true", help="skip the TUM frames")
    parser.add_argument("--clean", action="store_true",
                        help="the virtual Kinect's frames without the extra degradation")
    parser.add_argument("--first-steps", type=int, default=LearnerOptions().first_frame_steps,
                        help="steps on the first frame (default: the learner's "
                        "first_frame_steps): the next frame is aligned to it")
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0,
                        help="sensor noise, degradation and learning seed")
    parser.add_argument("--ablations", action="store_true",
                        help="ours with one part changed at a time (ABLATIONS), walks only")
    args = parser.parse_args()
    o3d, version = (None, "skipped") if args.no_peer else load_open3d()
    print(f"map: the learner's in a fixed frame, GNG-DT {MAP_PARAMS}; {args.first_steps:,} "
          f"steps on the first frame, {args.steps:,} per tracked frame; tracker: TrackerParams "
          f"defaults; peer: {version}")
    scenes = ["tabletop_walk"] if args.quick else args.scenes
    for scene in scenes:
        frames = args.frames or (120 if args.quick else SCENES[scene])
        walk(scene, frames, args, o3d)
    if not args.no_tum and not args.ablations:
        tum(args, o3d)


if __name__ == "__main__":
    main()
