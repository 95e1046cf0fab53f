"""Segment RGB-D frames into objects: a uint16 label image per frame and a JSON summary.

SOURCE is a recording (gngdt's MCAP, a ROS 2 bag, a RealSense .db3/.bag) or a folder of frames
in a layout ``gngdt record images`` reads (redwood, tum, pcl-tiff; detected, or ``--format``).
Each frame is deprojected to an organized point array and segmented by GNG-DT
(`gngdt.core.learner.frame_segmenter.FrameSegmenter`): by default online, one network carried from
frame to frame; with ``--independent`` every frame is learned from scratch (unrelated snapshots).

Outputs in ``--out DIR``: ``<name>.png`` per frame, a uint16 label image of the frame's size
(0 = no segment: no depth there; k >= 1 = segment k, by decreasing size), ``<name>`` being the
colour image's file stem for a folder and the 0-based frame index as 6 digits for a recording;
and ``summary.json`` (per frame: nodes, segments, steps, milliseconds per phase; the mode, the
parameters and the intrinsics used). Every frame is read once before any learning, so bad input
fails fast with the file named; outputs are written into a hidden folder beside DIR that becomes
DIR only when every frame is done. On failure DIR is left as it was (absent, or untouched) and
the exit code is 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from gngdt.io.frame import Frame
    from gngdt.io.profiles import Profile
    from gngdt.io.sources import FrameSource

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt segment recordings/tabletop.mcap --out seg/tabletop        # online: one network
  gngdt segment ../shared/data/labelled/mosd_learn --out seg/mosd --independent
  gngdt segment fr1_desk/ --format tum --out seg/desk --params my_profile.toml
  gngdt segment scans/ --out seg/scans --camera-json kinect.json --overwrite

--params FILE.toml: tables [gngdt] (GNGDT arguments, e.g. max_nodes, lambda), [segmentation]
(SegmentationParams) and [frames] (FrameSchedule: steps per frame, depth range, ...); keys left
out take the classes' defaults; [learner] is ignored. Without it: the default sensor profile.
"""

SUMMARY_NAME = "summary.json"
LABEL_DESCRIPTION = "uint16 PNG per frame, same size as its colour/depth image; 0 = no segment, " \
                    "k >= 1 = segment k (1 = largest)"


def write_label_image(path: Path, labels: np.ndarray) -> None:
    """Write (H, W) int labels >= 0 as a uint16 PNG; ValueError when they do not fit."""
    import cv2

    if labels.size and (labels.min() < 0 or labels.max() > np.iinfo(np.uint16).max):
        raise ValueError(f"{path}: labels {labels.min()}..{labels.max()} do not fit uint16")
    if not cv2.imwrite(str(path), labels.astype(np.uint16)):
        raise OSError(f"{path}: cannot write the label image")


def compile_kernels(profile: Profile, seed: int) -> float:
    """Compile (or load from numba's cache) the segmenter's kernels on a small frame, logging
    each step, so that the first real frame's time is its own; the seconds it took."""
    from gngdt.core.learner.warm_up import logged_progress, warm_up_segmenter
    from gngdt.io.segment_frames import make_segmenter

    started = time.perf_counter()
    log.info("preparing the kernels (the first run on a machine compiles them: 15-40 s)")
    warm_up_segmenter(make_segmenter(profile, seed), logged_progress(log))
    seconds = time.perf_counter() - started
    log.info("kernels ready in %.1f s", seconds)
    return seconds


def segment_source(source: FrameSource, profile: Profile, out: Path, *,
                   independent: bool = False, seed: int = 0, overwrite: bool = False
                   ) -> dict[str, Any]:
    """Segment every frame of ``source`` into ``out`` (label PNGs + summary.json, written as a
    whole or not at all); returns the summary."""
    from gngdt.core.sensor.depth import DepthRange
    from gngdt.eval.report import to_jsonable
    from gngdt.io.errors import RecordingError
    from gngdt.io.import_checks import depth_warning
    from gngdt.io.segment_frames import make_segmenter, segment_frames, timing_summary
    from gngdt.io.staged_directory import StagedDirectory

    staged = StagedDirectory(out, overwrite=overwrite)  # refuses a non-empty DIR before work
    log.info("checking %s (%s) ...", source.path, source.format)
    depth = DepthRange()
    total = source.check(depth)
    warnings = [*source.assumptions, *filter(None, [depth_warning(depth)])]
    for warning in warnings:
        log.warning("%s", warning)
    mode = "independent" if independent else "online"
    compile_seconds = compile_kernels(profile, seed)
    log.info("%d frames; segmenting %s with %s", total, mode, profile.path)
    segmenter = make_segmenter(profile, seed)
    frames: list[dict[str, Any]] = []
    first: Frame | None = None
    started = time.perf_counter()
    with staged as staging:
        for item in segment_frames(source, segmenter, independent):
            first = first or item.frame
            write_label_image(staging / f"{item.name}.png", item.result.labels)
            height, width = item.result.labels.shape
            frames.append({"name": item.name, "index": item.frame.index, "width": width,
                           "height": height, "nodes": item.result.n_nodes,
                           "segments": item.result.n_segments, "steps": item.result.steps,
                           "milliseconds": item.milliseconds})
            log.info("frame %d/%d %s: %d nodes, %d segments, %.0f ms", len(frames), total,
                     item.name, item.result.n_nodes, item.result.n_segments,
                     item.milliseconds["total"])
        if first is None:
            raise RecordingError(source.path, None, "no frames")
        intrinsics = first.intrinsics  # of the first frame (a recording may change them)
        summary = {
            "source": str(source.path), "format": source.format, "mode": mode,
            "frames": len(frames), "labels": LABEL_DESCRIPTION,
            "intrinsics": {"fx": intrinsics.fx, "fy": intrinsics.fy, "cx": intrinsics.cx,
                           "cy": intrinsics.cy, "from": source.camera_note},
            "parameters": {**profile.as_dict(), "random_state": seed},
            "warnings": warnings,
            "milliseconds": timing_summary([frame["milliseconds"] for frame in frames]),
            "compile_seconds": compile_seconds,
            "wall_seconds": time.perf_counter() - started,
            "per_frame": frames,
        }
        (staging / SUMMARY_NAME).write_text(
            json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return summary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from gngdt.io.sources import SOURCE_FORMATS
    from gngdt.services.capture import add_camera_arguments

    parser.add_argument("source", type=Path, metavar="SOURCE",
                        help="a recording (MCAP, ROS 2 bag, RealSense .db3/.bag), or a "
                        "folder of colour/depth frames")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="output folder (must be absent or empty unless --overwrite)")
    parser.add_argument("--independent", action="store_true",
                        help="learn every frame from scratch (default: online, one network "
                             "carried from frame to frame)")
    parser.add_argument("--params", type=Path, metavar="FILE.toml",
                        help="sensor profile (default: config/kinect.toml, installed with gngdt "
                             "as gngdt.config; `python -m gngdt.config` prints where)")
    parser.add_argument("--format", dest="source_format", choices=SOURCE_FORMATS,
                        help="source layout (default: detected; needed when it is ambiguous)")
    add_camera_arguments(parser)
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace a non-empty --out folder once the new one is complete")


def main(args: argparse.Namespace) -> int:
    """Run ``gngdt segment``; bad input: one error line naming the file, exit code 2."""
    from gngdt.io.errors import RecordingError
    from gngdt.io.profiles import default_sensor_profile, load_profile
    from gngdt.io.sources import SourceOptions, open_source

    try:
        profile = load_profile(args.params or default_sensor_profile(), base_model={})
        source = open_source(args.source, args.source_format,
                             SourceOptions(camera_json=args.camera_json,
                                           depth_scale=args.depth_scale))
        summary = segment_source(source, profile, args.out, independent=args.independent,
                                 seed=args.seed, overwrite=args.overwrite)
    except (RecordingError, ValueError, OSError) as error:
        log.error("gngdt segment: %s", error)
        log.error("gngdt segment: nothing written to %s", args.out)
        return 2
    total = summary["milliseconds"]["total"]
    print(f"wrote {summary['frames']} label images and {SUMMARY_NAME} to {args.out} "
          f"({summary['mode']}, {total['p50']:.0f} ms/frame p50, {total['p90']:.0f} p90; "
          f"kernels ready in {summary['compile_seconds']:.1f} s before the first frame)")
    for warning in summary["warnings"]:
        print(f"WARNING: {warning}")
    return 0
