"""Make recordings: render a synthetic scene or import real RGB-D frames into an MCAP file."""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Iterable
from pathlib import Path

from services.recording.errors import RecordingError
from services.recording.frame import Frame

logger = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt record synth --scene tabletop --frames 30 --out recordings/tabletop.mcap
  gngdt record synth --scene tabletop_vanish --frames 90 --out vanish.mcap   # a changing scene
  gngdt record images --format redwood ../shared/data/rgbd/rtabmap_rgbd_test --out lab.mcap
  gngdt record images --format tum rgbd_dataset_freiburg1_xyz --out fr1_xyz.mcap
  gngdt record images --format pcl-tiff frames/ --out grabber.mcap --fx 525 --fy 525
"""

#: Log a progress line every this many frames.
PROGRESS_EVERY = 10


class _DefaultsAndRawEpilog(
    argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter
):
    """Show defaults, and the epilog's lines as they are."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``synth`` and ``images`` sub-subcommands."""
    from services.recording.images import FORMATS
    from services.recording.writer import COLOR_FORMATS, COMPRESSIONS

    kinds = parser.add_subparsers(dest="record_kind", required=True, metavar="KIND")

    def add_output_options(sub: argparse.ArgumentParser) -> None:
        sub.add_argument("--out", type=Path, required=True, help="MCAP file to write")
        sub.add_argument("--fps", type=float, default=30.0, help="frame rate (default: 30)")
        sub.add_argument("--compression", choices=COMPRESSIONS, default="zstd")
        sub.add_argument(
            "--color-format",
            choices=COLOR_FORMATS,
            default="raw",
            help="colour as RawImage rgb8 (raw, default) or CompressedImage jpeg/png",
        )

    from services.recording.synth import SCENES

    scene_list = "\n".join(f"  {name:16s}{text}" for name, text in SCENES.items())
    synth = kinds.add_parser(
        "synth",
        help="render a synthetic scene with ground-truth labels and camera poses",
        description="Render a synthetic scene with the virtual Kinect: colour, depth, "
        "ground-truth labels and the camera's pose (/tf) per frame.",
        epilog=f"scenes:\n{scene_list}",
        formatter_class=_DefaultsAndRawEpilog,
    )
    synth.add_argument("--scene", required=True, metavar="NAME",
                       help=f"scene: {', '.join(SCENES)} (described below)")
    synth.add_argument("--frames", type=int, required=True, help="number of frames")
    synth.add_argument("--width", type=int, default=640)
    synth.add_argument("--height", type=int, default=480)
    synth.add_argument("--seed", type=int, default=0)
    add_output_options(synth)

    images = kinds.add_parser(
        "images",
        help="import real RGB-D frames (TUM, PCL ImageGrabber TIFFs, Redwood)",
        description="Import an RGB-D image folder. Camera parameters: --camera-json, else "
        "DIR/camera.json, else the format's defaults (TUM fr1: 517.3/516.5/318.6/255.3, depth "
        "5000/m; pcl-tiff: 525/525/320/240, 1000/m; redwood: 525/525/319.5/239.5, 1000/m); the "
        "--fx/--fy/--cx/--cy/--depth-scale options override single values.",
    )
    images.add_argument("directory", type=Path, metavar="DIR", help="folder with the images")
    images.add_argument("--format", dest="image_format", choices=FORMATS, required=True)
    images.add_argument("--camera-json", type=Path, help="camera parameters JSON file")
    for name in ("fx", "fy", "cx", "cy"):
        images.add_argument(f"--{name}", type=float, help=f"intrinsic {name} in pixels")
    images.add_argument("--depth-scale", type=float, help="depth units per metre (1000 = mm)")
    add_output_options(images)


def write_recording(
    frames: Iterable[Frame],
    args: argparse.Namespace,
    metadata: dict[str, dict[str, str]] | None = None,
) -> int:
    """Write ``frames`` to ``args.out`` with a progress line every ``PROGRESS_EVERY`` frames;
    ``metadata``: named MCAP metadata records."""
    from services.recording.writer import RecordingWriter

    started = time.perf_counter()
    with RecordingWriter(
        args.out, compression=args.compression, color_format=args.color_format
    ) as writer:
        for name, data in (metadata or {}).items():
            writer.add_metadata(name, data)
        for frame in frames:
            writer.write_frame(frame)
            if writer.frames_written % PROGRESS_EVERY == 0:
                logger.info("%d frames written", writer.frames_written)
    elapsed = time.perf_counter() - started
    size_mb = args.out.stat().st_size / 1e6
    print(f"wrote {writer.frames_written} frames to {args.out} ({size_mb:.1f} MB, {elapsed:.1f} s)")
    return 0


def _synth_frames(args: argparse.Namespace) -> Iterable[Frame]:
    try:
        from services.recording.synth import SCENES, render_scene
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


def _image_frames(args: argparse.Namespace) -> Iterable[Frame]:
    from dataclasses import replace

    from services.recording.images import iter_image_frames, load_camera

    camera = load_camera(args.directory, args.image_format, args.camera_json)
    overrides = {
        name: getattr(args, name)
        for name in ("fx", "fy", "cx", "cy", "depth_scale")
        if getattr(args, name) is not None
    }
    for name, value in overrides.items():
        if name != "cx" and name != "cy" and value <= 0:
            raise ValueError(f"--{name.replace('_', '-')} must be positive, got {value}")
    return iter_image_frames(
        args.directory, args.image_format, fps=args.fps, camera=replace(camera, **overrides)
    )


def _synth_metadata(args: argparse.Namespace) -> dict[str, dict[str, str]]:
    from services.recording.scenes import build_scene
    from services.recording.synth import SCENE_METADATA, scene_metadata

    return {SCENE_METADATA: scene_metadata(build_scene(args.scene), args.fps)}


def main(args: argparse.Namespace) -> int:
    try:
        if args.record_kind == "synth":
            frames = _synth_frames(args)
            return write_recording(frames, args, _synth_metadata(args))
        return write_recording(_image_frames(args), args)
    except (RecordingError, ValueError) as error:
        logger.error("%s", error)
        return 2
