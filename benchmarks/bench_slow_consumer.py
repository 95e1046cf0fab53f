"""Back-pressure: what one subscriber that never reads does to the pipeline, and how long the
pipeline takes to recover from a router restart.

    python benchmarks/bench_slow_consumer.py --seconds 20

Processes: ``gngdt router``, ``learn``, ``log`` (writing a .rrd: the other, well-behaved
subscriber) and ``capture --loop`` at the recorded 30 fps (640x480, clouds capped at 50,000 points
as ``gngdt run`` does). Three phases of ``--seconds`` each: baseline; with a hostile client
subscribed to ``gngdt/**`` whose callback never returns (a consumer that never reads); baseline
again after it left. Per phase: frames published by capture and learned by the learner (per
second), frames the logger received (from its .rrd growth) and latency percentiles. Then the
router is killed and restarted: the time until the first topology of a new frame. Not a test:
it prints figures (the machine may be shared: compare phases of one run, not runs).
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from procstat import gngdt

from gngdt.io.deproject import RUN_POINT_CAP as DEFAULT_MAX_POINTS
from gngdt.schemas.status import decode_status
from gngdt.schemas.topology import decode_topology
from gngdt.services.plumbing.session import client_config, free_tcp_port, open_config

#: a client of the router subscribed to everything, whose callback never returns
NEVER_READS = """
import time
from gngdt.schemas.wire import ALL_KEYS
from gngdt.services.plumbing.session import client_config, open_config
session = open_config(client_config([{endpoint!r}]), wait_s=30)
session.declare_subscriber(ALL_KEYS, lambda sample: time.sleep(3600))
print("subscribed", flush=True)
time.sleep(3600)
"""


@dataclass
class Observer:
    """A well-behaved client: counts clouds and topologies, keeps statuses, with arrival times."""

    endpoint: str
    lock: threading.Lock = field(default_factory=threading.Lock)
    clouds: list[float] = field(default_factory=list)
    topologies: list[tuple[float, int]] = field(default_factory=list)
    statuses: list[tuple[float, object]] = field(default_factory=list)

    def start(self) -> None:
        self.session = open_config(client_config([self.endpoint]), wait_s=30)
        self.session.declare_subscriber("gngdt/camera/points", self._cloud)
        self.session.declare_subscriber("gngdt/camera/topology", self._topology)
        self.session.declare_subscriber("gngdt/camera/learner/status", self._status)

    def _cloud(self, sample) -> None:
        with self.lock:
            self.clouds.append(time.monotonic())

    def _topology(self, sample) -> None:
        sequence = decode_topology(sample.payload.to_bytes()).frame_sequence
        with self.lock:
            self.topologies.append((time.monotonic(), sequence))

    def _status(self, sample) -> None:
        status = decode_status(sample.payload.to_bytes())
        with self.lock:
            self.statuses.append((time.monotonic(), status))

    def window(self, start: float, end: float) -> dict:
        with self.lock:
            clouds = sum(1 for at in self.clouds if start <= at < end)
            learned = [status for at, status in self.statuses if start <= at < end]
        seconds = end - start
        latencies = np.array([status.latency_ms for status in learned] or [np.nan])
        return {
            "clouds_per_s": clouds / seconds,
            "learned_per_s": len(learned) / seconds,
            "p50_ms": float(np.percentile(latencies, 50)),
            "p99_ms": float(np.percentile(latencies, 99)),
        }


def make_recording(directory: Path) -> Path:
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = directory / "loop.mcap"
    with RecordingWriter(path) as writer:
        for frame in render_scene("tabletop", 30, width=640, height=480):
            writer.write_frame(frame)
    return path


def wait_until(condition, timeout_s: float, what: str) -> float:
    started = time.monotonic()
    while time.monotonic() - started < timeout_s:
        if condition():
            return time.monotonic() - started
        time.sleep(0.02)
    raise SystemExit(f"timed out waiting for {what}")


def accepts(port: int) -> bool:
    import socket

    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) == 0


def phase(observer: Observer, rrd: Path, seconds: float, name: str) -> None:
    size_before, started = rrd.stat().st_size, time.monotonic()
    time.sleep(seconds)
    figures = observer.window(started, time.monotonic())
    rrd_mb_s = (rrd.stat().st_size - size_before) / 1e6 / (time.monotonic() - started)
    print(f"{name:<32} clouds {figures['clouds_per_s']:5.1f}/s  learned "
          f"{figures['learned_per_s']:5.1f}/s  latency p50 {figures['p50_ms']:6.1f} ms "
          f"p99 {figures['p99_ms']:7.1f} ms  logger writes {rrd_mb_s:5.2f} MB/s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="length of each phase")
    args = parser.parse_args()

    folder = Path(tempfile.mkdtemp(prefix="bench-slow-"))
    recording = make_recording(folder)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    connect = ("--zenoh-connect", endpoint)
    rrd = folder / "logger.rrd"
    processes = {"router": gngdt("router", "--listen", endpoint, log=folder / "router.log")}
    processes["learn"] = gngdt("learn", *connect, log=folder / "learn.log")
    processes["log"] = gngdt("log", "--save", str(rrd), "--keep-running", *connect,
                             log=folder / "log.log")
    observer = Observer(endpoint)
    observer.start()
    wait_until(lambda: "learning from" in (folder / "learn.log").read_text(), 120, "the learner")
    processes["capture"] = gngdt("capture", str(recording), "--loop", "--realtime",
                                 "--max-points",
                                 str(DEFAULT_MAX_POINTS), *connect, log=folder / "capture.log")
    hostile = None
    try:
        wait_until(lambda: len(observer.statuses) > 30, 120, "learned frames")
        phase(observer, rrd, args.seconds, "baseline")
        hostile = subprocess.Popen(
            [sys.executable, "-c", NEVER_READS.format(endpoint=endpoint)],
            stdout=subprocess.PIPE, start_new_session=True)
        assert hostile.stdout.readline().startswith(b"subscribed")
        phase(observer, rrd, args.seconds, "a subscriber that never reads")
        hostile.kill()
        hostile.wait()
        hostile = None
        phase(observer, rrd, args.seconds, "after it left")

        processes["router"].send_signal(signal.SIGKILL)
        processes["router"].wait()
        time.sleep(2.0)  # every client noticed
        with observer.lock:
            last = max(sequence for _, sequence in observer.topologies)
        restarted = time.monotonic()
        processes["router"] = gngdt("router", "--listen", endpoint, log=folder / "router2.log")
        port = int(endpoint.rsplit(":", 1)[1])
        listening = wait_until(lambda: accepts(port), 60, "the new router")
        accepted = time.monotonic()

        def new_topology() -> bool:
            with observer.lock:
                return any(at > restarted and sequence > last
                           for at, sequence in observer.topologies)

        wait_until(new_topology, 60, "a topology after the restart")
        with observer.lock:
            first = min(at for at, sequence in observer.topologies
                        if at > restarted and sequence > last)
        print(f"router restart: the new router accepted connections {listening:.2f} s after it "
              f"was started (Python and zenoh starting); the first topology of a new frame came "
              f"{first - accepted:.2f} s after that", flush=True)
    finally:
        if hostile is not None:
            hostile.kill()
        observer.session.close()
        for process in processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for name, process in processes.items():
            try:
                process.wait(30)
            except subprocess.TimeoutExpired:
                process.kill()
                print(f"{name} did not stop on SIGINT", flush=True)
    print(f"logs: {folder}")


if __name__ == "__main__":
    main()
