"""Make recordings: render a synthetic scene, import real RGB-D frames or record a RealSense
into an MCAP file."""

from __future__ import annotations

import argparse
import logging
import os
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt.io.errors import RecordingError
from gngdt.io.frame import Frame

if TYPE_CHECKING:
    from gngdt.io.import_checks import ImportChecks

logger = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt record synth --scene tabletop --frames 30 --out recordings/tabletop.mcap
  gngdt record synth --scene tabletop_vanish --frames 90 --out vanish.mcap   # a changing scene
  gngdt record images --format redwood ../shared/data/rgbd/rtabmap_rgbd_test --out lab.mcap
  gngdt record images --format tum rgbd_dataset_freiburg1_xyz --out fr1_xyz.mcap \\
      --poses rgbd_dataset_freiburg1_xyz/groundtruth.txt
  gngdt record images --format redwood ../shared/data/rgbd/tum_fr1_xyz_dvo_examples \\
      --poses ../shared/data/rgbd/tum_fr1_xyz_dvo_examples/poses --out tum3.mcap
  gngdt record images --format pcl-tiff frames/ --out grabber.mcap --fx 525 --fy 525
  gngdt record realsense --out desk.mcap --seconds 20   # the RealSense plugged in
  gngdt record synth --help                     # scenes and every option
"""

#: Log a progress line every this many frames.
PROGRESS_EVERY = 10


SYNTH_EXAMPLES = """examples:
  gngdt record synth --scene tabletop --frames 30 --out recordings/tabletop.mcap
  gngdt record synth --scene data2 --frames 10 --width 320 --height 240 --out small.mcap
  gngdt record synth --scene tabletop --frames 90 --fps 15 --color-format jpeg --out jpeg.mcap
"""

REALSENSE_EXAMPLES = """examples:
  gngdt record realsense --out desk.mcap --seconds 20          # 20 s of the camera plugged in
  gngdt record realsense --out desk.mcap                       # until Ctrl-C
  gngdt record realsense --serial 123456789012 --mode 848x480@30 --out desk.mcap
  gngdt record realsense --from session.db3 --out session.mcap  # a RealSense Viewer recording
"""

IMAGES_EXAMPLES = """examples:
  gngdt record images --format redwood ../shared/data/rgbd/rtabmap_rgbd_test --out lab.mcap
  gngdt record images --format tum rgbd_dataset_freiburg1_xyz --out fr1_xyz.mcap
  gngdt record images --format pcl-tiff frames/ --out grabber.mcap --fx 525 --fy 525
  gngdt record images --format tum my_frames/ --camera-json my_camera.json --out mine.mcap
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``synth`` and ``images`` sub-subcommands."""
    from gngdt.io.images import FORMATS
    from gngdt.io.import_checks import POSE_LIMITS_TITLE, add_pose_limit_arguments
    from gngdt.io.mcap.writer import COLOR_FORMATS, COMPRESSIONS
    from gngdt.io.synth.render import SCENES

    kinds = parser.add_subparsers(dest="record_kind", required=True, metavar="KIND")

    def add_output_options(sub: argparse.ArgumentParser, fps: bool = True) -> None:
        sub.add_argument("--out", type=Path, required=True, metavar="PATH.mcap",
                         help="MCAP file to write (replaced if it exists)")
        if fps:
            sub.add_argument("--fps", type=float, default=30.0,
                             help="frame rate of the recording's stamps (default: %(default)g)")
        sub.add_argument("--compression", choices=COMPRESSIONS, default="zstd",
                         help="MCAP chunk compression (default: %(default)s)")
        sub.add_argument(
            "--color-format",
            choices=COLOR_FORMATS,
            default="raw",
            help="colour as a RawImage rgb8 (raw) or a CompressedImage jpeg/png "
            "(default: %(default)s)",
        )

    scene_lines = "\n".join(f"  {name:<16} {text}" for name, text in sorted(SCENES.items()))
    synth = kinds.add_parser(
        "synth",
        help="render a synthetic scene with ground-truth labels and camera poses",
        description="Render a synthetic scene with the virtual Kinect: colour, depth, "
        "ground-truth labels and the camera's pose (/tf) per frame.\n\nscenes:\n" + scene_lines,
        epilog=SYNTH_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    synth.add_argument("--scene", required=True, choices=sorted(SCENES), metavar="NAME",
                       help=f"scene to render: {', '.join(sorted(SCENES))} (described above)")
    synth.add_argument("--frames", type=int, required=True, help="number of frames to render")
    synth.add_argument("--width", type=int, default=640,
                       help="image width in pixels (default: %(default)s)")
    synth.add_argument("--height", type=int, default=480,
                       help="image height in pixels (default: %(default)s)")
    synth.add_argument("--seed", type=int, default=0,
                       help="seed of the sensor noise (default: %(default)s)")
    add_output_options(synth)

    images = kinds.add_parser(
        "images",
        help="import real RGB-D frames (TUM, PCL ImageGrabber TIFFs, Redwood)",
        description="Import a folder of RGB-D images (colour registered to depth) into an "
        "MCAP recording. Camera parameters: --camera-json, else DIR/camera.json, else the "
        "format's defaults (TUM fr1: 517.3/516.5/318.6/255.3, depth 5000/m; pcl-tiff: "
        "525/525/320/240, 1000/m; redwood: 525/525/319.5/239.5, 1000/m); the "
        "--fx/--fy/--cx/--cy/--depth-scale options override single values.",
        epilog=IMAGES_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    images.add_argument("directory", type=Path, metavar="DIR", help="folder with the images")
    images.add_argument("--format", dest="image_format", choices=FORMATS,
                        help="folder layout (default: detected): tum (rgb.txt and depth.txt "
                        "listing the images), pcl-tiff (PCL ImageGrabber frame_*_rgb.tiff and "
                        "frame_*_depth.tiff), redwood (color/ and depth/ PNGs of the same names)")
    images.add_argument("--camera-json", type=Path, metavar="FILE.json",
                        help="camera parameters: fx, fy, cx, cy, depth_scale (and width, height)")
    for name in ("fx", "fy", "cx", "cy"):
        images.add_argument(f"--{name}", type=float, help=f"intrinsic {name} in pixels")
    images.add_argument("--depth-scale", type=float, help="depth units per metre (1000 = mm)")
    images.add_argument(
        "--poses",
        type=Path,
        metavar="FILE",
        help="camera-to-world poses, written as /tf from 'world': a TUM trajectory (timestamp "
        "tx ty tz qx qy qz qw per line, interpolated at each frame's time), one 'tx ty tz qx "
        "qy qz qw' line per frame, or a folder with one file per frame (a 4x4 matrix or such a "
        "line, e.g. pose/NNNNNN.txt); at most 1,000,000 poses. Each posed frame is checked "
        "against its depth as the learner checks it; when most contradict it, nothing is "
        "written and the likely cause is named (quaternion order, inverted transform, units)",
    )
    add_pose_limit_arguments(images.add_argument_group(POSE_LIMITS_TITLE))
    add_output_options(images)
    _add_realsense(kinds, add_output_options)


def _add_realsense(kinds: Any, add_output_options: Any) -> None:
    realsense = kinds.add_parser(
        "realsense", help="record a live RealSense (or convert a RealSense recording)",
        description="Record a live RealSense into gngdt's MCAP: depth aligned to colour, the "
        "device's own intrinsics and depth units, until --seconds or Ctrl-C. A camera lost "
        "mid-way ends the recording with what it holds (a complete file), exit status 1. "
        "Needs the [realsense] extra.",
        epilog=REALSENSE_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    realsense.add_argument("--serial", metavar="SERIAL",
                           help="the camera's serial number (default: the one plugged in)")
    realsense.add_argument("--mode", default="640x480@30", metavar="WxH@FPS",
                           help="what the camera streams, depth and colour alike (default "
                           "%(default)s)")
    realsense.add_argument("--seconds", type=float, metavar="N",
                           help="stop after N seconds (default: at Ctrl-C)")
    realsense.add_argument("--from", dest="from_recording", type=Path, metavar="FILE",
                           help="convert this RealSense recording (.db3, legacy .bag) instead "
                           "of recording a camera")
    add_output_options(realsense, fps=False)


def write_recording(
    frames: Iterable[Frame],
    args: argparse.Namespace,
    metadata: dict[str, dict[str, str]] | None = None,
    checks: ImportChecks | None = None,
) -> int:
    """Write ``frames`` to ``args.out`` with a progress line every ``PROGRESS_EVERY`` frames;
    ``metadata``: named MCAP metadata records; ``checks``: what the frames are checked for on
    their way (an import's depth and poses). The file is written beside ``args.out`` and takes
    its place only when complete and its poses usable (else exit 2, ``args.out`` untouched)."""
    from gngdt.io.mcap.writer import RecordingWriter

    started = time.perf_counter()
    partial = args.out.with_name(f".{args.out.name}.partial-{os.getpid()}")
    try:
        with RecordingWriter(
            partial, compression=args.compression, color_format=args.color_format
        ) as writer:
            for name, data in (metadata or {}).items():
                writer.add_metadata(name, data)
            for frame in frames if checks is None else checks.watch(frames):
                writer.write_frame(frame)
                if writer.frames_written % PROGRESS_EVERY == 0:
                    logger.info("%d frames written", writer.frames_written)
        if checks is not None and not report_checks(checks):
            logger.error("nothing written to %s", args.out)
            return 2
        os.replace(partial, args.out)
    finally:
        partial.unlink(missing_ok=True)
    elapsed = time.perf_counter() - started
    size_mb = args.out.stat().st_size / 1e6
    print(f"wrote {writer.frames_written} frames to {args.out} ({size_mb:.1f} MB, {elapsed:.1f} s)")
    return 0


def report_checks(checks: ImportChecks) -> bool:
    """Say what the import's checks found (depth range, poses); False when the poses are
    unusable (most frames rejected)."""
    from gngdt.io.import_checks import depth_warning

    print(checks.depth.describe(), flush=True)
    warning = depth_warning(checks.depth)
    if warning:
        logger.warning("%s", warning)
    report = checks.pose_report()
    if report is None:
        return True
    if report.failed:
        logger.error("%s", report.text)
        return False
    if report.rejected:
        logger.warning("%s", report.text)
    else:
        print(report.text, flush=True)
    return True


def _synth_frames(args: argparse.Namespace) -> Iterable[Frame]:
    try:
        from gngdt.io.synth.render import SCENES, render_scene
    except ImportError as error:
        raise ValueError(f"the synthetic renderer is not available ({error})") from error
    if args.scene not in SCENES:
        raise ValueError(f"unknown scene {args.scene!r}; scenes: {', '.join(sorted(SCENES))}")
    if args.frames <= 0:
        raise ValueError(f"--frames must be positive, got {args.frames}")
    return render_scene(
        args.scene,
        args.frames,
        width=args.width,
        height=args.height,
        seed=args.seed,
        fps=args.fps,
    )


def image_format(args: argparse.Namespace) -> str:
    """The folder's layout: ``--format``, else detected (RecordingError when ambiguous)."""
    from gngdt.io.images import detect_format

    return args.image_format or detect_format(args.directory)


def _image_frames(args: argparse.Namespace) -> Iterable[Frame]:
    from dataclasses import replace

    from gngdt.io.images import iter_image_frames, load_camera

    camera = load_camera(args.directory, image_format(args), args.camera_json)
    overrides = {
        name: getattr(args, name)
        for name in ("fx", "fy", "cx", "cy", "depth_scale")
        if getattr(args, name) is not None
    }
    for name, value in overrides.items():
        if name != "cx" and name != "cy" and value <= 0:
            raise ValueError(f"--{name.replace('_', '-')} must be positive, got {value}")
    frames = iter_image_frames(
        args.directory, image_format(args), fps=args.fps, camera=replace(camera, **overrides)
    )
    if args.poses is None:
        return frames
    from gngdt.io.images import count_image_frames
    from gngdt.io.pose_files import attach_poses, load_poses

    poses = load_poses(args.poses)  # every pose error before the first frame is written
    count = count_image_frames(args.directory, image_format(args), fps=args.fps)
    return attach_poses(frames, poses, count)


def _synth_metadata(args: argparse.Namespace) -> dict[str, dict[str, str]]:
    from gngdt.io.synth.render import SCENE_METADATA, scene_metadata
    from gngdt.io.synth.scenes import build_scene

    return {SCENE_METADATA: scene_metadata(build_scene(args.scene), args.fps)}


class Take:
    """The frames of a RealSense source for a recording: until ``seconds`` (None: no limit), a
    stop signal or the camera's loss (kept in ``error``; the frames before it are written)."""

    def __init__(self, source: Any, seconds: float | None, stop: Any) -> None:
        self.source = source
        self.seconds = seconds
        self.stop = stop
        self.error: RecordingError | None = None
        self.frames = 0

    def __iter__(self) -> Iterator[Frame]:
        started = time.monotonic()
        try:
            for _, frame in self.source.frames():
                self.frames += 1
                yield frame
                if self.stop.is_set() or (
                        self.seconds is not None and time.monotonic() - started >= self.seconds):
                    return
        except RecordingError as error:
            self.error = error
            logger.error("%s; the recording keeps the frames before", error)


def record_realsense(source: Any, args: argparse.Namespace) -> int:
    """Record ``source`` (a `RealSenseSource`) into ``args.out``: 0, or 1 when the camera was
    lost (the file then holds the frames before, complete), or 2 when the source gave not a
    single frame (a recording the SDK cannot read: the file's problem)."""
    from gngdt.services.plumbing import lifecycle

    if args.seconds is not None and args.seconds <= 0:
        raise ValueError(f"--seconds must be positive, got {args.seconds}")
    logger.info("recording %s into %s%s", source.describe(), args.out,
                "" if args.seconds is None else f" for {args.seconds:g} s")
    try:
        with lifecycle.graceful() as stop:
            take = Take(source, args.seconds, stop)
            write_recording(take, args)
    finally:
        source.close()
    if take.error is None:
        return 0
    return 1 if take.frames else 2


def _realsense_source(args: argparse.Namespace) -> Any:
    from gngdt.io.sources.realsense import RealSenseSource, live_spec

    if args.from_recording is not None:
        if args.serial is not None:
            raise ValueError("--serial is for a camera, not with --from")
        return RealSenseSource(args.from_recording)
    return RealSenseSource(f"{live_spec(args.serial)}:{args.mode}")


def main(args: argparse.Namespace) -> int:
    try:
        if args.record_kind == "realsense":
            return record_realsense(_realsense_source(args), args)
        if args.record_kind == "synth":
            frames = _synth_frames(args)
            return write_recording(frames, args, _synth_metadata(args))
        from gngdt.core.odometry.pose_checks import PoseLimits
        from gngdt.io.import_checks import ImportChecks, pose_limit_values

        checks = ImportChecks(PoseLimits(**pose_limit_values(args)))
        return write_recording(_image_frames(args), args, checks=checks)
    except (RecordingError, ValueError) as error:
        logger.error("%s", error)
        return 2
