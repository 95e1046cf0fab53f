"""Run the whole pipeline on one source (a recording, or a live RealSense with ``--realsense``): a
loopback router, then learner, logger and capture.

The router is this process's own zenoh session (mode router, a free port on 127.0.0.1, scouting
off) and admits only this run's children: each authenticates with a user and password made for
the run for its role (zenoh's usrpwd; `RunAccess`), and the router's access control lets each
role put only on its own streams, so a neighbour on the machine can neither publish into the
run (a forged end of stream) nor listen, and no service can speak for another. ``run`` starts
the learner and the logger, waits for their liveliness tokens, says where its servers are,
starts the capture, waits for the end of the stream, lets the learner finish its last frame and
the logger flush (or serve on, ``--linger``), then prints a summary: every frame sent accounted
for, every refusal with its reason (capture's from its end of stream, the learner's from its
acknowledgements), the files and servers with their addresses, and warnings. SIGINT, SIGTERM
and SIGHUP stop everything cleanly, and the children die with ``run`` however it ends. The exit
status says which service said no (`gngdt.services.run.verdict`).
"""

from __future__ import annotations

import argparse
import logging
import shutil
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

from gngdt.io.deproject import RUN_POINT_CAP
from gngdt.io.outputs.rerun_output import add_serve_arguments
from gngdt.schemas.wire import (
    ALL_KEYS,
    BRIDGE,
    DEFAULT_CAMERA,
    LEARNER,
    LOGGER_ALIVE,
    alive_key,
    topic,
)
from gngdt.services.capture import SETTINGS as CAPTURE_SETTINGS
from gngdt.services.capture import add_source_arguments
from gngdt.services.learner import SETTINGS as LEARNER_SETTINGS
from gngdt.services.logger import SETTINGS as LOGGER_SETTINGS
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.report import read_report
from gngdt.services.plumbing.roles import RUN_FOLDER_PREFIX, RunAccess, remove_stale_credentials
from gngdt.services.plumbing.session import ZenohSetupError, free_tcp_port, open_config
from gngdt.services.plumbing.settings import OptionGroup
from gngdt.services.run import live
from gngdt.services.run.children import (
    Child,
    Pipeline,
    StartupProgress,
    cpu_ticks,
    wait_for_startup,
    wait_until,
)
from gngdt.services.run.observe import Observed
from gngdt.services.run.plan import ROS2_ROUTER, RunPlan, drop_unwritten, plan_run
from gngdt.services.run.summary import RunFacts, file_size, format_summary, recorded_frames
from gngdt.services.run.verdict import (
    DONE,
    EXIT_STATUS_HELP,
    FAILED,
    INPUT_UNUSABLE,
    INTERRUPTED,
    RunOutcome,
    exit_status,
)

__all__ = ["CHILD_SETTINGS", "EXAMPLES", "Child", "Observed", "Pipeline", "RunAccess",
           "StartupProgress", "add_arguments", "child_settings", "cpu_ticks", "main",
           "wait_for_startup", "wait_until"]

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt run recordings/tabletop.mcap                 # writes runs/tabletop-<time>.rrd
  gngdt run recordings/tabletop.mcap --fast --save out.rrd   # refused if out.rrd exists
  gngdt run recordings/tabletop.mcap --save out.rrd --overwrite   # ... unless asked
  gngdt run recordings/tabletop.mcap --connect       # to a running rerun viewer
  gngdt run recordings/tabletop.mcap --mcap runs/tabletop.mcap   # + every stream for Foxglove
  gngdt run recordings/tabletop.mcap --keep-everything            # every frame in full in the .rrd
  gngdt run --realsense                              # the RealSense plugged in, until Ctrl-C
  gngdt run session.db3 --foxglove                   # live in Foxglove at ws://127.0.0.1:8765
  gngdt run recordings/tabletop.mcap --ros2          # + ROS 2 topics, via rmw_zenohd on 7447
  gngdt run walk.mcap --track                        # camera poses estimated, not read
  gngdt run recordings/tabletop.mcap --serve --linger   # the web viewer serves on until Ctrl-C

""" + EXIT_STATUS_HELP

#: each service's option groups: `gngdt run` has their options and hands each service its own
CHILD_SETTINGS: dict[str, list[OptionGroup]] = {
    "capture": CAPTURE_SETTINGS, "learn": LEARNER_SETTINGS, "log": LOGGER_SETTINGS}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_source_arguments(parser)
    viewer = parser.add_mutually_exclusive_group()
    viewer.add_argument("--save", type=Path, metavar="PATH",
                        help="write the rerun recording here (default runs/<recording>-<time>.rrd)")
    viewer.add_argument("--connect", action="store_true", help="log to a running rerun viewer")
    viewer.add_argument("--serve", action="store_true",
                        help="serve a web viewer (on this machine only unless --bind says)")
    parser.add_argument("--url", help="rerun viewer URL for --connect")
    add_serve_arguments(parser)
    parser.add_argument("--mcap", type=Path, metavar="PATH",
                        help="also record every gngdt stream (images, clouds, topology, scene, "
                        "objects, status) into this MCAP file for Foxglove (rerun shows only its "
                        "images and clouds)")
    parser.add_argument("--foxglove", action="store_true",
                        help="also serve every stream live to Foxglove (WebSocket at --bind, "
                        "port 8765 unless --bind names one)")
    live.add_linger_argument(parser)
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing --save or --mcap file (default: refused)")
    parser.add_argument("--cam", default=DEFAULT_CAMERA, help="camera name in the topics")
    parser.add_argument("--startup-timeout", type=float, default=60.0, metavar="SECONDS",
                        help="while the learner and logger come up (the first run on a machine "
                        "compiles kernels: 15-40 s, longer on a busy one), give up on one only "
                        "when it shows no progress, no CPU time used and nothing logged, for "
                        "this long (default 60)")
    parser.add_argument("--drain-timeout", type=float, default=30.0, metavar="SECONDS",
                        help="after the stream ends, how long learner and logger may take to "
                        "finish before they are interrupted (default 30)")
    parser.add_argument("--ros2", nargs="?", const=ROS2_ROUTER, metavar="ENDPOINT",
                        help="also run `gngdt ros2 --no-input`: the results as ROS 2 topics on the "
                        f"ROS 2 router at ENDPOINT (default {ROS2_ROUTER}, rmw_zenohd's)")
    # the services' own options, declared once by each (`gngdt.services.plumbing.settings`)
    for group in CHILD_SETTINGS.values():
        for options in group:
            options.add_to(parser)


def child_settings(args: argparse.Namespace, service: str, veil_ratio: float | None = None
                   ) -> dict[str, Any]:
    """The options ``service`` runs with: its option groups' values as the run parsed them,
    and what the run decides for it (capture under ``--track``: the recording's poses ignored
    and whole clouds, as tracking aligns whole depth images; otherwise clouds capped at
    `RUN_POINT_CAP`, and veil pixels dropped as the sensor profile says)."""
    values = {name: value for group in CHILD_SETTINGS[service]
              for name, value in group.values(args).items()}
    if service == "capture":
        if args.track:
            values["fixed_frame"] = "none"
        if values["max_points"] is None:
            values["max_points"] = 0 if args.track else RUN_POINT_CAP
        if values["drop_veil"] is None:
            values["drop_veil"] = veil_ratio
    return values


def ros2_arguments(args: argparse.Namespace, report: Path) -> list[str]:
    """The ROS 2 bridge's command line under ``run --ros2``: results out, no camera input; what
    it did into ``report``."""
    return ["--cam", args.cam, "--no-input", "--ros2-connect", args.ros2,
            "--router-wait", str(args.startup_timeout), "--report", str(report)]


def logger_arguments(args: argparse.Namespace, rrd_path: Path | None,
                     mcap_path: Path | None = None, report: Path | None = None) -> list[str]:
    """Where the logger writes and serves (the run reserved its paths: ``--overwrite``), and
    what it did into ``report``; with ``--linger`` its servers outlive the stream."""
    arguments = ["--overwrite", *(["--report", str(report)] if report else [])]
    if mcap_path is not None:
        arguments += ["--mcap", str(mcap_path)]
    if args.linger is not None:
        arguments.append("--keep-running")  # until the run tells it to stop
    if args.connect:
        return [*arguments, "--connect", *(["--url", args.url] if args.url else [])]
    if args.foxglove:
        arguments += ["--foxglove", "--bind", args.bind]
    if args.serve:
        return [*arguments, "--serve", "--bind", args.bind, "--grpc-port",
                str(args.grpc_port), "--web-port", str(args.web_port)]
    return [*arguments, "--save", str(rrd_path)]  # (the run reserved its paths: --overwrite)


def run_pipeline(args: argparse.Namespace, plan: RunPlan, log_dir: Path) -> RunOutcome:
    """The run's router and services, supervised to the end (`supervise`). Raises
    ZenohSetupError when the router cannot start, StartupTimeout when the services do not."""
    access = RunAccess(f"tcp/127.0.0.1:{free_tcp_port()}", log_dir)
    router = open_config(access.router(), what="router")
    observed = Observed()
    declared = [
        router.liveliness().declare_subscriber(ALL_KEYS, observed.on_liveliness, history=True),
        router.declare_subscriber(topic(args.cam, "learner/status"), observed.on_status),
        router.declare_subscriber(topic(args.cam, "learner/ack"), observed.on_ack),
        router.declare_subscriber(topic(args.cam, "eos"), observed.on_eos),
    ]
    pipeline = Pipeline(access, log_dir, args.log_level)
    try:
        with lifecycle.graceful() as stop:
            early_end, lingered = supervise(args, pipeline, observed, stop, plan)
        # a stop while the servers lingered ends the lingering, not the run's work
        interrupted = stop.is_set() and lingered is None
        failure = pipeline.failed()
    finally:
        pipeline.close()
        for entity in declared:
            entity.undeclare()
        router.close()
        access.forget()
    with observed.lock:
        status, end, acks = observed.status, observed.end, observed.acks
    if interrupted:
        early_end = early_end or f"interrupted ({lifecycle.stop_reason()})"
    return RunOutcome(status, end, early_end, failure, interrupted, acks,
                      read_report(log_dir / "log.report.json"),
                      read_report(log_dir / "ros2.report.json"), lingered)


def report(args: argparse.Namespace, plan: RunPlan, outcome: RunOutcome, code: int) -> None:
    """Print the run's summary (and a failed service's last words); ``code``: its exit
    status."""
    facts = RunFacts(outcome.status, outcome.end, outcome.acks, plan.destination,
                     recorded_frames(args.recording), outcome.early_end,
                     output_lines(args, plan, outcome, code),
                     plan.profile.model_value("max_nodes"), plan.mode, plan.paced,
                     [stop_warning(output) for output in outcome.stopped_outputs])
    failure = outcome.failure
    try:  # after a SIGHUP the terminal may be gone: nothing more to say then
        print(format_summary(facts), flush=True)
        if failure is not None:
            print(f"\n{failure.name} failed (exit {failure.process.returncode}):\n"
                  f"{failure.stderr_tail()}", file=sys.stderr)
    except OSError:
        pass


def output_lines(args: argparse.Namespace, plan: RunPlan, outcome: RunOutcome,
                 code: int) -> list[str]:
    """The summary's lines on what the run wrote and served: the .rrd (or what the viewer was
    given), the MCAP, the live servers' addresses, the ROS 2 bridge; a failed run's files are
    said to be partial, or removed."""
    what = "in the .rrd:" if plan.rrd_path is not None else "to the viewer:"
    lines = [f"  {what:<18}{plan.rates.describe()}"]
    if plan.rrd_path is not None:  # (what a removed file held is not said)
        size = f"  .rrd size:        {kept_file(plan.rrd_path, code)}"
        lines = [size, *lines] if plan.rrd_path.is_file() else [size]
    if plan.mcap_path is not None:
        lines.append(f"mcap:               {plan.mcap_path} ({kept_file(plan.mcap_path, code)}; "
                     "every stream, for Foxglove)")
    lines += live.summary_lines(live.live_outputs(args), outcome.lingered, plan.live)
    if args.ros2:
        lines.append(live.ros2_line(outcome.ros2_report, args.ros2))
    return lines


def kept_file(path: Path, code: int) -> str:
    """A file's size, and what a run that ended with ``code`` left of it: a failed run's
    file is partial, or removed when the learner learned no frame (`drop_unwritten`)."""
    if not path.is_file():
        return "not written" if code in (DONE, INTERRUPTED) else \
            "removed: the run failed and the learner learned no frame"
    return file_size(path) + ("; partial: the run failed, it holds what came until then"
                              if code == FAILED else "")


def stop_warning(output: dict[str, Any]) -> str:
    """The summary's warning on an output that stopped writing before the end."""
    return (f"{output['where']} stopped early: {output['stopped_early']}; what came before is "
            "kept, complete and readable; nothing after it")


def main(args: argparse.Namespace) -> int:
    from gngdt.io.mcap.reader import RecordingError

    try:
        plan = plan_run(args)
    except (RecordingError, ValueError, OSError) as error:
        log.error("%s", error)
        return INPUT_UNUSABLE
    remove_stale_credentials()  # of runs killed before they could
    log_dir = Path(tempfile.mkdtemp(prefix=RUN_FOLDER_PREFIX))  # 0700: the run's passwords
    try:
        outcome = run_pipeline(args, plan, log_dir)
    except (ZenohSetupError, StartupTimeout) as error:
        if isinstance(error, ZenohSetupError):
            log.error("%s", error)
        drop_unwritten(plan, everything=True)
        return 1
    code, why = exit_status(outcome)
    drop_unwritten(plan, everything=code not in (DONE, INTERRUPTED)
                   and not outcome.acks.outcomes["learned"])
    report(args, plan, outcome, code)
    if why:
        log.error("%s", why)
    if outcome.failure is None:
        shutil.rmtree(log_dir, ignore_errors=True)
    return code


class StartupTimeout(Exception):
    """The learner and the logger did not come up in time."""


def supervise(args: argparse.Namespace, pipeline: Pipeline, observed: Observed,
              stop: threading.Event, plan: RunPlan) -> tuple[str, float | None]:
    """Start the services and see the stream through; why it ended early (or ``""``), and how
    long the servers served after a file's end (None: they did not)."""
    log.info("starting the learner and the logger (the first run on a machine compiles the "
             "learning kernels: 15-40 s, longer on a busy machine; later runs take seconds)")
    learner = pipeline.start("learn", ["--cam", args.cam, "--exit-on-eos"],
                             child_settings(args, "learn"))
    logger = pipeline.start("log", logger_arguments(args, plan.rrd_path, plan.mcap_path,
                                                    pipeline.log_dir / "log.report.json"),
                            child_settings(args, "log"))
    starting = {learner: alive_key(args.cam, LEARNER), logger: LOGGER_ALIVE}
    if args.ros2:  # the results into ROS 2 as well (see `gngdt ros2`)
        bridge = pipeline.start("ros2", ros2_arguments(args, pipeline.log_dir / "ros2.report.json"))
        starting[bridge] = alive_key(args.cam, BRIDGE)
    silent = wait_for_startup(starting, observed, args.startup_timeout, stop, pipeline)
    if silent:
        log.error("the %s shows no progress: no CPU time used and nothing logged for %.0f s "
                  "while starting (a hung process?); its log: %s", silent.name,
                  args.startup_timeout, silent.stderr_path)
        pipeline.interrupt_all()
        for child in pipeline.children:
            child.stop(args.drain_timeout)
        raise StartupTimeout
    early_end, lingered = "", None
    if not stop.is_set() and pipeline.failed() is None:
        live.announce(live.live_outputs(args))
        early_end = replay(args, pipeline, observed, stop, plan, learner, logger)
        if (not early_end and args.linger is not None and not stop.is_set()
                and pipeline.failed() is None):
            learner.stop(args.drain_timeout)  # the final network reaches the servers first
            lingered = args.linger
            live.linger(live.live_outputs(args), args.linger, stop)
    failure = pipeline.failed()  # a capture that failed after its end of stream (a camera lost)
    with observed.lock:
        stream_ended = observed.end is not None  # only this run's capture can send it
    lost = failure is not None and failure.name == "capture" and stream_ended  # lets them finish
    if (stop.is_set() and lingered is None) or (failure is not None and not lost) or early_end:
        log.info("%s; stopping the services",
                 "interrupted" if stop.is_set() else early_end or "a service failed")
        pipeline.interrupt_all()
    for child in pipeline.children:
        if child.name == "ros2" or lingered is not None:  # they serve until told to stop
            child.interrupt()
        child.stop(args.drain_timeout)
    return early_end, lingered


def replay(args: argparse.Namespace, pipeline: Pipeline, observed: Observed,
           stop: threading.Event, plan: RunPlan, learner: Child, logger: Child) -> str:
    """Start the capture and wait until it, the learner or the logger ends (or a stop signal);
    why the stream ended early, or ``""``."""
    capture = pipeline.start("capture", [str(args.recording), "--cam", args.cam],
                             child_settings(args, "capture", plan.veil_ratio))
    log.info("replaying %s", args.recording)  # once every service's process is there
    wait_until(lambda: capture.process.poll() is not None
               or learner.process.poll() is not None or logger.process.poll() is not None,
               float("inf"), stop, pipeline)
    if args.linger is not None:  # the learner ends the stream's learning, the logger lingers
        wait_until(lambda: learner.process.poll() is not None, args.drain_timeout, stop,
                   pipeline)
    with observed.lock:
        stream_ended = observed.end is not None
    if (capture.process.poll() is None and not stream_ended and not stop.is_set()
            and pipeline.failed() is None):
        quitter = learner if learner.process.poll() is not None else logger
        return (f"the {'learner' if quitter is learner else 'logger'} stopped while capture "
                "was still replaying")
    return ""
