"""A run's plan: its source opened once and its parameters read as the services will, its
outputs named and reserved, every port it will serve checked free -- all before any process
starts, so a wrong option is said at once (ValueError or RecordingError)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from gngdt.io.outputs.rerun_output import default_rrd_path, rates_from_args, reserve_path
from gngdt.io.outputs.rerun_sinks import check_ports_free
from gngdt.schemas.wire import topic
from gngdt.services.capture import source_spec
from gngdt.services.run.live import check_linger

if TYPE_CHECKING:
    from gngdt.io.outputs.rerun_log import DisplayRates
    from gngdt.io.profiles import Profile


#: where `--ros2` finds ROS 2 by default: rmw_zenohd listens there
ROS2_ROUTER = "tcp/127.0.0.1:7447"
#: how a source goes to the learner (the summary says which ran)
PACED = ("every frame, each sent once the learner took the one before (a file; --realtime: at "
         "the recorded pace, the latest frame wins)")
REALTIME = "real time (--realtime): the recorded pace, the learner takes the latest frame"
LIVE = "a live camera: real time, the learner takes the latest frame"


def run_name(spec: str) -> str:
    """The name a run's files take from its source: a file's stem, or a spec without its
    colons (``realsense:123`` -> ``realsense-123``)."""
    if ":" in spec and not Path(spec).exists():
        return "-".join(part for part in spec.split(":") if part)
    return Path(spec).stem


@dataclass
class RunPlan:
    """What a run will learn with and write, checked before anything starts."""

    rates: DisplayRates
    #: the learner's parameters, as the learner will read them (a wrong file fails here)
    profile: Profile
    rrd_path: Path | None
    mcap_path: Path | None
    #: how the source goes to the learner: `PACED`, `REALTIME` or `LIVE`
    mode: str = ""

    @property
    def veil_ratio(self) -> float | None:
        """The sensor profile's veil ratio (capture drops those pixels), if it has a schedule."""
        schedule = self.profile.config.schedule
        return None if schedule is None else schedule.veil_ratio

    @property
    def paced(self) -> bool:
        """A file read frame by frame (every frame waits for the learner)."""
        return self.mode == PACED

    @property
    def live(self) -> bool:
        """A live camera: real time, until Ctrl-C."""
        return self.mode == LIVE

    @property
    def destination(self) -> str:
        if self.rrd_path is not None:
            return str(self.rrd_path)
        if self.served:
            return "served by --serve, not saved (without --serve a run saves its .rrd)"
        return "a rerun viewer (--connect; nothing saved)"

    #: the run serves rerun's web viewer (--serve)
    served: bool = False


def plan_run(args: argparse.Namespace) -> RunPlan:
    """The run's plan, its outputs named and reserved (`plan_outputs`); ValueError or
    RecordingError for anything wrong, before any process starts."""
    from gngdt.io.sources import SourceOptions, open_source

    args.recording = source_spec(args)
    options = SourceOptions(camera_json=args.camera_json, depth_scale=args.depth_scale)
    # as capture will open it: RecordingError says why it cannot
    source = open_source(args.recording, options=options)
    source.close()
    mode = LIVE if source.live else REALTIME if args.realtime else PACED
    if args.url and not args.connect:
        raise ValueError("--url needs --connect")
    from gngdt.io.outputs.foxglove import FoxgloveOutput
    from gngdt.services.learner import profile_from_args

    FoxgloveOutput.check_args(args)  # a port in use: said before anything starts
    check_linger(args)
    check_ros2_router(args.ros2)
    profile = profile_from_args(args)  # a wrong params file: said before anything starts
    topic(args.cam, "points")  # validates the camera name
    rates = rates_from_args(args)
    return RunPlan(rates, profile, *plan_outputs(args), mode=mode, served=args.serve)


def check_ros2_router(endpoint: str | None) -> None:
    """ValueError, before anything starts, when nothing listens at ``--ros2``'s endpoint (a
    wrong endpoint fails in seconds, with what docs/ros2.md says to start)."""
    from gngdt.services.plumbing.session import ROS2_SESSION, endpoint_listening, router_advice

    if endpoint is not None and endpoint_listening(endpoint) is False:
        raise ValueError(f"--ros2 {endpoint}: nothing listens there; "
                         f"{router_advice(ROS2_SESSION)}")


# --- issue 24.4: runs that never collide -------------------------------------------------------
def plan_outputs(args: argparse.Namespace) -> tuple[Path | None, Path | None]:
    """The run's .rrd and MCAP paths, each reserved for this run alone (created empty at once:
    two runs started in the same second get two names, and each summary names its own); a
    ``--save`` or ``--mcap`` file that exists is refused unless ``--overwrite``, and a busy
    ``--serve`` port before anything starts (ValueError)."""
    if args.serve:
        try:
            check_ports_free(args.bind, {"--grpc-port": args.grpc_port,
                                         "--web-port": args.web_port})
        except OSError as error:
            raise ValueError(str(error)) from error
    for option, path in (("--save", args.save), ("--mcap", args.mcap)):
        if path is not None and path.exists() and not args.overwrite:
            raise ValueError(f"{option} {path}: the file exists (an earlier run's?); choose "
                             "another path, or --overwrite to replace it")
    mcap_path = None if args.mcap is None else claim(args.mcap, args.overwrite)
    rrd_path = None
    if not (args.connect or args.serve):
        rrd_path = (claim(args.save, args.overwrite) if args.save
                    else reserve_path(default_rrd_path(run_name(args.recording))))
    return rrd_path, mcap_path


def claim(path: Path, overwrite: bool) -> Path:
    """``path`` for this run: reserved (created empty) unless it is to be overwritten."""
    if overwrite and path.exists():
        return path
    reserved = reserve_path(path)
    if reserved != path:  # created since the check above: another run took it
        reserved.unlink()
        raise ValueError(f"{path}: another run created it just now; choose another path")
    return reserved


def drop_unwritten(plan: RunPlan, everything: bool = False) -> None:
    """Remove the files reserved for a run that wrote nothing into them, or (``everything``:
    a run that failed before it learned a frame) whatever they hold."""
    for path in (plan.rrd_path, plan.mcap_path):
        if path is not None and path.is_file() and (everything or path.stat().st_size == 0):
            path.unlink()
# --- end of issue 24.4 ------------------------------------------------------------------------
