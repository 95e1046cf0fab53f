"""Learn GNG-DT topologies from a camera's point clouds and publish them with their clusterings.

Each cloud on ``gngdt/<cam>/points`` is learned by the learner's per-frame policy
(`gngdt.core.learner.frame_learner.FrameLearner`: one network, in the frame of the first cloud; the
learner's profile forgets nodes that stand for nothing any more and rehearses earlier frames of
a moving camera; a map in a fixed frame grows with the surface seen). Each frame gets the
learning steps that fit in its share of the time between frames, so the learner keeps up on a
busy machine. With ``--track``, clouds without a pose are placed by aligning them to the map,
and the camera's pose is published on ``gngdt/<cam>/tf``. At most every ``publish_every_s``
of the stream's clock (0.1 s), and after the stream's last frame, the learner publishes the
topology (edges per property, every clustering of `gngdt.core.clustering.CLUSTERINGS` with
persistent cluster ids, and persistent node ids), the objects (one per confirmed cluster of
``objects_from``, as a foxglove SceneUpdate) and a status message, and with every
``scene_every_frames``-th publication the whole scene as a foxglove SceneUpdate; a queryable
on the topology key answers a late joiner with the latest topology
(`gngdt.services.learner.serve`). The model is checkpointed periodically and on SIGINT/SIGTERM,
and resumed from the checkpoint on start (`gngdt.services.learner.checkpoints`).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt.core.clustering import CLUSTERINGS
from gngdt.io.import_checks import add_pose_limit_arguments, pose_limit_values
from gngdt.schemas.wire import DEFAULT_CAMERA, topic
from gngdt.services.plumbing.session import add_zenoh_arguments, open_session
from gngdt.services.plumbing.settings import OptionGroup, add_settings_argument

if TYPE_CHECKING:
    from gngdt.io.profiles import Profile

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt learn                                          # camera "camera", the learner's defaults
  gngdt learn --params config/learner.toml --checkpoint runs/learner.npz
  gngdt learn --cam left --samples-per-frame 20000 --max-nodes 2000
  gngdt learn --params config/kinect.toml --print-params   # effective values, and from where
  gngdt learn --workspace-m 50 --max-speed 2     # a room-sized robot: tighter pose checks
  gngdt learn --track                            # unposed clouds: track the camera (odom)
"""


def add_learning_arguments(group: Any) -> None:
    """How the learner learns (`LEARNING`: `gngdt run` has these options too)."""
    group.add_argument("--params", type=Path, metavar="FILE.toml",
                       help="GNG-DT parameters and learner options; config/learner.toml "
                       "documents every key (installed with gngdt: `python -m gngdt.config` "
                       "prints where)")
    group.add_argument("--checkpoint", type=Path, metavar="PATH",
                       help="checkpoint file (.npz): resumed from if present, saved periodically "
                       "and on shutdown")
    group.add_argument("--samples-per-frame", type=int,
                       help="learning steps per frame (default 10000)")
    group.add_argument("--max-nodes", type=int, help="node budget (default 1000)")
    group.add_argument("--min-cluster-size", type=int,
                       help="smallest component counted as a cluster (default 5)")
    group.add_argument("--checkpoint-every", type=int, metavar="FRAMES",
                       help="checkpoint every this many learned frames (default 30)")
    group.add_argument("--seed", type=int, help="random seed of the model (default 0)")
    group.add_argument("--objects-from", metavar="CLUSTERING",
                       help="clustering published as objects on gngdt/<cam>/objects (default "
                       f"segments; any of {', '.join(CLUSTERINGS)})")
    group.add_argument("--publish-every", type=float, metavar="SECONDS",
                       help="publish what was learned (topology, objects, scene, status) at "
                       "most this often, in seconds of the stream's own clock (default 0.1: "
                       "every third frame at 30 fps; the last frame always; 0: every learned "
                       "frame)")
    group.add_argument("--object-confirm-frames", type=int, metavar="FRAMES",
                       help="a cluster is published as an object once seen in this many "
                       "publications in a row (default 5; 1: at once)")
    group.add_argument("--scene-every", type=int, metavar="FRAMES",
                       help="publish the foxglove scene on gngdt/<cam>/scene with every this "
                       "many publications (default 3; 0: never)")
    add_pose_limit_arguments(group)
    group.add_argument("--track", action="store_true", default=None,
                       help="estimate the camera's pose of clouds that come without one by "
                       "aligning each to the map; publish it on gngdt/<cam>/tf and learn in "
                       "the fixed frame 'odom'; frames whose alignment fails are not learned "
                       "(the status says why)")


#: the learner's options, declared once for `gngdt learn` and `gngdt run`
LEARNING = OptionGroup("learning (gngdt learn)", add_learning_arguments)
#: the option groups a settings file (``--settings``) may hold
SETTINGS = [LEARNING]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cam", default=DEFAULT_CAMERA, help="camera name in the topics")
    parser.add_argument("--print-params", action="store_true",
                        help="print every effective parameter and where it came from (a "
                        "default, the --params file or an option), then exit")
    for group in SETTINGS:
        group.add_to(parser)
    parser.add_argument("--exit-on-eos", action="store_true",
                        help="exit after learning the last frame of a stream (used by `gngdt run`)")
    add_settings_argument(parser)
    add_zenoh_arguments(parser)


def profile_from_args(args: argparse.Namespace) -> Profile:
    """The params file (or the learner's defaults) overridden by explicit command-line options;
    ValueError naming the file or option that is wrong."""
    from gngdt.io.profiles import load_profile

    flags = {"samples_per_frame": "samples_per_frame", "min_cluster_size": "min_cluster_size",
             "checkpoint_every_frames": "checkpoint_every", "seed": "seed",
             "objects_from": "objects_from", "object_confirm_frames": "object_confirm_frames",
             "scene_every_frames": "scene_every", "publish_every_s": "publish_every",
             "track": "track"}
    options = {name: getattr(args, flag) for name, flag in flags.items()}
    options.update({f"pose_{name}": value for name, value in pose_limit_values(args).items()})
    return load_profile(args.params).with_overrides(
        {"max_nodes": args.max_nodes}, options, "command line")


def main(args: argparse.Namespace) -> int:
    from gngdt.core.learner.frame_learner import FrameLearner
    from gngdt.io.checkpoints import CheckpointError, CheckpointLock
    from gngdt.io.profiles import format_parameters
    from gngdt.services.learner import checkpoints
    from gngdt.services.learner.serve import LearnerInstances, serve, warm_up

    lock = None
    try:
        profile = profile_from_args(args)
        if args.print_params:
            print(format_parameters(profile), end="")
            return 0
        config = profile.config
        topic(args.cam, "points")
        if args.checkpoint is not None:
            lock = CheckpointLock(args.checkpoint).acquire()
            checkpoints.clean_checkpoint_directory(args.checkpoint)
        if args.checkpoint is not None and args.checkpoint.exists():
            learner = checkpoints.resume(args.checkpoint, args.cam, config)
        else:
            learner = FrameLearner(args.cam, config)
        session = open_session(args)  # ZenohSetupError: said by the command line, exit 1
        try:
            # announced before the kernels: a second learner of the camera is refused at once,
            # and a capture reading a file waits for this one while it compiles
            instances = LearnerInstances(session, args.cam)
            started = time.monotonic()
            log.info("preparing the learning kernels (the first run on a machine compiles them "
                     "with numba, 15-40 s; later runs load them from its cache in under a "
                     "second)")
            warm_up(config)
            log.info("kernels ready in %.1f s", time.monotonic() - started)
            return serve(args, config, learner, session, instances)
        finally:
            time.sleep(0.1)  # let the last BLOCK puts reach the router
            session.close()
    except (ValueError, CheckpointError) as error:
        log.error("%s", error)
        return 2
    finally:
        if lock is not None:
            lock.release()
