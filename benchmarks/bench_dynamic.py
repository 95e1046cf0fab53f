"""A moving camera and a changing scene: issue 11's targets, measured on the virtual Kinect.

Renders the moving scenes (``tabletop_walk``: a camera walking through a static scene and back;
``tabletop_vanish``: the red box vanishes at frame 60; ``tabletop_move``: the blue sphere slides
0.3 m from frame 60 to 105), writes them as recordings with poses, and replays each as the learner
does (``gngdt eval recording``'s replay: 10,000 steps a frame, 1,000 nodes) in the world frame,
with the learner's profile (forgetting and rehearsal), with forgetting alone (the profile before
rehearsal) and, as the baseline in the same run, with neither (the paper's GNG-DT); the walk also
in the camera frame. Prints per run: the ghost share in steady state (the
second half of the frames; mean and worst frame), the largest node count, the position error on
the world seen so far over that of k-means with as many centres (fitted on the other half of the
same world sample; steady-state mean and last), the out-of-view nodes kept at the end, and for a
changed object the frames until its old-place nodes were gone.

    python benchmarks/bench_dynamic.py [--width 640 --height 480] [--quick] [--scenes ...]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from gngdt_core.frame_learner import LEARNER_MODEL_DEFAULTS
from gngdt_eval.dynamics import DynamicsSettings
from gngdt_eval.recording_eval import RecordingSettings, replay, summarise_over_time
from gngdt_io.mcap_writer import RecordingWriter
from gngdt_io.synth.render import SCENE_METADATA, render_scene, scene_metadata
from gngdt_io.synth.scenes import build_scene

#: scene -> frames rendered (the walk goes out and back: 240 frames at 30 fps)
SCENES = {"tabletop_walk": 240, "tabletop_vanish": 150, "tabletop_move": 150}


def record(scene: str, frames: int, width: int, height: int, folder: Path) -> Path:
    path = folder / f"{scene}.mcap"
    with RecordingWriter(path) as writer:
        writer.add_metadata(SCENE_METADATA, scene_metadata(build_scene(scene), 30.0))
        for frame in render_scene(scene, frames, width=width, height=height):
            writer.write_frame(frame)
    return path


def run(path: Path, forgetting: bool, rehearsal: bool, world: bool,
        reference_every: int) -> dict:
    settings = RecordingSettings(
        methods=("GNG-DT",),
        utility_k=LEARNER_MODEL_DEFAULTS["utility_k"] if forgetting else None,
        replay_share=LEARNER_MODEL_DEFAULTS["replay_share"] if rehearsal else 0.0,
        world_frame=world,
        dynamics=DynamicsSettings(reference_every=reference_every),
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--quick", action="store_true",
                        help="320x240 and the walk one way only (a smoke run)")
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES),
                        help="scenes to run (default: all three)")
    args = parser.parse_args()
    width, height = (320, 240) if args.quick else (args.width, args.height)
    frames = dict(SCENES, tabletop_walk=120) if args.quick else SCENES
    scenes = {scene: frames[scene] for scene in args.scenes}
    print(f"virtual Kinect {width}x{height} at 30 fps; learner: 10,000 steps a frame, 1,000 "
          f"nodes; the learner's profile = {LEARNER_MODEL_DEFAULTS}")
    print(f"{'run':>40} {'ghost':>7} {'worst':>7} {'nodes':>6} {'err/k-means':>15} "
          f"{'kept':>6} {'forgot':>6}  frames until the old place is empty")
    print(f"{'':>40} {'steady':>7} {'frame':>7} {'max':>6} {'steady / last':>15} "
          f"{'oov':>6}")
    with tempfile.TemporaryDirectory() as folder:
        for scene, frames in scenes.items():
            started = time.perf_counter()
            path = record(scene, frames, width, height, Path(folder))
            print(f"{scene}: {frames} frames rendered in {time.perf_counter() - started:.0f} s")
            runs = [("world, forgetting + rehearsal", True, True, True),
                    ("world, forgetting, no rehearsal", True, False, True),
                    ("world, neither (paper)", False, False, True)]
            if scene == "tabletop_walk":
                runs.append(("camera frame, forgetting + rehearsal", True, True, False))
            for name, forgetting, rehearsal, world in runs:
                result = run(path, forgetting, rehearsal, world, reference_every=30)
                print(line(name, result), flush=True)


if __name__ == "__main__":
    main()
