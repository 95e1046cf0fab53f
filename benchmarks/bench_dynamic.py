"""A moving camera and a changing scene, measured on the virtual Kinect (issues 11 and 27).

Three parts (``--parts``, default all):

- **map** (issue 27, "resolution, not a count"): the walk (``tabletop_walk``: 3.2 m sideways
  past a table, a crate and a bin, and back) replayed through the learner's own per-frame policy
  (`FrameLearner`, as ``gngdt eval recording`` does: 10,000 steps a frame) with the learner's
  map in a fixed frame (one node per 0.1 m cell of surface seen, ``LEARNER_WORLD_DEFAULTS``) and,
  as the baseline in the same run, the fixed budget of 1,000 nodes it had before. Printed along
  the walk, every ``--every`` frames: nodes, the position error on the world seen so far and its
  ratio to k-means with as many centres (fitted on the other half of the same world sample; the
  sample holds ``WORLD_POINTS_PER_NODE`` points per node of the largest map); then the worst
  ratio over the walk. The same on the real posed frames of ``../shared/data/rgbd`` (TUM fr1/xyz,
  three frames with ground-truth poses), frame by frame.
- **load** (issue 27, "keep up"): the walk, recorded with its poses, streamed at its recorded
  30 fps through the real pipeline (``gngdt capture`` -> ``gngdt learn`` -> ``gngdt log`` on a
  loopback router), quiet and with ``--busy`` processes spinning beside it, once with the time
  budget (``frame_time_share = 0.8``) and once without (the learner's default: every frame
  learned fully, or dropped). Printed per run: frames learned of frames sent, mean steps per
  learned frame, the position error on the world seen so far along the walk (the latest
  topology published by then, every 10th frame) and its ratio to the quiet run's with the same
  settings, and k-means's ratio at the end.
- **changes** (issue 11): the walk and the scenes where the red box vanishes at frame 60
  (``tabletop_vanish``) and the blue sphere slides 0.3 m (``tabletop_move``), replayed with the
  learner's profile (forgetting and rehearsal), with forgetting alone and with neither (the
  paper's GNG-DT), the walk also in the camera frame: ghost share in steady state (mean and
  worst frame), largest node count, error over k-means (steady mean / last), out-of-view nodes
  kept, and frames until a changed object's old-place nodes are gone.

The camera tracking of ``--track`` (its ATE and frames per second beside Open3D's RGB-D
odometry, on the same walk with real-sensor-like damage): ``benchmarks/bench_tracking.py``.

    python benchmarks/bench_dynamic.py [--quick] [--parts map load changes] [--busy 2]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from gngdt.core.learner.frame_learner import LEARNER_MODEL_DEFAULTS, LEARNER_WORLD_DEFAULTS
from gngdt.eval.dynamics import DynamicsSettings, DynamicsTracker
from gngdt.eval.recording_eval import RecordingSettings, frame_points, replay, summarise_over_time
from gngdt.io.deproject import RUN_POINT_CAP as RUN_MAX_POINTS
from gngdt.io.mcap.writer import RecordingWriter
from gngdt.io.synth.render import SCENE_METADATA, render_scene, scene_metadata
from gngdt.io.synth.scenes import build_scene
from gngdt.schemas.wire import ALL_KEYS, DEFAULT_CAMERA, LEARNER, alive_key

#: scene -> frames rendered (the walk goes out and back: 240 frames at 30 fps)
SCENES = {"tabletop_walk": 240, "tabletop_vanish": 150, "tabletop_move": 150}
TUM = Path(__file__).resolve().parents[2] / "shared/data/rgbd/tum_fr1_xyz_dvo_examples"
#: world sample points per node of the largest map: k-means is fitted on half of them
WORLD_POINTS_PER_NODE = 40
#: part "load": the time budget's share of the frame interval (``frame_time_share``)
BUDGET_SHARE = 0.8
#: the map variants of part "map": name -> RecordingSettings overrides
MAP_RUNS = {
    f"resolution {LEARNER_WORLD_DEFAULTS['resolution_m']} m (the learner's)": {},
    "fixed budget 1000 nodes (before)": {"resolution_m": 0.0, "max_nodes": 1000},
}


def record(scene: str, frames: int, width: int, height: int, folder: Path) -> Path:
    path = folder / f"{scene}.mcap"
    with RecordingWriter(path) as writer:
        writer.add_metadata(SCENE_METADATA, scene_metadata(build_scene(scene), 30.0))
        for frame in render_scene(scene, frames, width=width, height=height):
            writer.write_frame(frame)
    return path


def record_tum(folder: Path) -> Path | None:
    """The shared TUM frames with their ground-truth poses as a recording (None: absent)."""
    from gngdt.io.frame import CameraPose
    from gngdt.io.images import iter_image_frames, load_camera
    from gngdt.io.pose_files import load_poses

    if not TUM.is_dir():
        return None
    poses = load_poses(TUM / "poses").matrices
    path = folder / "tum_fr1_xyz.mcap"
    camera = load_camera(TUM, "redwood")
    with RecordingWriter(path) as writer:
        for index, frame in enumerate(iter_image_frames(TUM, "redwood", camera=camera)):
            frame.pose = CameraPose(poses[index], "world")
            frame.timestamp_ns = (index + 1) * 33_000_000
            writer.write_frame(frame)
    return path


# ------------------------------------------------------------------------------------ map

def map_curve(path: Path, every: int, overrides: dict, world_points: int) -> list[dict]:
    """Per reference frame: frame, nodes, world error (m) and its ratio to k-means."""
    settings = RecordingSettings(methods=("GNG-DT",), **overrides, dynamics=DynamicsSettings(
        reference_every=every, world_sample=world_points))
    result = replay(path, "GNG-DT", 0, settings)
    return [{"frame": frame["frame"], "nodes": frame["nodes"],
             "error": frame["dynamics"]["world_qe_pos"],
             "ratio": frame["dynamics"]["world_ratio_to_kmeans"]}
            for frame in result["frames"] if "world_ratio_to_kmeans" in frame["dynamics"]]


def print_curves(curves: dict[str, list[dict]]) -> None:
    names = list(curves)
    print(f"  {'frame':>5} " + " ".join(f"| {'nodes':>6} {'err mm':>6} {'/k-means':>8}"
                                          for _ in names) + "   (" + "; ".join(names) + ")")
    for row in zip(*curves.values(), strict=True):
        print(f"  {row[0]['frame']:>5} " + " ".join(
            f"| {point['nodes']:>6} {point['error'] * 1000:>6.1f} {point['ratio']:>8.3f}"
            for point in row))
    for name, curve in curves.items():
        worst = max(curve, key=lambda point: point["ratio"])
        print(f"  {name}: worst ratio {worst['ratio']:.3f} (frame {worst['frame']}), "
              f"last {curve[-1]['ratio']:.3f}")


def part_map(args: argparse.Namespace, folder: Path) -> None:
    frames = 120 if args.quick else SCENES["tabletop_walk"]
    path = record("tabletop_walk", frames, args.width, args.height, folder)
    world_points = WORLD_POINTS_PER_NODE * (5_000 if not args.quick else 4_000)
    print(f"\n[map] tabletop_walk, {frames} frames {args.width}x{args.height}; world sample "
          f"{world_points:,} points; k-means every {args.every} frames")
    print_curves({name: map_curve(path, args.every, overrides, world_points)
                  for name, overrides in MAP_RUNS.items()})
    tum = record_tum(folder)
    if tum is None:
        print(f"\n[map] real posed frames: {TUM} not found, skipped")
        return
    print("\n[map] TUM fr1/xyz, 3 real Kinect frames with ground-truth poses, each frame")
    print_curves({name: map_curve(tum, 1, overrides, 40_000)
                  for name, overrides in MAP_RUNS.items()})


# ------------------------------------------------------------------------------------ load

def spin() -> subprocess.Popen:
    """A busy process: one core's worth of pure Python spinning."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def pipeline_run(recording: Path, workdir: Path, params: Path | None, busy: int) -> dict:
    """The walk through capture -> learner -> logger at 30 fps with ``busy`` spinning
    processes beside it; the learner's last status, the end of stream, and every topology's
    node positions by frame sequence."""
    from gngdt.schemas.topology import decode_topology
    from gngdt.schemas.wire import LOGGER_ALIVE, topic
    from gngdt.services.plumbing.session import free_tcp_port, open_config
    from gngdt.services.run import Observed, Pipeline, RunAccess, wait_until

    access = RunAccess(f"tcp/127.0.0.1:{free_tcp_port()}", workdir)
    router = open_config(access.router(), what="router")
    observed, topologies, lock = Observed(), {}, threading.Lock()

    def on_topology(sample) -> None:
        snapshot = decode_topology(sample.payload.to_bytes())
        with lock:
            topologies[snapshot.frame_sequence] = np.array(snapshot.positions)

    declared = [
        router.liveliness().declare_subscriber(ALL_KEYS, observed.on_liveliness, history=True),
        router.declare_subscriber(topic("camera", "learner/status"), observed.on_status),
        router.declare_subscriber(topic("camera", "eos"), observed.on_eos),
        router.declare_subscriber(topic("camera", "topology"), on_topology)]
    pipeline, stop, spinners = Pipeline(access, workdir, "WARNING"), threading.Event(), []
    try:
        extra = ["--params", str(params)] if params else []
        learner = pipeline.start("learn", ["--exit-on-eos", *extra])
        pipeline.start("log", ["--save", str(workdir / "load.rrd")])
        wait_until(lambda: observed.has_alive(alive_key(DEFAULT_CAMERA, LEARNER))
                   and observed.has_alive(LOGGER_ALIVE), 300, stop, pipeline)
        spinners = [spin() for _ in range(busy)]
        # as `gngdt run` starts it: a random 50,000 points of each cloud
        pipeline.start("capture", [str(recording), "--realtime", "--max-points",
                                    str(RUN_MAX_POINTS)])
        started = time.monotonic()
        while learner.process.poll() is None and time.monotonic() - started < 600:
            time.sleep(0.2)
        failed = pipeline.failed()
        if failed is not None:
            raise RuntimeError(f"{failed.name} failed:\n{failed.stderr_tail()}")
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
        pipeline.interrupt_all()
        pipeline.close()
        for entity in declared:
            entity.undeclare()
        router.close()
    return {"status": observed.status, "end": observed.end, "topologies": topologies}


class Nodes:
    """Node positions as `DynamicsTracker.world_reference` reads a model."""

    def __init__(self, positions: np.ndarray) -> None:
        self.positions_ = positions


def errors_along(recording: Path, topologies: dict[int, np.ndarray], every: int) -> dict:
    """The position error on the world seen so far, every ``every`` frames, of the latest
    topology published by then; k-means's ratio on the last frame."""
    from scipy.spatial import cKDTree

    tracker = DynamicsTracker(DynamicsSettings(world_sample=WORLD_POINTS_PER_NODE * 4_000), [],
                              posed=True)
    sequences = np.array(sorted(topologies))
    errors, last = {}, None
    for count, points in enumerate(frame_points(recording, RecordingSettings()), start=1):
        tracker.world.update(points.positions, points.view, count)
        known = sequences[sequences <= points.index]
        if known.size and (points.index % every == every - 1):
            nodes = topologies[int(known[-1])]
            distance = cKDTree(nodes).query(tracker.world.points, k=1)[0]
            errors[points.index] = float(np.sqrt(np.mean(distance ** 2)))
        last = points
    final = tracker.world_reference(Nodes(topologies[int(sequences[-1])]))
    return {"errors": errors, "ratio": final.get("world_ratio_to_kmeans", float("nan")),
            "frames": last.index + 1}


def part_load(args: argparse.Namespace, folder: Path) -> None:
    frames = 120 if args.quick else SCENES["tabletop_walk"]
    recording = record("tabletop_walk", frames, 640, 480, folder)
    budget = folder / "budget.toml"
    budget.write_text(f"[learner]\nframe_time_share = {BUDGET_SHARE}\n")
    print(f"\n[load] tabletop_walk with poses, {frames} frames 640x480 at 30 fps through "
          f"capture -> learn -> log; {args.busy} busy processes beside it (python -c 'while "
          "True: pass') or none; the learner's defaults")
    print(f"  {'run':<34} {'learned':>9} {'steps/frame':>11} {'error mm':>9} {'/quiet':>14} "
          f"{'/k-means':>8}")
    print(f"  {'':<34} {'':>9} {'':>11} {'mean last':>9} {'mean worst':>14} {'last':>8}")
    for budget_name, params in ((f"time budget {BUDGET_SHARE}", budget),
                                ("no budget (the default)", None)):
        quiet = None
        for busy in (0, args.busy):
            with tempfile.TemporaryDirectory(dir=folder) as workdir:
                run = pipeline_run(recording, Path(workdir), params, busy)
            status, end = run["status"], run["end"]
            along = errors_along(recording, run["topologies"], 10)
            errors = np.array([along["errors"][k] for k in sorted(along["errors"])])
            quiet = errors if busy == 0 else quiet
            shared = min(len(errors), len(quiet))
            versus = errors[:shared] / quiet[:shared]
            name = f"{budget_name}, {'quiet' if busy == 0 else f'{busy} busy'}"
            print(f"  {name:<34} {status.frames_used:>4}/{end.frames_sent:<4} "
                  f"{status.steps / max(status.frames_used, 1):>11,.0f} "
                  f"{errors.mean() * 1000:>4.1f} {errors[-1] * 1000:>4.1f} "
                  f"{versus.mean():>6.3f} {versus.max():>6.3f} {along['ratio']:>8.3f}",
                  flush=True)


# ------------------------------------------------------------------------------------ changes

def run_changes(path: Path, forgetting: bool, rehearsal: bool, world: bool) -> dict:
    settings = RecordingSettings(
        methods=("GNG-DT",),
        utility_k=LEARNER_MODEL_DEFAULTS["utility_k"] if forgetting else None,
        replay_share=LEARNER_MODEL_DEFAULTS["replay_share"] if rehearsal else 0.0,
        world_frame=world,
        dynamics=DynamicsSettings(reference_every=30),
    )
    started = time.perf_counter()
    result = replay(path, "GNG-DT", 0, settings)
    result["seconds"] = time.perf_counter() - started
    return result


def frames_until_gone(summary: dict | None) -> str:
    """'never' when some trial's old place kept nodes to the end, else the mean frames."""
    return "never" if summary is None else f"{summary['mean']:g}"


def line(name: str, result: dict) -> str:
    over = summarise_over_time([result])
    frames = [frame["dynamics"] for frame in result["frames"]]
    steady = frames[len(frames) // 2:]
    ratios = [d["world_ratio_to_kmeans"] for d in steady if "world_ratio_to_kmeans" in d]
    changes = ", ".join(
        f"{name}: {frames_until_gone(c['frames_until_gone'])}"
        f" (from {c['old_place_nodes_at_change']} nodes)"
        for name, c in over["changes"].items()) or "-"
    ratio = (f"{np.mean(ratios):.3f} / {ratios[-1]:.3f}" if ratios else "-")
    kept = frames[-1].get("out_of_view_nodes", "-")
    return (f"{name:>40} {over['ghost_share_steady']['mean']:>7.2%} "
            f"{over['ghost_share_steady_max']['mean']:>7.2%} "
            f"{over['nodes_max']['mean']:>6.0f} {ratio:>15} {kept!s:>6} "
            f"{over['forgotten']['mean']:>6.0f}  {changes}  ({result['seconds']:.0f} s)")


def part_changes(args: argparse.Namespace, folder: Path) -> None:
    frames = dict(SCENES, tabletop_walk=120) if args.quick else SCENES
    print(f"\n[changes] virtual Kinect {args.width}x{args.height} at 30 fps; the learner: 10,000 "
          f"steps a frame; its profile = {LEARNER_MODEL_DEFAULTS}, map in a fixed frame "
          f"{LEARNER_WORLD_DEFAULTS}")
    print(f"{'run':>40} {'ghost':>7} {'worst':>7} {'nodes':>6} {'err/k-means':>15} "
          f"{'kept':>6} {'forgot':>6}  frames until the old place is empty")
    print(f"{'':>40} {'steady':>7} {'frame':>7} {'max':>6} {'steady / last':>15} "
          f"{'oov':>6}")
    for scene in args.scenes:
        started = time.perf_counter()
        path = record(scene, frames[scene], args.width, args.height, folder)
        print(f"{scene}: {frames[scene]} frames rendered in {time.perf_counter() - started:.0f} s")
        runs = [("world, forgetting + rehearsal", True, True, True),
                ("world, forgetting, no rehearsal", True, False, True),
                ("world, neither (paper)", False, False, True)]
        if scene == "tabletop_walk":
            runs.append(("camera frame, forgetting + rehearsal", True, True, False))
        for name, forgetting, rehearsal, world in runs:
            print(line(name, run_changes(path, forgetting, rehearsal, world)), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", choices=("map", "load", "changes"),
                        default=["map", "load", "changes"])
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--quick", action="store_true",
                        help="320x240 and the walk one way only (a smoke run)")
    parser.add_argument("--every", type=int, default=20,
                        help="map: k-means every this many frames (default 20)")
    parser.add_argument("--busy", type=int, default=2, help="load: busy processes (default 2)")
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES),
                        help="changes: scenes to run (default: all three)")
    args = parser.parse_args()
    if args.quick:
        args.width, args.height = 320, 240
    with tempfile.TemporaryDirectory() as folder:
        parts = {"map": part_map, "load": part_load, "changes": part_changes}
        for name in args.parts:
            parts[name](args, Path(folder))


if __name__ == "__main__":
    main()
