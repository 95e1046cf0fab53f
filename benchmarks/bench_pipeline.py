"""End-to-end pipeline figures: real-time replay, frame-to-topology latency, CPU and peak RSS per
process, with shared memory and over the network.

    python benchmarks/bench_pipeline.py [--frames 90] [--samples-per-frame 10000]
                                        [--max-points N] [--recording X]
                                        [--transports network,shm] [--repeat N] [--pipeline-only]
    python benchmarks/bench_pipeline.py --max-points 0      # full clouds, network vs shm

Renders (or takes) a 640x480 recording, replays it at its recorded 30 fps through capture ->
learner -> logger (writing a .rrd), clients of a `gngdt router` process on loopback, once per
transport (``pipeline_runs.TRANSPORTS``: ``network`` = shared memory off everywhere, the
baseline; ``shm`` = gngdt's default), and prints per run: frames sent / learned / dropped,
latency p50/p99 (capture -> topology, the learner's publish time and a subscriber's receive
time), CPU of each process while capture streams, how many payloads went through shared memory,
peak RSS. Baselines in the same run: deprojection as a per-pixel Python loop vs the vectorised
ray map, and a learner that queues every frame (FIFO) vs latest-frame-wins, replayed against the
learning times measured here.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pipeline_runs import (
    TRANSPORTS,
    BenchPipeline,
    Transport,
    load_average,
    percentiles,
    shared_memory_use,
)

from gngdt.schemas.wire import DEFAULT_CAMERA, LEARNER, LOGGER_ALIVE, alive_key


def render_recording(path: Path, frames: int) -> None:
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    with RecordingWriter(path, compression="lz4") as writer:
        for frame in render_scene("tabletop", frames, width=640, height=480):
            writer.write_frame(frame)


def deprojection_baseline(frame) -> tuple[float, float]:
    """(vectorised ms, Python-loop ms scaled to the full frame) for one frame."""
    from gngdt.io.deproject import Deprojector

    deproject = Deprojector()
    deproject(frame.depth, frame.color, frame.intrinsics)
    started = time.perf_counter()
    repeats = 20
    for _ in range(repeats):
        deproject(frame.depth, frame.color, frame.intrinsics)
    vectorised_ms = (time.perf_counter() - started) / repeats * 1e3

    k = frame.intrinsics
    rows = frame.depth.shape[0] // 8  # one eighth of the rows, scaled up
    started = time.perf_counter()
    points = []
    for v in range(rows):
        for u in range(frame.depth.shape[1]):
            z = frame.depth[v, u] * 0.001
            if 0.1 <= z <= 10.0:
                points.append(((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z,
                               *frame.color[v, u]))
    loop_ms = (time.perf_counter() - started) * 1e3 * frame.depth.shape[0] / rows
    return vectorised_ms, loop_ms


def queueing_baseline(recording: Path, samples_per_frame: int, fps: float) -> dict[str, float]:
    """Latency of FIFO vs latest-frame-wins, replaying measured learning times at ``fps``."""
    from gngdt.core import GNGDT
    from gngdt.io.mcap.reader import read_frames
    from gngdt.services.capture import CloudOptions, FrameToCloud

    to_cloud = FrameToCloud(CloudOptions())
    model = GNGDT(random_state=0)
    learn_seconds, cloud_bytes = [], 0
    for frame in read_frames(recording):
        positions, colors = to_cloud(frame)
        cloud_bytes = positions.nbytes + colors.nbytes
        started = time.perf_counter()
        model.partial_fit(positions, colors, n_steps=samples_per_frame)
        learn_seconds.append(time.perf_counter() - started)
    learn_seconds = learn_seconds[1:] * 2  # drop the JIT-warm-up frame; a longer stream
    arrivals = np.arange(len(learn_seconds)) / fps

    fifo_latency, finish = [], 0.0
    for arrival, cost in zip(arrivals, learn_seconds, strict=True):
        finish = max(finish, arrival) + cost
        fifo_latency.append(finish - arrival)
    queued_max = int(max(np.searchsorted(arrivals, arrivals + np.array(fifo_latency)) -
                         np.arange(len(arrivals))))

    latest_latency, clock, index, used = [], 0.0, 0, 0
    while index < len(arrivals):
        clock = max(clock, arrivals[index])
        newest = int(np.searchsorted(arrivals, clock, side="right")) - 1
        clock += learn_seconds[newest]
        latest_latency.append(clock - arrivals[newest])
        used += 1
        index = newest + 1
    return {
        "learn_ms_mean": float(np.mean(learn_seconds)) * 1e3,
        "fifo_p50": float(np.percentile(fifo_latency, 50)) * 1e3,
        "fifo_p99": float(np.percentile(fifo_latency, 99)) * 1e3,
        "fifo_queue_mb": queued_max * cloud_bytes / 1e6,
        "latest_p50": float(np.percentile(latest_latency, 50)) * 1e3,
        "latest_p99": float(np.percentile(latest_latency, 99)) * 1e3,
        "latest_used": used,
        "frames": len(arrivals),
    }


@dataclass
class PipelineRun:
    """One replay through capture -> learner -> logger with one transport."""

    transport: str
    status: object
    end: object
    received_latency_ms: list[float]
    cpu_percent: dict[str, float]
    peaks_mb: dict[str, float]
    streaming_seconds: float
    shared_memory: dict[str, dict[str, tuple[int, int]]]
    load: float


def run_pipeline(recording: Path, samples_per_frame: int, workdir: Path,
                 capture_options: list[str], transport: Transport) -> PipelineRun:
    """Replay ``recording`` at its recorded rate through a router process, a learner, a logger
    writing a .rrd and a capture; CPU is measured while capture streams."""
    load = load_average()
    bench = BenchPipeline(workdir, transport)
    try:
        bench.start("learn", ["--exit-on-eos", "--samples-per-frame", str(samples_per_frame)],
                    "learner")
        bench.start("log", ["--save", str(workdir / "bench.rrd")], "logger")
        bench.wait(lambda: bench.observer.has_alive(alive_key(DEFAULT_CAMERA, LEARNER),
                                                    LOGGER_ALIVE), 120, "learner and logger")
        capture = bench.start("capture", [str(recording), *capture_options])
        window = bench.stream([capture], [DEFAULT_CAMERA])
        seen = bench.observer.camera("gngdt/camera")
        with bench.observer.lock:
            status, end, received = seen.status, seen.end, list(seen.received_latency_ms)
    finally:
        bench.close()
    use = {child.name: shared_memory_use(child.stderr_path.read_text(errors="replace"))
           for child in bench.children}
    return PipelineRun(transport.name, status, end, received, window.percent(), window.peaks,
                       window.seconds, use, load)


def print_runs(runs: list[PipelineRun]) -> None:
    """One row per run: frames, latency, CPU per process, and what went through shared
    memory."""
    print(f"{'transport':9s} {'load':>4s} {'sent':>4s} {'learned':>7s} {'dropped':>7s} "
          f"{'p50 ms':>6s} {'p99 ms':>6s} {'rx p50':>6s} {'rx p99':>6s}  "
          "CPU % of a core while streaming: capture/learner/logger/router (total)")
    for run in runs:
        status, end = run.status, run.end
        rx50, rx99 = percentiles(run.received_latency_ms)
        cpu = run.cpu_percent
        names = ("capture", "learner", "logger", "router")
        print(f"{run.transport:9s} {run.load:4.1f} {end.frames_sent if end else '?':>4} "
              f"{status.frames_used:7d} {status.frames_dropped:7d} "
              f"{status.latency_p50_ms:6.1f} {status.latency_p99_ms:6.1f} {rx50:6.1f} {rx99:6.1f}"
              f"  {'/'.join(f'{cpu.get(name, 0):.0f}' for name in names)} "
              f"({sum(cpu.values()):.0f})")
    for run in runs:
        used = [f"{name}: " + ", ".join(f"{key.rsplit('/', 1)[-1]} {shared}/{total}"
                                        for key, (shared, total) in use.items())
                for name, use in run.shared_memory.items() if use]
        sent = max(run.end.frames_sent if run.end else 0, 1)
        per_frame = ", ".join(f"{name} {percent * run.streaming_seconds * 10 / sent:.1f}"
                              for name, percent in run.cpu_percent.items())
        print(f"  {run.transport}: streamed {run.streaming_seconds:.1f} s; CPU ms per frame sent: "
              f"{per_frame}; through shared memory: {'; '.join(used) or 'nothing'}; peak RSS "
              + ", ".join(f"{name} {mb:.0f} MB" for name, mb in run.peaks_mb.items()))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90, help="frames to render (30 fps)")
    parser.add_argument("--samples-per-frame", type=int, default=10_000)
    parser.add_argument("--recording", type=Path, help="use this 640x480 recording instead")
    parser.add_argument("--max-points", type=int, help="capture's point cap per frame")
    parser.add_argument("--transports", default="network,shm",
                        help="comma-separated, run in this order: network (shared memory off: "
                        "the baseline), zenoh (zenoh's own pool only, as before gngdt's pools), "
                        "shm (gngdt's default); default network,shm")
    parser.add_argument("--repeat", type=int, default=1,
                        help="run the transports this many times, interleaved (default 1)")
    parser.add_argument("--pipeline-only", action="store_true",
                        help="skip the deprojection and queueing baselines")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    transports = [TRANSPORTS[name.strip()] for name in args.transports.split(",")]

    with tempfile.TemporaryDirectory(prefix="bench-pipeline-") as directory:
        workdir = Path(directory)
        recording = args.recording
        if recording is None:
            recording = workdir / "tabletop_640.mcap"
            started = time.perf_counter()
            render_recording(recording, args.frames)
            print(f"rendered {args.frames} frames 640x480 in {time.perf_counter() - started:.1f} s")

        from gngdt.io.mcap.reader import read_frames

        if not args.pipeline_only:
            first = next(iter(read_frames(recording)))
            vectorised_ms, loop_ms = deprojection_baseline(first)
            print(f"deprojection 640x480: vectorised {vectorised_ms:.1f} ms, "
                  f"Python loop {loop_ms:.0f} ms ({loop_ms / vectorised_ms:.0f}x)")

        capture_options = [] if args.max_points is None else ["--max-points",
                                                               str(args.max_points)]
        print(f"pipeline: capture {' '.join(capture_options) or '(full clouds)'} at the recorded "
              f"rate, learner {args.samples_per_frame} steps/frame, logger to .rrd, a `gngdt "
              f"router` process; transports {args.transports}, {args.repeat}x")
        runs = []
        for repeat in range(args.repeat):
            for transport in transports:
                runs.append(run_pipeline(recording, args.samples_per_frame,
                                         workdir / f"{transport.name}-{repeat}", capture_options,
                                         transport))
        print_runs(runs)
        print("(p50/p99: capture -> topology published, the learner's status; rx: received by "
              "a subscriber; load: the machine's 1-minute load average before the run)")
        if args.pipeline_only:
            return 0
        overloaded = args.samples_per_frame * 4
        baseline = queueing_baseline(recording, overloaded, 30.0)
        print(f"queueing baseline at {overloaded} steps/frame (learning "
              f"{baseline['learn_ms_mean']:.0f} ms/frame, {baseline['frames']} frames at 30 fps):")
        print(f"  FIFO (every frame queued): p50 {baseline['fifo_p50']:.0f} ms, "
              f"p99 {baseline['fifo_p99']:.0f} ms, queue up to {baseline['fifo_queue_mb']:.0f} MB")
        print(f"  latest-frame-wins: p50 {baseline['latest_p50']:.0f} ms, "
              f"p99 {baseline['latest_p99']:.0f} ms, {baseline['latest_used']} frames learned, "
              "one cloud buffered")
    return 0


if __name__ == "__main__":
    sys.exit(main())
