"""Run the whole pipeline on one source (a recording, or a live RealSense with ``--realsense``): a
loopback router, then learner, logger and capture.

The router is this process's own zenoh session (mode router, a free port on 127.0.0.1, scouting
off) and admits only this run's children: each authenticates with a user and password made for
the run for its role (zenoh's usrpwd; `RunAccess`), and the router's access control lets each
role put only on its own streams, so a neighbour on the machine can neither publish into the
run (a forged end of stream) nor listen, and no service can speak for another. ``run`` starts
the learner and the logger, waits for their liveliness tokens, starts the capture, waits for
the end of the stream, lets the learner finish its last frame and the logger flush, then
prints a summary. SIGINT, SIGTERM and SIGHUP stop
everything cleanly, and the children die with ``run`` however it ends. Exit status is non-zero
when the recording is unusable, a service failed, or the stream ended before the recording did.
"""

from __future__ import annotations

import argparse
import logging
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from gngdt.core.learner.warm_up import PROGRESS_PHRASE
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
from gngdt.services.plumbing.roles import RUN_FOLDER_PREFIX, RunAccess, remove_stale_credentials
from gngdt.services.plumbing.session import ZenohSetupError, free_tcp_port, open_config
from gngdt.services.plumbing.settings import OptionGroup, write_settings
from gngdt.services.run.plan import RunPlan, drop_unwritten, plan_run
from gngdt.services.run.summary import file_size, format_summary, mostly_rejected, recorded_frames

if TYPE_CHECKING:
    import zenoh

    from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo

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
"""

#: where `--ros2` finds ROS 2 by default: rmw_zenohd listens there
ROS2_ROUTER = "tcp/127.0.0.1:7447"
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


@dataclass(eq=False)  # a process: equal only to itself (and hashable)
class Child:
    """One service process; its stderr goes to a file whose tail is shown when it fails."""

    name: str
    process: subprocess.Popen
    stderr_path: Path
    stderr_file: IO[bytes]

    def stderr_tail(self, lines: int = 20) -> str:
        text = self.stderr_path.read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])

    def interrupt(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)

    def stop(self, timeout_s: float) -> int:
        """Wait for the process, escalating SIGINT -> SIGKILL after ``timeout_s``."""
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.interrupt()
        try:
            return self.process.wait(10.0)
        except subprocess.TimeoutExpired:
            log.error("%s did not stop; killing it", self.name)
            self.process.kill()
            return self.process.wait()


@dataclass
class Observed:
    """What ``run`` hears on its own router session: liveliness, status and eos."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    alive: set[str] = field(default_factory=set)
    status: LearnerStatusInfo | None = None
    end: StreamEndInfo | None = None

    def on_liveliness(self, sample: zenoh.Sample) -> None:
        import zenoh

        key = str(sample.key_expr)
        with self.lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(key)
            else:
                self.alive.discard(key)

    def on_status(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.messages import MessageError
        from gngdt.schemas.status import decode_status

        try:
            status = decode_status(sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.status = status

    def on_eos(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.messages import MessageError
        from gngdt.schemas.status import decode_stream_end

        try:
            end = decode_stream_end(sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.end = end

    def has_alive(self, prefix: str) -> bool:
        with self.lock:
            return any(key.startswith(prefix) for key in self.alive)




class Pipeline:
    """The child processes of one run."""

    def __init__(self, access: RunAccess, log_dir: Path, log_level: str) -> None:
        self.access = access
        self.log_dir = log_dir
        self.log_level = log_level
        self.children: list[Child] = []
        self.interrupted = False

    def start(self, name: str, arguments: list[str],
              settings: dict[str, Any] | None = None) -> Child:
        """Start the service ``name`` with ``arguments`` and its ``settings`` (its options'
        values: a file beside its log, `gngdt.services.plumbing.settings`)."""
        if settings is not None:
            path = write_settings(self.log_dir / f"{name}.settings.json", settings)
            arguments = [*arguments, "--settings", str(path)]
        # -P: the user's current folder is not put first on the children's import path
        command = [sys.executable, "-P", "-m", "gngdt.services.cli", name, *arguments,
                   "--zenoh-config", str(self.access.client_file(name)),
                   "--log-level", self.log_level]
        stderr_path = self.log_dir / f"{name}.log"
        stderr_file = open(stderr_path, "wb")  # closed in Pipeline.close()
        env = lifecycle.child_environment()  # the child dies with this process
        log.debug("starting %s", " ".join(command))
        process = subprocess.Popen(command, stdout=stderr_file, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, env=env, start_new_session=True)
        child = Child(name, process, stderr_path, stderr_file)
        self.children.append(child)
        return child

    def failed(self) -> Child | None:
        """The first child that exited with an error, if any (not counting our own SIGINT)."""
        interrupted_codes = (130, -signal.SIGINT) if self.interrupted else ()
        for child in self.children:
            code = child.process.poll()
            if code is not None and code != 0 and code not in interrupted_codes:
                return child
        return None

    def interrupt_all(self) -> None:
        self.interrupted = True
        for child in self.children:
            child.interrupt()

    def close(self) -> None:
        for child in self.children:
            if child.process.poll() is None:
                child.process.kill()
                child.process.wait()
            child.stderr_file.close()


def wait_until(condition, timeout_s: float, stop: threading.Event, pipeline: Pipeline) -> bool:
    """Poll ``condition`` until true; False on timeout, stop request or a failed child."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not stop.is_set() and pipeline.failed() is None:
        if condition():
            return True
        time.sleep(0.05)
    return bool(condition())


class StartupProgress:
    """Whether a starting child is making progress: the CPU time it used, the lines it logged
    (its start-up steps, e.g. "compiling kernels 2/4", are shown as they come)."""

    def __init__(self, child: Child) -> None:
        self.child = child
        self.cpu_ticks = -1
        self.log_bytes = 0
        self.last_progress = time.monotonic()

    def advanced(self) -> bool:
        """Did the child use CPU or log anything since the last call? New start-up steps in its
        log are shown."""
        ticks = cpu_ticks(self.child.process.pid)
        size = self.child.stderr_path.stat().st_size if self.child.stderr_path.exists() else 0
        moved = ticks != self.cpu_ticks or size != self.log_bytes
        if size > self.log_bytes:
            with open(self.child.stderr_path, "rb") as file:
                file.seek(self.log_bytes)
                for line in file.read(size - self.log_bytes).decode(errors="replace").splitlines():
                    if PROGRESS_PHRASE in line:
                        log.info("%s: %s", self.child.name,
                                 line[line.index(PROGRESS_PHRASE):])
        self.cpu_ticks, self.log_bytes = ticks, size
        if moved:
            self.last_progress = time.monotonic()
        return moved


def cpu_ticks(pid: int) -> int:
    """CPU time a process has used (user + system, in clock ticks; Linux /proc), -1 if gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return -1
    return int(fields[11]) + int(fields[12])


def wait_for_startup(starting: dict[Child, str], observed: Observed, silence_s: float,
                     stop: threading.Event, pipeline: Pipeline) -> Child | None:
    """Wait until every child in ``starting`` has declared its liveliness token, as long as each
    keeps making progress; the first child silent for ``silence_s`` (None: all came up, or a
    stop signal or a failed child ended the wait)."""
    progress = {child: StartupProgress(child) for child in starting}
    while not stop.is_set() and pipeline.failed() is None:
        waiting = [child for child, token in starting.items() if not observed.has_alive(token)]
        if not waiting:
            return None
        for child in waiting:
            watch = progress[child]
            if not watch.advanced() and time.monotonic() - watch.last_progress > silence_s:
                return child
        time.sleep(0.1)
    return None


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


def ros2_arguments(args: argparse.Namespace) -> list[str]:
    """The ROS 2 bridge's command line under ``run --ros2``: results out, no camera input."""
    return ["--cam", args.cam, "--no-input", "--ros2-connect", args.ros2,
            "--router-wait", str(args.startup_timeout)]


def logger_arguments(args: argparse.Namespace, rrd_path: Path | None,
                     mcap_path: Path | None = None) -> list[str]:
    """Where the logger writes and serves (the run reserved its paths: ``--overwrite``)."""
    arguments = ["--overwrite"]
    if mcap_path is not None:
        arguments += ["--mcap", str(mcap_path)]
    if args.connect:
        return [*arguments, "--connect", *(["--url", args.url] if args.url else [])]
    if args.foxglove:
        arguments += ["--foxglove", "--bind", args.bind]
    if args.serve:
        return [*arguments, "--serve", "--keep-running", "--bind", args.bind, "--grpc-port",
                str(args.grpc_port), "--web-port", str(args.web_port)]
    return [*arguments, "--save", str(rrd_path)]  # (the run reserved its paths: --overwrite)


def learned_nothing(outcome: RunOutcome) -> bool:
    """Whether the stream ended without the learner learning a single frame (issue 24.6: depth
    in the wrong unit leaves every cloud empty)."""
    return (outcome.end is not None and outcome.status is None and outcome.failure is None
            and not outcome.interrupted)


@dataclass
class RunOutcome:
    """How a run went: what the run's own router heard, and which service failed."""

    status: LearnerStatusInfo | None
    end: StreamEndInfo | None
    early_end: str
    failure: Child | None
    interrupted: bool


def run_pipeline(args: argparse.Namespace, plan: RunPlan, log_dir: Path) -> RunOutcome:
    """The run's router and services, supervised to the end (`supervise`). Raises
    ZenohSetupError when the router cannot start, StartupTimeout when the services do not."""
    access = RunAccess(f"tcp/127.0.0.1:{free_tcp_port()}", log_dir)
    router = open_config(access.router(), what="router")
    observed = Observed()
    declared = [
        router.liveliness().declare_subscriber(ALL_KEYS, observed.on_liveliness, history=True),
        router.declare_subscriber(topic(args.cam, "learner/status"), observed.on_status),
        router.declare_subscriber(topic(args.cam, "eos"), observed.on_eos),
    ]
    pipeline = Pipeline(access, log_dir, args.log_level)
    try:
        with lifecycle.graceful() as stop:
            early_end = supervise(args, pipeline, observed, stop, plan.rrd_path,
                                  plan.veil_ratio, plan.mcap_path)
        failure = pipeline.failed()
    finally:
        pipeline.close()
        for entity in declared:
            entity.undeclare()
        router.close()
        access.forget()
    with observed.lock:
        status, end = observed.status, observed.end
    if stop.is_set():
        early_end = early_end or f"interrupted ({lifecycle.stop_reason()})"
    return RunOutcome(status, end, early_end, failure, stop.is_set())


def report(args: argparse.Namespace, plan: RunPlan, outcome: RunOutcome) -> None:
    """Print the run's summary (and a failed service's last words)."""
    outputs = [f"  in the .rrd:      {plan.rates.describe()}"]
    if plan.rrd_path is not None:
        outputs[0:0] = [f"  .rrd size:        {file_size(plan.rrd_path)}"]
    if plan.mcap_path is not None:
        outputs.append(f"mcap:               {plan.mcap_path} ({file_size(plan.mcap_path)}; "
                       "every stream, for Foxglove)")
    failure = outcome.failure
    try:  # after a SIGHUP the terminal may be gone: nothing more to say then
        print(format_summary(outcome.status, outcome.end, plan.destination,
                             recorded_frames(args.recording), outcome.early_end, outputs,
                             plan.profile.model_value("max_nodes"), plan.mode),
              flush=True)
        if failure is not None:
            print(f"\n{failure.name} failed (exit {failure.process.returncode}):\n"
                  f"{failure.stderr_tail()}", file=sys.stderr)
    except OSError:
        pass


def main(args: argparse.Namespace) -> int:
    from gngdt.io.mcap.reader import RecordingError

    try:
        plan = plan_run(args)
    except (RecordingError, ValueError, OSError) as error:
        log.error("%s", error)
        return 2
    remove_stale_credentials()  # of runs killed before they could
    log_dir = Path(tempfile.mkdtemp(prefix=RUN_FOLDER_PREFIX))  # 0700: the run's passwords
    try:
        outcome = run_pipeline(args, plan, log_dir)
    except (ZenohSetupError, StartupTimeout) as error:
        if isinstance(error, ZenohSetupError):
            log.error("%s", error)
        return 1
    finally:
        drop_unwritten(plan)
    report(args, plan, outcome)
    if outcome.failure is not None:
        failure = outcome.failure
        return 2 if failure.name == "capture" and failure.process.returncode == 2 else 1
    shutil.rmtree(log_dir, ignore_errors=True)
    if outcome.interrupted:
        return 130
    if learned_nothing(outcome):
        log.error("the learner learned nothing: no frame's cloud had a point it could learn "
                  "(depth in another unit than millimetres? `gngdt record images` prints the "
                  "depth range it found)")
        return 1
    if mostly_rejected(outcome.status):
        log.error("most frames were not learned: their camera poses are out of bounds or "
                  "contradict their depth (see 'poses rejected' above; `gngdt record images "
                  "--poses` names the usual misreadings of a pose file)")
        return 1
    return 1 if outcome.early_end else 0


class StartupTimeout(Exception):
    """The learner and the logger did not come up in time."""


def supervise(args: argparse.Namespace, pipeline: Pipeline, observed: Observed,
              stop: threading.Event, rrd_path: Path | None,
              veil_ratio: float | None = None, mcap_path: Path | None = None) -> str:
    """Start the services and see the stream through; why it ended early, or ``""``."""
    log.info("starting the learner and the logger (the first run on a machine compiles the "
             "learning kernels: 15-40 s, longer on a busy machine; later runs take seconds)")
    learner = pipeline.start("learn", ["--cam", args.cam, "--exit-on-eos"],
                             child_settings(args, "learn"))
    logger = pipeline.start("log", logger_arguments(args, rrd_path, mcap_path),
                            child_settings(args, "log"))
    starting = {learner: alive_key(args.cam, LEARNER), logger: LOGGER_ALIVE}
    if args.ros2:  # the results into ROS 2 as well (see `gngdt ros2`)
        bridge = pipeline.start("ros2", ros2_arguments(args))
        starting[bridge] = alive_key(args.cam, BRIDGE)
    silent = wait_for_startup(starting, observed, args.startup_timeout, stop, pipeline)
    ready = not silent and not stop.is_set() and pipeline.failed() is None
    early_end, stream_ended = "", False
    if silent:
        log.error("the %s shows no progress: no CPU time used and nothing logged for %.0f s "
                  "while starting (a hung process?); its log: %s", silent.name,
                  args.startup_timeout, silent.stderr_path)
        pipeline.interrupt_all()
        for child in pipeline.children:
            child.stop(args.drain_timeout)
        raise StartupTimeout
    if ready:
        log.info("replaying %s", args.recording)
        capture = pipeline.start("capture", [str(args.recording), "--cam", args.cam],
                                 child_settings(args, "capture", veil_ratio))
        wait_until(lambda: capture.process.poll() is not None
                   or learner.process.poll() is not None or logger.process.poll() is not None,
                   float("inf"), stop, pipeline)
        with observed.lock:
            stream_ended = observed.end is not None  # only this run's capture can send it
        if (capture.process.poll() is None and not stream_ended and not stop.is_set()
                and pipeline.failed() is None):
            quitter = learner if learner.process.poll() is not None else logger
            early_end = (f"the {'learner' if quitter is learner else 'logger'} stopped while "
                         "capture was still replaying")
    failure = pipeline.failed()  # a capture that failed after its end of stream (a camera lost)
    lost = failure is not None and failure.name == "capture" and stream_ended  # lets them finish
    if stop.is_set() or (failure is not None and not lost) or early_end:
        log.info("%s; stopping the services",
                 "interrupted" if stop.is_set() else early_end or "a service failed")
        pipeline.interrupt_all()
    for child in pipeline.children:
        if child.name == "ros2":  # bridges until told to stop: once the others are done
            child.interrupt()
        child.stop(args.drain_timeout)
    return early_end
