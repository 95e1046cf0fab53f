"""Bridge gngdt and ROS 2 over zenoh (rmw_zenoh's wire format): camera topics in, results out.

A robot's camera topics come in; clouds, nodes, graph, objects, camera pose and status go out,
in ROS 2's graph, without a ROS installation.

A ROS 2 node ``gngdt_<cam>`` (domain ``--domain``, else ``ROS_DOMAIN_ID``, else 0) on the same
router as the other services (or on the ROS 2 router ``--ros2-connect`` names):

out (`gngdt.services.ros2.outbound`): ``/gngdt/<cam>/points`` sensor_msgs/PointCloud2 (x, y, z,
rgb), ``/gngdt/<cam>/nodes`` PointCloud2 (x, y, z, rgb, normal_x/y/z, a uint32
``label_<clustering>`` per clustering: the persistent cluster id, 0xFFFFFFFF for none),
``/gngdt/<cam>/graph`` visualization_msgs/MarkerArray (a LINE_LIST per topology, coloured by
cluster; at most ``--graph-rate`` a second), ``/gngdt/<cam>/objects`` MarkerArray (a CUBE and a
TEXT_VIEW_FACING label per object, marker id = object id; DELETE for ids gone), ``/tf``
tf2_msgs/TFMessage (fixed frame -> camera when the clouds have poses) and ``/gngdt/<cam>/status``
diagnostic_msgs/DiagnosticArray (the bridge's and the learner's status, once a second).

in (`gngdt.services.ros2.inbound`, unless ``--no-input``): a camera driver's colour and depth
sensor_msgs/Image and CameraInfo (realsense2_camera's names by default), paired by stamp, as
gngdt frames on ``gngdt/<cam>/{color,depth,calibration,points}`` (what `gngdt capture`
publishes), with poses from ``/tf`` when ``--fixed-frame`` names a frame.

Liveliness tokens: the node, each publisher and subscription (ROS 2's graph: ``ros2 node
list``, ``ros2 topic list``), and gngdt's ``gngdt/<cam>/ros2/alive`` (and, with input,
``gngdt/<cam>/capture/alive``). A bad message is counted in the status and skipped.
"""

from __future__ import annotations

import argparse
import logging
import time
from typing import TYPE_CHECKING

from gngdt.io.mcap.limits import ReadLimits
from gngdt.io.sources.base import DEFAULT_MAX_SKEW_MS
from gngdt.schemas.wire import BRIDGE, CAPTURE, DEFAULT_CAMERA, alive_key, topic
from gngdt.services.capture import add_cloud_arguments, add_sampling_seed_argument
from gngdt.services.plumbing.report import add_report_argument, write_report
from gngdt.services.plumbing.session import DEFAULT_ENDPOINT, add_zenoh_arguments

if TYPE_CHECKING:
    import zenoh

    from gngdt.io.deproject import FrameToCloud
    from gngdt.services.ros2.inbound import RosToGngdt

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt ros2 --zenoh-connect tcp/127.0.0.1:7447      # beside rmw_zenohd: a RealSense in, all out
  gngdt ros2 --fixed-frame odom --voxel 0.01         # camera poses from /tf, learned in odom
  gngdt ros2 --color-topic /kinect/rgb/image_raw --depth-topic /kinect/depth/image_raw \\
      --camera-info-topic /kinect/rgb/camera_info --max-skew-ms 20
  gngdt ros2 --no-input --domain 3                   # only what gngdt learns, into domain 3
  gngdt run recordings/tabletop.mcap --ros2          # a recording's results into ROS 2
"""

#: ROS 2's largest domain id (ROS 2's documentation: 0-232 on Linux)
MAX_DOMAIN_ID = 232
DEFAULT_GRAPH_RATE_HZ = 2.0
#: how often /gngdt/<cam>/status is published
STATUS_PERIOD_S = 1.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from gngdt.services.ros2.inbound import CameraTopics

    parser.add_argument("--cam", default=DEFAULT_CAMERA,
                        help="camera name in gngdt's topics; the ROS 2 node is gngdt_<cam>, its "
                        "topics /gngdt/<cam>/... (letters, digits and _)")
    parser.add_argument("--domain", type=int, metavar="ID",
                        help=f"ROS 2 domain id, 0-{MAX_DOMAIN_ID} (default: ROS_DOMAIN_ID, else 0)")
    parser.add_argument("--ros2-connect", action="append", metavar="ENDPOINT",
                        help="the ROS 2 side is on this router (e.g. rmw_zenohd's "
                        "tcp/127.0.0.1:7447), joined as a second client session; default: the "
                        "router the other services use")
    out = parser.add_argument_group("out (gngdt -> ROS 2)")
    out.add_argument("--graph-rate", type=float, default=DEFAULT_GRAPH_RATE_HZ, metavar="HZ",
                     help="most graphs (/gngdt/<cam>/graph) a second: a MarkerArray of "
                     "thousands of lines takes ~100 ms to encode "
                     f"(default {DEFAULT_GRAPH_RATE_HZ:g})")
    out.add_argument("--camera-frame", metavar="FRAME",
                     help="ROS frame of a posed cloud's points, the child of the fixed frame in "
                     "/tf (default: the camera name); must not be a frame the robot's TF "
                     "already has")
    camera = parser.add_argument_group("in (a ROS 2 camera driver -> gngdt)")
    camera.add_argument("--no-input", action="store_true",
                        help="subscribe to no camera (gngdt's own capture publishes the frames)")
    defaults = CameraTopics()
    camera.add_argument("--color-topic", default=defaults.color,
                        help=f"colour sensor_msgs/Image, rgb8 or bgr8 (default {defaults.color})")
    camera.add_argument("--depth-topic", default=defaults.depth,
                        help="depth sensor_msgs/Image aligned to colour, 16UC1 millimetres or "
                        f"32FC1 metres (default {defaults.depth})")
    camera.add_argument("--camera-info-topic", default=defaults.camera_info,
                        help=f"colour sensor_msgs/CameraInfo (default {defaults.camera_info})")
    camera.add_argument("--max-skew-ms", type=float, default=DEFAULT_MAX_SKEW_MS,
                        help="largest stamp difference between a colour and a depth image "
                        f"paired into a frame (default {DEFAULT_MAX_SKEW_MS:g})")
    camera.add_argument("--fixed-frame", metavar="FRAME",
                        help="look up each frame's camera pose in this frame (e.g. odom, map) "
                        "in /tf and /tf_static; frames without a pose publish no cloud "
                        "(default: no poses, camera-frame clouds)")
    limits = ReadLimits()
    camera.add_argument("--max-frame-pixels", type=int, default=limits.max_frame_pixels,
                        metavar="N", help="largest image, width x height (default "
                        f"{limits.max_frame_pixels:,}); a larger one is refused, counted")
    camera.add_argument("--max-pending-mb", type=int, default=limits.max_held_bytes >> 20,
                        metavar="MB", help="images held waiting for their partner (default "
                        f"{limits.max_held_bytes >> 20})")
    add_cloud_arguments(camera)
    add_sampling_seed_argument(camera)
    add_report_argument(parser, "the node, the router its ROS 2 side used, its topics and the "
                        "messages it published")
    add_zenoh_arguments(parser)


def domain_id(args: argparse.Namespace) -> int:
    """``--domain``, else ``ROS_DOMAIN_ID`` (``args.environment``), else 0; ``ValueError``
    naming the source."""
    if args.domain is not None:
        value, source = args.domain, "--domain"
    else:
        text = args.environment.ros_domain_id
        if not text:
            return 0
        source = f"ROS_DOMAIN_ID={text!r}"
        value = int(text) if text.isdigit() else -1
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise ValueError(f"{source}: a ROS 2 domain id is 0-{MAX_DOMAIN_ID}")
    return value


def check_names(args: argparse.Namespace) -> None:
    """The camera name and topics must make valid ROS 2 names (``ValueError`` says which)."""
    from gngdt.io.ros2.wire import validate_node_name, validate_topic_name
    from gngdt.schemas.wire import topic

    topic(args.cam, "points")
    try:
        validate_node_name(f"gngdt_{args.cam}")
        validate_topic_name(f"/gngdt/{args.cam}/points")
    except ValueError:
        raise ValueError(f"--cam {args.cam!r}: ROS 2 names take letters, digits and _ only "
                         "(the node is gngdt_<cam>)") from None
    for option in ("color_topic", "depth_topic", "camera_info_topic"):
        try:
            validate_topic_name(getattr(args, option))
        except ValueError as error:
            raise ValueError(f"--{option.replace('_', '-')}: {error}") from None
    if not args.graph_rate > 0:
        raise ValueError(f"--graph-rate must be positive, got {args.graph_rate}")
    if args.max_skew_ms < 0:
        raise ValueError(f"--max-skew-ms must be >= 0, got {args.max_skew_ms}")
    ReadLimits(max_frame_pixels=args.max_frame_pixels,
               max_held_bytes=args.max_pending_mb << 20)  # positive, or ValueError


def main(args: argparse.Namespace) -> int:
    from gngdt.services.capture import frame_to_cloud
    from gngdt.services.plumbing.session import ZenohSetupError, open_session

    try:
        check_names(args)
        domain = domain_id(args)
        to_cloud = frame_to_cloud(args)
    except ValueError as error:
        log.error("%s", error)
        return 2
    sessions: list[zenoh.Session] = []
    try:
        sessions.append(open_session(args))
        if args.ros2_connect:
            sessions.append(open_ros2_session(args.ros2_connect, args.router_wait))
    except ZenohSetupError:  # said by the command line, exit 1; the sessions close first
        for session in sessions:
            session.close()
        raise
    try:
        bridge(args, sessions[0], sessions[-1], domain, to_cloud)
    finally:
        for session in reversed(sessions):
            session.close()
    return 0


def give_back_memory(inbound: RosToGngdt | None, trimmed_at: int) -> int:
    """Once the camera's samples are all handled, give the memory they took back to the system
    (`gngdt.io.memory`: an image flood left the bridge at 846 of its 882 MB peak, 10 s after);
    the samples received by then."""
    from gngdt.io.memory import release_free_memory

    if inbound is None:
        return trimmed_at
    received = inbound.worker.counts.received
    if received != trimmed_at and inbound.idle():
        release_free_memory()
        return received
    return trimmed_at


def open_ros2_session(endpoints: list[str], wait_s: float) -> zenoh.Session:
    """A client session of the ROS 2 router (loopback defaults: listening nowhere, no scouting)."""
    from gngdt.services.plumbing.session import ROS2_SESSION, client_config, open_config

    return open_config(client_config(endpoints), what=ROS2_SESSION, wait_s=wait_s)


def bridge(args: argparse.Namespace, gngdt: zenoh.Session, ros: zenoh.Session, domain: int,
           to_cloud: FrameToCloud) -> None:
    """Translate until a stop signal; everything declared is undeclared on the way out."""
    from gngdt.io.memory import map_large_buffers
    from gngdt.io.ros2.messages import OK, WARN, Status
    from gngdt.io.ros2.node import Ros2Node
    from gngdt.services.plumbing import lifecycle
    from gngdt.services.ros2.inbound import CameraTopics, RosToGngdt
    from gngdt.services.ros2.outbound import GngdtToRos, ros_topics

    map_large_buffers()  # 4K images and large clouds: each freed at once, not kept in arenas
    node = Ros2Node(ros, f"gngdt_{args.cam}", domain_id=domain)
    outbound = GngdtToRos(gngdt, node, args.cam, args.camera_frame or args.cam,
                          1.0 / args.graph_rate)
    inbound = None
    tokens = [gngdt.liveliness().declare_token(alive_key(args.cam, BRIDGE))]
    try:
        if not args.no_input:
            to_cloud.warm_up()  # numba's kernels loaded before the first frame, not on it
            inbound = RosToGngdt(
                gngdt, node, args.cam,
                CameraTopics(args.color_topic, args.depth_topic, args.camera_info_topic),
                to_cloud, max_skew_ns=int(args.max_skew_ms * 1e6),
                max_pixels=args.max_frame_pixels, max_held_bytes=args.max_pending_mb << 20,
                fixed_frame=args.fixed_frame, pool_bytes=args.environment.shm_pool_bytes)
            tokens.append(gngdt.liveliness().declare_token(alive_key(args.cam, CAPTURE)))
        log.info("ROS 2 node gngdt_%s in domain %d: %s", args.cam, domain,
                 "camera in, results out" if inbound else "results out")
        skipped = 0
        trimmed_at = 0  # samples received when the memory was last given back
        with lifecycle.graceful() as stop:
            while not stop.wait(STATUS_PERIOD_S):
                trimmed_at = give_back_memory(inbound, trimmed_at)
                values = outbound.counts() | (inbound.counts_for_status() if inbound else {})
                bad = sum(value for key, value in values.items()
                          if key.endswith(("malformed", "failed", "bad_frames",
                                           "calibrations_refused")))
                outbound.publish_status(Status(
                    topic(args.cam, BRIDGE), WARN if bad > skipped else OK,
                    f"skipped {bad - skipped} bad messages" if bad > skipped else "bridging",
                    args.cam, values))
                skipped = bad
    finally:
        for token in tokens:
            token.undeclare()
        outbound.close()
        if inbound is not None:
            inbound.close()
        node.close()
        time.sleep(0.1)  # let the undeclarations reach the router
        write_report(args.report, {
            "node": f"/gngdt_{args.cam}", "domain": domain,
            "router": args.ros2_connect or args.zenoh_connect or [DEFAULT_ENDPOINT],
            "topics": list(ros_topics(args.cam).values()), "messages_out": outbound.published})
