"""Soak: the whole pipeline on a looped replay at 30 fps for ``--minutes``; prints each service's
RSS over time (and its slope), dropped frames and latency percentiles at start and end.

    python benchmarks/bench_soak.py --minutes 10
    python benchmarks/bench_soak.py --minutes 3 --width 640 --height 480 --save-rrd
    python benchmarks/bench_soak.py --minutes 5 --recording real.mcap --save-rrd --mcap

Processes: ``gngdt router``, ``learn``, ``log`` (``--stdout`` into /dev/null by default, so a
long soak does not fill the disk; ``--save-rrd`` writes a real .rrd in a temporary directory
instead, and reports its growth in MB per minute; ``--mcap`` also records every stream into an
MCAP file) and ``capture --loop`` at the recorded 30 fps (a synthetic tabletop, or
``--recording``). Not a test: it prints figures.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]

from procstat import status_mb, wait_until  # noqa: E402  (benchmarks/, beside this script)

from gngdt.io.deproject import RUN_POINT_CAP as DEFAULT_MAX_POINTS  # noqa: E402
from gngdt.schemas.status import LearnerStatusInfo, decode_status  # noqa: E402
from gngdt.services.plumbing.session import client_config, free_tcp_port, open_config  # noqa: E402


@dataclass
class StatusLog:
    """Learner status messages with their arrival time (seconds since the soak began)."""

    started: float = field(default_factory=time.monotonic)
    entries: list[tuple[float, LearnerStatusInfo]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, sample) -> None:
        status = decode_status(sample.payload.to_bytes())
        with self.lock:
            self.entries.append((time.monotonic() - self.started, status))

    def window(self, start_s: float, end_s: float) -> list[LearnerStatusInfo]:
        with self.lock:
            return [status for at, status in self.entries if start_s <= at < end_s]


def make_recording(directory: Path, width: int, height: int, frames: int) -> Path:
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = directory / "soak.mcap"
    with RecordingWriter(path) as writer:
        for frame in render_scene("tabletop", frames, width=width, height=height, fps=30.0):
            writer.write_frame(frame)
    return path


def start(arguments: list[str], log_path: Path, stdout=None) -> subprocess.Popen:
    with open(log_path, "wb") as log_file:
        return subprocess.Popen(
            [sys.executable, "-m", "gngdt.services.cli", *arguments], cwd=REPO_ROOT,
            stdout=stdout if stdout is not None else log_file, stderr=log_file,
            stdin=subprocess.DEVNULL, start_new_session=True)


def slope_mb_per_min(samples: list[tuple[float, float]]) -> float:
    """Least-squares slope of (seconds, MB) samples, MB per minute."""
    if len(samples) < 2:
        return 0.0
    seconds, megabytes = np.array(samples).T
    return float(np.polyfit(seconds / 60.0, megabytes, 1)[0])


def latency_line(label: str, statuses: list[LearnerStatusInfo]) -> str:
    if not statuses:
        return f"  {label}: no status"
    latencies = np.array([status.latency_ms for status in statuses])
    p50, p90, p99 = np.percentile(latencies, [50, 90, 99])
    return (f"  {label}: {len(statuses)} topologies, latency p50 {p50:.0f} ms, "
            f"p90 {p90:.0f} ms, p99 {p99:.0f} ms, max {latencies.max():.0f} ms")


@dataclass
class Samples:
    """What the soak sampled, each series (seconds since it began, MB)."""

    #: resident set per process
    rss: dict[str, list[tuple[float, float]]]
    #: the logger's output files ("rrd", "mcap"), whether or not they were written
    files: dict[str, Path]
    #: size per output file, once it exists
    sizes: dict[str, list[tuple[float, float]]]


def parse_args() -> argparse.Namespace:
    """The soak's options (see the module's docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--frames", type=int, default=60, help="frames in the looped recording")
    parser.add_argument("--samples-per-frame", type=int, default=5000)
    parser.add_argument("--max-points", type=int, default=DEFAULT_MAX_POINTS,
                        help="capture's point cap, as `gngdt run` (default %(default)s; 0: all)")
    parser.add_argument("--sample-every", type=float, default=10.0, metavar="SECONDS")
    parser.add_argument("--save-rrd", action="store_true",
                        help="the logger writes a .rrd (default: --stdout to /dev/null)")
    parser.add_argument("--mcap", action="store_true",
                        help="the logger also records every stream into an MCAP file")
    parser.add_argument("--recording", type=Path,
                        help="loop this recording instead of a synthetic tabletop")
    parser.add_argument("--logger-args", default="",
                        help="extra `gngdt log` options, e.g. \"--keep-everything\"")
    return parser.parse_args()


def start_services(args: argparse.Namespace, work: Path, endpoint: str,
                   processes: dict[str, subprocess.Popen], devnull) -> None:
    """Start the router, learner and logger into ``processes`` (each added as it starts, so
    the caller can stop whichever are up if one fails)."""
    connect = ["--zenoh-connect", endpoint]
    processes["router"] = start(["router", "--listen", endpoint], work / "router.log")
    wait_until(lambda: "listening on" in (work / "router.log").read_text(), 60, "the router")
    processes["learn"] = start(["learn", "--samples-per-frame", str(args.samples_per_frame),
                                *connect], work / "learn.log")
    viewer = ["--save", str(work / "soak.rrd")] if args.save_rrd else ["--stdout"]
    viewer += ["--mcap", str(work / "soak-log.mcap")] if args.mcap else []
    viewer += args.logger_args.split()
    processes["log"] = start(["log", *viewer, "--keep-running", *connect], work / "log.log",
                             stdout=None if args.save_rrd else devnull)


def sample_processes(processes: dict[str, subprocess.Popen], started: float, duration: float,
                     sample_every: float, work: Path) -> Samples:
    """Every ``sample_every`` s until ``duration`` s after ``started``: each process's RSS and
    each output file's size; then a last RSS of each. A process exiting ends the soak."""
    rss: dict[str, list[tuple[float, float]]] = {name: [] for name in processes}
    files = {"rrd": work / "soak.rrd", "mcap": work / "soak-log.mcap"}
    sizes: dict[str, list[tuple[float, float]]] = {name: [] for name in files}
    while (elapsed := time.monotonic() - started) < duration:
        for name, process in processes.items():
            if process.poll() is not None:
                raise SystemExit(f"{name} exited with {process.returncode}; see {work}")
            rss[name].append((elapsed, status_mb(process.pid, "VmRSS")))
        for name, path in files.items():
            if path.exists():
                sizes[name].append((elapsed, path.stat().st_size / 1e6))
        time.sleep(min(sample_every, max(0.0, duration - elapsed)))
    for name, process in processes.items():
        rss[name].append((time.monotonic() - started, status_mb(process.pid, "VmRSS")))
    return Samples(rss, files, sizes)


def stop_processes(processes: dict[str, subprocess.Popen]) -> None:
    """SIGINT every process still running; SIGKILL any not gone 30 s later."""
    for process in processes.values():
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGINT)
    for process in processes.values():
        try:
            process.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)


def soak(args: argparse.Namespace, work: Path, recording: Path) -> tuple[StatusLog, Samples]:
    """Run the pipeline on ``recording`` looped for ``args.minutes``, sampling as it goes; every
    process is stopped however the soak ends."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    connect = ["--zenoh-connect", endpoint]
    processes: dict[str, subprocess.Popen] = {}
    devnull = open(os.devnull, "wb")
    try:
        start_services(args, work, endpoint, processes, devnull)
        session = open_config(client_config([endpoint]))
        statuses = StatusLog()
        session.declare_subscriber("gngdt/camera/learner/status", statuses.add)
        time.sleep(5.0)  # learner warm-up (numba)
        statuses.started = time.monotonic()
        processes["capture"] = start(["capture", str(recording), "--loop", "--realtime",
                                      "--max-points", str(args.max_points), *connect],
                                     work / "capture.log")
        samples = sample_processes(processes, statuses.started, args.minutes * 60.0,
                                   args.sample_every, work)
        session.close()
    finally:
        stop_processes(processes)
        devnull.close()
    return statuses, samples


def print_memory(samples: Samples) -> None:
    """Print each output file's growth and each process's RSS over time, with their slopes
    after the first minute."""
    for name, series in samples.sizes.items():
        if series:
            steady = [sample for sample in series if sample[0] >= 60.0] or series
            print(f".{name}: {samples.files[name].stat().st_size / 1e6:.1f} MB at the end, "
                  f"growing {slope_mb_per_min(steady):.1f} MB/min after the first minute")
    print("RSS (MB) over time; slope fitted after the first minute:")
    for name, series in samples.rss.items():
        steady = [sample for sample in series if sample[0] >= 60.0] or series
        shown = ", ".join(f"{at / 60:.1f}m {mb:.0f}" for at, mb in series[:: max(
            1, len(series) // 8)])
        print(f"  {name:8s} start {series[0][1]:6.0f}  end {series[-1][1]:6.0f}  "
              f"slope {slope_mb_per_min(steady):+.2f} MB/min   [{shown}]")


def print_latency_and_frames(statuses: StatusLog, duration: float) -> None:
    """Print latency percentiles over the first and last minute, then the learner's last
    frame counts and the capture rate."""
    minute = min(60.0, duration / 3)
    first, last = statuses.window(0, minute), statuses.window(duration - minute, duration + 1)
    print(f"latency (capture -> topology published), first and last {minute:.0f} s:")
    print(latency_line("start", first))
    print(latency_line("end  ", last))
    with statuses.lock:
        final = statuses.entries[-1][1] if statuses.entries else None
    if final is not None:
        sent = final.frame_sequence + 1
        print(f"frames: ~{sent} sent, {final.frames_received} received by the learner, "
              f"{final.frames_used} learned, {final.frames_dropped} dropped (latest-wins), "
              f"{final.malformed_messages} malformed; {final.nodes} nodes, "
              f"{final.steps_per_second:,.0f} steps/s")
        capture_rate = sent / duration
        print(f"capture rate: {capture_rate:.1f} frames/s (target 30)")


def print_report(args: argparse.Namespace, work: Path, statuses: StatusLog,
                 samples: Samples) -> None:
    """Print the soak's set-up, memory over time, latency and frame counts."""
    source = (str(args.recording) if args.recording
              else f"{args.width}x{args.height} tabletop ({args.frames} frames)")
    print(f"soak: {args.minutes:g} min, {source} looped at 30 fps, {args.samples_per_frame} "
          f"steps/frame, logger {'to .rrd' if args.save_rrd else 'to --stdout > /dev/null'}"
          f"{' + MCAP' if args.mcap else ''} {args.logger_args}; logs in {work}")
    print_memory(samples)
    print_latency_and_frames(statuses, args.minutes * 60.0)


def main() -> int:
    args = parse_args()
    work = Path(tempfile.mkdtemp(prefix="gngdt-soak-"))
    recording = args.recording or make_recording(work, args.width, args.height, args.frames)
    statuses, samples = soak(args, work, recording)
    print_report(args, work, statuses, samples)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
