"""Replay a source as a camera on zenoh: colour, depth, calibration and point cloud per frame.

The source is a recording (gngdt's MCAP, a ROS 2 bag, a RealSense ``.db3``/``.bag``), a folder of
RGB-D images, a synthetic scene (``synth:<scene>[:<frames>]``) or a live RealSense
(``--realsense [SERIAL]``): anything `gngdt.io.sources` opens. A live camera paces itself; a
camera lost mid-stream ends the stream (end of stream published, exit status 1).

Each frame is stamped with a monotonically increasing sequence number and the wall-clock time
at which it is replayed (its "capture time" as a live camera would give it), so latency
downstream is measured against the moment the frame entered the pipeline. After the last frame
an end-of-stream message (``gngdt.StreamEnd``) is published, unless ``--loop`` replays forever.

When the recording has camera poses (``/tf``, see ``gngdt.io.mcap.reader``), each cloud is
published with its pose: points in the camera frame, ``frame_id`` the fixed frame
(``--fixed-frame``, default the first of world/map/odom found), ``pose`` the camera's pose in
it, and the camera's pose on ``gngdt/<cam>/tf`` (``foxglove.FrameTransform`` fixed frame ->
camera). A frame the transforms do not cover (the recording has poses, only not at that time)
publishes its images but no cloud, warned: a camera-frame cloud would not fit the map.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gngdt.io.deproject import RUN_POINT_CAP, CloudOptions, FrameToCloud
from gngdt.io.mcap.limits import ReadLimits
from gngdt.io.sources.base import DEFAULT_MAX_SKEW_MS, BadFrameHandler, SourceOptions
from gngdt.schemas.clouds import MAX_CLOUD_POINTS
from gngdt.schemas.wire import (
    CAPTURE,
    DEFAULT_CAMERA,
    ENCODING_CALIBRATION,
    ENCODING_FRAME_TRANSFORM,
    ENCODING_POINT_CLOUD,
    ENCODING_RAW_IMAGE,
    ENCODING_STREAM_END,
    FrameStamp,
    alive_key,
    topic,
)
from gngdt.services.capture_tally import CaptureTally, exit_status, no_points_reason
from gngdt.services.pacing import LearnerLost, LearnerPacing
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.session import (
    SharedMemoryPublisher,
    add_zenoh_arguments,
    declare_publisher,
    open_session,
    wait_for_subscribers,
)
from gngdt.services.plumbing.settings import OptionGroup, add_settings_argument
from gngdt.services.replay_clock import DEFAULT_MAX_GAP_S, RecordedClock, ReplayClock

if TYPE_CHECKING:
    import zenoh

    from gngdt.io.frame import CameraIntrinsics, Frame
    from gngdt.io.sources import FrameSource

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt capture recordings/tabletop.mcap               # at the recorded rate, then end-of-stream
  gngdt capture recordings/tabletop.mcap --fast --voxel 0.01 --max-points 50000
  gngdt capture recordings/tabletop.mcap --loop --cam left --zenoh-connect tcp/10.0.0.2:7447
  gngdt capture mybag_0.mcap --topics /camera --max-skew-ms 20   # a ROS 2 bag, unsynchronised
  gngdt capture ../shared/data/rgbd/tum_fr1_xyz_dvo_examples     # a folder of RGB-D images
  gngdt capture synth:tabletop_walk:120 --fast                   # a synthetic scene
  gngdt capture --realsense                     # the RealSense plugged in ([realsense] extra)
  gngdt capture --realsense 123456789012 --loop # that camera (by serial number)
  gngdt capture session.db3                     # a RealSense recording (.db3 or legacy .bag)
"""

#: a file read frame by frame: how long the learner may take a frame, and how long capture waits
#: for a learner to appear before replaying without one
DEFAULT_LEARNER_TIMEOUT_S = 60.0
DEFAULT_WAIT_LEARNER_S = 60.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_source_arguments(parser)
    for group in SETTINGS:
        group.add_to(parser)
    parser.add_argument("--loop", action="store_true", help="replay forever (no end-of-stream)")
    parser.add_argument("--cam", default=DEFAULT_CAMERA, help="camera name in the topics")
    parser.add_argument(
        "--wait-subscribers", type=float, default=10.0, metavar="SECONDS",
        help="real time: wait this long for a points subscriber before the first frame "
        "(default 10)")
    parser.add_argument(
        "--wait-learner", type=float, default=DEFAULT_WAIT_LEARNER_S, metavar="SECONDS",
        help="a file read frame by frame: wait this long for the camera's learner before the "
        f"first frame, then replay without one, in real time (default {DEFAULT_WAIT_LEARNER_S:g})")
    add_sampling_seed_argument(parser)
    add_settings_argument(parser)
    add_zenoh_arguments(parser)


def add_source_arguments(parser: argparse.ArgumentParser) -> None:
    """SOURCE, or ``--realsense [SERIAL]`` (shared with `gngdt run`; `source_spec` reads them)."""
    parser.add_argument("recording", metavar="SOURCE", nargs="?",
                        help="a recording (MCAP, ROS 2 bag, RealSense .db3/.bag), a folder of "
                        "RGB-D images, synth:<scene>[:<frames>] or realsense:[SERIAL][:WxH@FPS]")
    parser.add_argument("--realsense", nargs="?", const="", metavar="SERIAL",
                        help="a live RealSense instead of SOURCE: the one plugged in, or the one "
                        "with this serial number (depth aligned to colour, 640x480 at 30 fps; "
                        "needs the [realsense] extra)")


def source_spec(args: argparse.Namespace) -> str:
    """The source SOURCE or ``--realsense`` names; ValueError unless exactly one is given."""
    from gngdt.io.sources.realsense import live_spec

    if (args.recording is None) == (args.realsense is None):
        raise ValueError("give a SOURCE (a recording, a folder, synth:<scene>) or --realsense "
                         "[SERIAL], not both and not neither")
    return str(args.recording) if args.realsense is None else live_spec(args.realsense)


def add_reading_arguments(group: Any) -> None:
    """How capture reads a source and makes its clouds (`READING`: `gngdt run` has these
    options too)."""
    speed = group.add_mutually_exclusive_group()
    speed.add_argument(
        "--rate", type=float, default=1.0, help="replay speed factor (default 1.0 = recorded rate)"
    )
    speed.add_argument("--fast", action="store_true", help="replay as fast as possible")
    group.add_argument(
        "--realtime", action="store_true",
        help="a file as a live camera would send it: at the recorded pace (--rate), the learner "
        "taking the latest frame and dropping what arrives while it learns. Default for a file: "
        "every frame, each sent once the learner took the one before (a live camera is always "
        "real time)")
    group.add_argument(
        "--learner-timeout", type=float, default=DEFAULT_LEARNER_TIMEOUT_S, metavar="SECONDS",
        help="a file read frame by frame ends, naming the reason, when the learner takes no "
        f"frame for this long (default {DEFAULT_LEARNER_TIMEOUT_S:g})")
    group.add_argument(
        "--topics", metavar="PREFIX",
        help="read only the recording's topics under PREFIX (a bag with several cameras)")
    group.add_argument(
        "--fixed-frame", default="auto", metavar="FRAME",
        help="frame the camera poses are given in (e.g. map, odom); 'auto' (default): world, "
        "map or odom, whichever the recording's transforms connect to the images; 'none': "
        "ignore the poses, publish camera-frame clouds")
    group.add_argument(
        "--max-skew-ms", type=float, default=DEFAULT_MAX_SKEW_MS,
        help="largest stamp difference between a frame's colour and depth images "
        f"(default {DEFAULT_MAX_SKEW_MS:g})")
    group.add_argument(
        "--max-gap", type=float, default=DEFAULT_MAX_GAP_S, metavar="SECONDS",
        help="longest wait between two frames: a longer gap in the recorded stamps is "
        f"shortened to this, with a warning (default {DEFAULT_MAX_GAP_S:g})")
    add_camera_arguments(group)
    add_cloud_arguments(group)


def add_camera_arguments(parser: Any) -> None:
    """--camera-json and --depth-scale, for every kind of source (shared with `gngdt run`)."""
    parser.add_argument("--camera-json", type=Path, metavar="FILE",
                        help="camera parameters, a JSON object with fx, fy, cx, cy (pixels) and "
                        "optionally depth_scale, width, height: an image folder's instead of its "
                        "camera.json, a recording's instead of its calibration (a bag recorded "
                        "without CameraInfo)")
    parser.add_argument("--depth-scale", type=float, metavar="UNITS_PER_M",
                        help="units per metre of the 16-bit depth images (1000: millimetres, "
                        "the default of recordings; 5000: TUM; 10000: 0.1 mm) instead of what "
                        "the source says")


def add_cloud_arguments(parser: Any) -> None:
    """How a frame becomes a cloud (depth range, voxel, veil, point cap); see `frame_to_cloud`."""
    parser.add_argument("--min-depth", type=float, default=CloudOptions.min_depth_m,
                        help="nearest depth kept, metres (default %(default)s)")
    parser.add_argument("--max-depth", type=float, default=CloudOptions.max_depth_m,
                        help="farthest depth kept, metres (default %(default)s)")
    parser.add_argument(
        "--voxel", type=float, metavar="SIZE_M", help="voxel-grid downsampling cell size, metres")
    parser.add_argument(
        "--drop-veil", type=float, metavar="RATIO",
        help="drop veil points: pixels whose depth jumps from a neighbour's by more than RATIO "
        "of the nearer depth (mixed pixels along depth edges; 0.03 for a Kinect, see "
        "config/kinect.toml); default: keep every pixel (`gngdt run`: the sensor profile's)")
    parser.add_argument(
        "--max-points", type=int,
        help="publish a random subset of at most this many points per frame (default: all, "
        f"up to {MAX_CLOUD_POINTS:,}, what a learner accepts and a zenoh message holds; "
        f"`gngdt run`: {RUN_POINT_CAP:,}, all with --track; 0: all)")


def add_sampling_seed_argument(parser: Any) -> None:
    """``--seed`` of the point cap (not in `READING`: `gngdt run`'s ``--seed`` is the
    learner's)."""
    parser.add_argument("--seed", type=int, default=0, help="seed of the point-cap sampling")


def add_limit_arguments(limits: Any) -> None:
    """What a recording may hold (`LIMITS`)."""
    defaults = ReadLimits()
    limits.add_argument(
        "--max-frame-pixels", type=int, default=defaults.max_frame_pixels, metavar="N",
        help=f"largest image, width x height (default {defaults.max_frame_pixels:,}, 4096x2160); "
        "a larger one is a bad frame, skipped")
    limits.add_argument(
        "--max-chunk-mb", type=int, default=defaults.max_chunk_bytes >> 20, metavar="MB",
        help="largest MCAP chunk once decompressed, checked before decompressing (default "
        f"{defaults.max_chunk_bytes >> 20}); a file with a larger one is refused")
    limits.add_argument(
        "--max-pending-mb", type=int, default=defaults.max_held_bytes >> 20, metavar="MB",
        help="images held while waiting for their colour/depth partner or a calibration "
        f"(default {defaults.max_held_bytes >> 20})")
    limits.add_argument(
        "--max-transforms", type=int, default=defaults.max_transform_samples, metavar="N",
        help="transform samples (/tf) read for camera poses, 64 bytes each, ~40 s a million "
        f"(default {defaults.max_transform_samples:,}); the rest are not read, with a warning")


#: how capture reads a source and makes its clouds, declared once for `gngdt capture` and
#: `gngdt run`
READING = OptionGroup("reading and deprojecting (gngdt capture)", add_reading_arguments)
LIMITS = OptionGroup("limits (a recording beyond them is refused, naming the file and the frame)",
                     add_limit_arguments)
#: the option groups a settings file (``--settings``) may hold
SETTINGS = [READING, LIMITS]


#: each `CloudOptions` field's command-line option
CLOUD_OPTION_FLAGS = {"min_depth_m": "--min-depth", "max_depth_m": "--max-depth",
                      "voxel_size_m": "--voxel", "max_points": "--max-points",
                      "veil_ratio": "--drop-veil"}


def frame_to_cloud(args: argparse.Namespace) -> FrameToCloud:
    """The frame-to-cloud conversion `add_cloud_arguments` describes (``ValueError`` naming the
    option for a wrong value)."""
    try:
        options = CloudOptions(args.min_depth, args.max_depth, args.voxel,
                               args.max_points or None, args.drop_veil or 0.0)
    except ValueError as error:
        message = str(error).replace(f"{CloudOptions.WHAT} ", "")
        for field, flag in CLOUD_OPTION_FLAGS.items():
            message = message.replace(field, flag)
        raise ValueError(message) from None
    return FrameToCloud(options, args.seed)


def source_options(args: argparse.Namespace,
                   on_bad_frame: BadFrameHandler | None = None) -> SourceOptions:
    """How to read the source, from the command line (``ValueError`` for a wrong value); a
    frame it cannot read goes to ``on_bad_frame`` (default: logged) and is skipped."""
    if args.max_skew_ms < 0:
        raise ValueError(f"--max-skew-ms must be >= 0, got {args.max_skew_ms}")
    limits = ReadLimits(args.max_frame_pixels, args.max_chunk_mb << 20,
                        args.max_pending_mb << 20, args.max_transforms)
    fixed_frame = None if args.fixed_frame.lower() == "none" else args.fixed_frame
    return SourceOptions(camera_json=args.camera_json, depth_scale=args.depth_scale,
                         topic_prefix=args.topics,
                         max_skew_ms=args.max_skew_ms, fixed_frame=fixed_frame, limits=limits,
                         on_bad_frame=on_bad_frame or log_bad_frame)


class CapturePublisher:
    """The capture's publishers, declared once; every put carries the frame's attachment.
    ``paced``: a file read frame by frame (every cloud must arrive); ``pool_bytes``: their
    shared-memory pools' size (`declare_publisher`)."""

    def __init__(self, session: zenoh.Session, camera: str, paced: bool = False,
                 pool_bytes: int | None = None) -> None:
        def declare(name: str, encoding: str, latest_wins: bool) -> SharedMemoryPublisher:
            return declare_publisher(session, topic(camera, name), encoding, latest_wins,
                                     pool_bytes=pool_bytes)

        self.camera = camera
        self.color = declare("color", ENCODING_RAW_IMAGE, latest_wins=True)
        self.depth = declare("depth", ENCODING_RAW_IMAGE, latest_wins=True)
        self.calibration = declare("calibration", ENCODING_CALIBRATION, latest_wins=False)
        # paced (a file read frame by frame): every cloud must arrive, the learner waits for it
        self.points = declare_publisher(session, topic(camera, "points"), ENCODING_POINT_CLOUD,
                                        latest_wins=not paced, large=True, pool_bytes=pool_bytes)
        self.tf = declare("tf", ENCODING_FRAME_TRANSFORM, latest_wins=False)
        self.eos = declare("eos", ENCODING_STREAM_END, latest_wins=False)
        self._last_intrinsics: CameraIntrinsics | None = None

    def close(self) -> None:
        """Undeclare the publishers (each logs how many of its payloads went through shared
        memory)."""
        for publisher in (self.color, self.depth, self.calibration, self.points, self.eos):
            publisher.undeclare()

    def publish_frame(
        self, frame: Frame, stamp: FrameStamp, positions: np.ndarray | None,
        colors: np.ndarray | None, sensor_time_ns: int | None = None,
        cloud: bytearray | None = None
    ) -> None:
        """Calibration (when new), colour, depth, the camera's pose (posed frames) and the
        cloud (``positions`` and ``colors``, or ``cloud`` serialised already, `cloud_of`;
        neither: images only); the cloud's own timestamp is ``sensor_time_ns`` (default the
        stamp's capture time): when the camera took it, which the learner's motion and pose
        checks use."""
        from gngdt.schemas.clouds import cloud_to_wire, pose_to_transform
        from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration

        attachment = stamp.to_attachment()
        time_ns = stamp.capture_time_ns
        if frame.intrinsics != self._last_intrinsics:
            calibration = intrinsics_to_calibration(
                frame.intrinsics, timestamp_ns=time_ns, frame_id=self.camera
            )
            self.calibration.put(calibration.SerializeToString(), attachment=attachment)
            self._last_intrinsics = frame.intrinsics
        color = image_to_raw(frame.color, timestamp_ns=time_ns, frame_id=self.camera)
        self.color.put(color.SerializeToString(), attachment=attachment)
        depth = image_to_raw(frame.depth, timestamp_ns=time_ns, frame_id=self.camera)
        self.depth.put(depth.SerializeToString(), attachment=attachment)
        if positions is None and cloud is None:  # no cloud (no pose at its time, no depth)
            return
        pose = frame.pose
        if pose is not None:  # fixed frame -> camera (the images' frame_id), before the cloud
            transform = pose_to_transform(pose.matrix, pose.frame_id, self.camera,
                                          timestamp_ns=time_ns)
            self.tf.put(transform.SerializeToString(), attachment=attachment)
        # serialised straight into one buffer: megabytes copied once more, into shared memory
        if cloud is None:
            cloud = cloud_to_wire(positions, colors, timestamp_ns=sensor_time_ns or time_ns,
                                  frame_id=self.camera if pose is None else pose.frame_id,
                                  pose=None if pose is None else pose.matrix)
        self.points.put(cloud, attachment=attachment)

    def publish_end(self, frames_sent: int, last_sequence: int, recording: str,
                    tally: CaptureTally | None = None) -> None:
        """The end of stream: frames sent, and (``tally``) those refused by why, those sent
        without a cloud and what capture warns about the stream."""
        from gngdt.schemas.status import encode_stream_end

        now = time.time_ns()
        tally = tally or CaptureTally()
        message = encode_stream_end(
            timestamp_ns=now,
            frames_sent=frames_sent,
            last_frame_sequence=last_sequence,
            recording=recording,
            frame_id=self.camera,
            frames_refused=dict(tally.refused),
            frames_without_cloud=dict(tally.without_cloud),
            warnings=tally.warnings,
        )
        self.eos.put(
            message.SerializeToString(), attachment=FrameStamp(last_sequence, now).to_attachment()
        )


def log_bad_frame(error: Exception) -> None:
    """A bad frame of the recording (named by file and frame) is logged; replay goes on."""
    log.error("%s; skipped, continuing with the next good frame", error)


class Replay:
    """Frames of a source (forever with ``loop``), and what went wrong reading it.

    A bad frame is logged and skipped; damage to the file itself ends a pass, logged, and is
    kept in ``error``: with not a single frame read, the capture fails (exit 2).
    """

    def __init__(self, source: FrameSource, loop: bool, stop: threading.Event,
                 tally: CaptureTally | None = None) -> None:
        self.source = source
        self.loop = loop
        self.stop = stop
        self.error: Exception | None = None
        self.frames_read = 0
        self.frames_sent = 0
        #: frames refused by why, sent without a cloud, the stream's warnings
        self.tally = tally if tally is not None else CaptureTally()
        #: why the learner stopped taking frames of a paced file ("": it did not)
        self.learner_lost = ""

    def __iter__(self) -> Iterator[Frame]:
        from gngdt.io.errors import RecordingError

        while not self.stop.is_set():
            yielded = 0
            try:
                for _, frame in self.source.frames():
                    yielded += 1
                    self.frames_read += 1
                    yield frame
            except RecordingError as error:
                self.error = error
                self.tally.reading_stopped(error)
                if yielded:
                    log.error("%s (continuing after %d good frames of this pass)", error, yielded)
            if not self.loop or yielded == 0:
                return


def main(args: argparse.Namespace) -> int:
    from gngdt.io.errors import RecordingError
    from gngdt.io.sources import open_source

    tally = CaptureTally()
    try:
        args.recording = source_spec(args)
        source = open_source(args.recording, options=source_options(args, tally.bad_frame))
        to_cloud = frame_to_cloud(args)
        to_cloud.warm_up()  # numba's kernels loaded before the first frame, not on it
        clock = ReplayClock(None if args.fast or source.live else args.rate, args.max_gap)
    except (ValueError, RecordingError) as error:
        log.error("%s", error)
        return 2
    session = open_session(args)  # ZenohSetupError: said by the command line, exit 1
    try:
        replay = capture(args, source, clock, to_cloud, session, tally)
    finally:
        session.close()
    return exit_status(replay, source.live)


def capture(args: argparse.Namespace, source: FrameSource, clock: ReplayClock,
            to_cloud: FrameToCloud, session: zenoh.Session,
            tally: CaptureTally | None = None) -> Replay:
    """Publish the source's frames on ``session`` until it ends or a stop signal, then the end
    of stream; the replay (what was read, sent and refused, what went wrong). A file is paced by
    its learner (`gngdt.services.pacing`) unless ``--realtime``."""
    paced = not source.live and not args.realtime
    publisher = CapturePublisher(session, args.cam, paced, args.environment.shm_pool_bytes)
    token = session.liveliness().declare_token(alive_key(args.cam, CAPTURE))
    with lifecycle.graceful() as stop:
        replay = Replay(source, args.loop, stop, tally)
        replay.tally.warnings[:0] = source.assumptions
        pacing = wait_for_consumers(args, session, publisher, paced, stop)
        speed = ("live" if source.live else "as fast as possible" if clock.rate is None
                 else f"at {clock.rate:g}x the recorded rate")
        mode = (", every frame once the learner took the one before" if pacing is not None
                else "" if source.live else ", in real time (the learner takes the latest frame)")
        log.info("replaying %s %s%s%s", source.describe(), speed, mode,
                 ", looping" if args.loop else "")
        try:
            frames_sent = publish(args, replay, clock, to_cloud, publisher, stop, pacing)
        finally:
            if pacing is not None:
                pacing.close()
        replay.frames_sent = frames_sent
        replay.tally.judge_depth()  # a stream shorter than the check
        if not stop.is_set() or not args.loop:
            # with nothing sent, frame 0 is named and frames_sent = 0 says it never came
            publisher.publish_end(frames_sent, max(frames_sent - 1, 0), source.path.name,
                                  replay.tally)
            said = replay.tally.describe()
            log.info("sent %d frames of %s, end of stream%s", frames_sent, args.recording,
                     f"; {said}" if said else "")
    time.sleep(0.2)  # let BLOCK puts drain to the router before the session closes
    token.undeclare()
    publisher.close()
    source.close()
    return replay


def wait_for_consumers(args: argparse.Namespace, session: zenoh.Session,
                       publisher: CapturePublisher, paced: bool,
                       stop: threading.Event) -> LearnerPacing | None:
    """Before the first frame: a file waits for the camera's learner (its pacing, None: the
    file goes in real time, as it does when no learner came within ``--wait-learner``); real
    time waits for any points subscriber."""
    if paced:
        pacing = LearnerPacing(session, args.cam, args.learner_timeout)
        if pacing.wait_for_learner(args.wait_learner, stop):
            wait_for_subscribers(publisher.points, args.wait_subscribers, stop)
            return pacing
        pacing.close()
        if not stop.is_set():
            log.warning("no learner of camera %r after %.0f s (--wait-learner): replaying in "
                        "real time, frames are not waited for", args.cam, args.wait_learner)
        return None
    if not wait_for_subscribers(publisher.points, args.wait_subscribers, stop):
        log.warning("no subscriber on %s after %.1f s; publishing anyway",
                    topic(args.cam, "points"), args.wait_subscribers)
    return None


def publish(args: argparse.Namespace, replay: Replay, clock: ReplayClock, to_cloud: FrameToCloud,
            publisher: CapturePublisher, stop: threading.Event,
            pacing: LearnerPacing | None = None) -> int:
    """Publish every frame of the replay at the clock's pace (and, with ``pacing``, each cloud
    once the learner took the one before, the next frame read meanwhile); the number of frames
    sent."""
    frames_sent = 0  # also the next frame's sequence: only published frames are numbered
    tally = replay.tally
    last_cloud = -1  # the sequence of the last cloud sent
    sensor_clock = RecordedClock() if pacing is not None else None
    for frame in replay:
        clock.wait_for(frame.timestamp_ns, stop, frame.index)
        if stop.is_set():
            break
        capture_time_ns = time.time_ns()
        sensor_time_ns = (capture_time_ns if sensor_clock is None
                          else sensor_clock.stamp(frame.timestamp_ns))
        tally.check_depth(frame)
        try:
            cloud, points = cloud_of(frame, to_cloud, args.cam, sensor_time_ns)
        except ValueError as error:
            tally.refuse(f"{args.recording}: frame {frame.index}", str(error))
            continue
        if frame.pose_error:  # the reader warned; the cloud would not fit the map
            cloud, points = None, 0
            tally.no_cloud(f"frame {frame.index}", "no camera pose at its time")
        elif points == 0:  # every pixel out of range: no depth, or another unit
            cloud = None
            tally.no_cloud(f"frame {frame.index}", no_points_reason(to_cloud.options))
        if pacing is not None and not wait_taken(pacing, last_cloud, replay, stop):
            break
        publisher.publish_frame(frame, FrameStamp(frames_sent, capture_time_ns), None, None,
                                cloud=cloud)
        log.debug("frame %d: %d points", frames_sent, points)
        last_cloud = frames_sent if cloud is not None else last_cloud
        frames_sent += 1
    if pacing is not None:  # the end of stream after the last frame's learning
        wait_taken(pacing, last_cloud, replay, stop)
    return frames_sent


def cloud_of(frame: Frame, to_cloud: FrameToCloud, camera: str,
             sensor_time_ns: int) -> tuple[bytearray, int]:
    """The frame's cloud serialised for the wire (its points deprojected straight into the
    buffer) and its point count; in the camera frame ``camera``, or the pose's fixed frame."""
    pose = frame.pose
    return to_cloud.to_wire(frame, timestamp_ns=sensor_time_ns,
                            frame_id=camera if pose is None else pose.frame_id,
                            pose=None if pose is None else pose.matrix)


def wait_taken(pacing: LearnerPacing, sequence: int, replay: Replay,
               stop: threading.Event) -> bool:
    """Wait for the learner to take cloud ``sequence`` (-1: none sent yet); False when it
    stopped taking frames (said, and kept in ``replay``)."""
    if sequence < 0:
        return True
    try:
        pacing.wait_taken(sequence, stop)
    except LearnerLost as error:
        log.error("%s; ending the stream", error)
        replay.learner_lost = str(error)
        return False
    return not stop.is_set()
