"""End-to-end pipeline figures: real-time replay, frame-to-topology latency, peak RSS per service.

    python benchmarks/bench_pipeline.py [--frames 90] [--samples-per-frame 10000]
                                        [--max-points N] [--recording X]

Renders (or takes) a 640x480 recording, replays it at its recorded 30 fps through capture ->
learner -> logger on a loopback router, and prints: frames sent / learned / dropped, learning steps
per frame, latency p50/p99 (learner's publish time and a subscriber's receive time), peak RSS of
each service. Baselines in the same run: deprojection as a per-pixel Python loop vs the
vectorised ray map, and a learner that queues every frame (FIFO) vs latest-frame-wins, replayed
against the learning times measured here.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from procstat import cpu_seconds, status_mb

from schemas.wire import FrameStamp, topic
from services.logger import LIVELINESS_KEY
from services.plumbing.session import free_tcp_port, open_config, router_config
from services.run import Observed, Pipeline, wait_until


def render_recording(path: Path, frames: int) -> None:
    from gngdt_io.mcap_writer import RecordingWriter
    from gngdt_io.synth.render import render_scene

    with RecordingWriter(path, compression="lz4") as writer:
        for frame in render_scene("tabletop", frames, width=640, height=480):
            writer.write_frame(frame)


def deprojection_baseline(frame) -> tuple[float, float]:
    """(vectorised ms, Python-loop ms scaled to the full frame) for one frame."""
    from gngdt_io.deproject import Deprojector

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
    from gngdt_core import GNGDT
    from gngdt_io.mcap_reader import read_frames
    from services.capture import CloudOptions, FrameToCloud

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


def run_pipeline(
    recording: Path, samples_per_frame: int, workdir: Path, capture_options: list[str]
) -> dict[str, object]:
    from schemas.topology import decode_topology

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_config(router_config([endpoint]), what="router")
    observed = Observed()
    received_latency_ms: list[float] = []
    lock = threading.Lock()

    def on_topology(sample) -> None:
        stamp = FrameStamp.from_attachment(sample.attachment.to_bytes())
        latency = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        decode_topology(sample.payload.to_bytes())
        with lock:
            received_latency_ms.append(latency)

    declared = [
        router.liveliness().declare_subscriber("gngdt/**", observed.on_liveliness, history=True),
        router.declare_subscriber(topic("camera", "learner/status"), observed.on_status),
        router.declare_subscriber(topic("camera", "eos"), observed.on_eos),
        router.declare_subscriber(topic("camera", "topology"), on_topology),
    ]
    pipeline = Pipeline(endpoint, workdir, "WARNING")
    stop = threading.Event()
    peaks: dict[str, float] = {}
    cpu: dict[str, float] = {}
    try:
        learner = pipeline.start("learn", ["--exit-on-eos", "--samples-per-frame",
                                           str(samples_per_frame)])
        logger = pipeline.start("log", ["--save", str(workdir / "bench.rrd")])
        wait_until(lambda: observed.has_alive("gngdt/camera/learner/alive")
                   and observed.has_alive(LIVELINESS_KEY), 120, stop, pipeline)
        capture = pipeline.start("capture", [str(recording), *capture_options])
        started = time.monotonic()
        children = {"capture": capture, "learner": learner, "logger": logger}
        streaming_seconds = 0.0
        while any(child.process.poll() is None for child in children.values()):
            if capture.process.poll() is None:
                streaming_seconds = time.monotonic() - started
            for name, child in children.items():
                peaks[name] = max(peaks.get(name, 0.0), status_mb(child.process.pid, "VmHWM"))
                cpu[name] = max(cpu.get(name, 0.0), cpu_seconds(child.process.pid))
            time.sleep(0.1)
            if time.monotonic() - started > 600:
                break
        failed = pipeline.failed()
        if failed is not None:
            raise RuntimeError(f"{failed.name} failed:\n{failed.stderr_tail()}")
    finally:
        pipeline.interrupt_all()
        pipeline.close()
        for entity in declared:
            entity.undeclare()
        router.close()
    return {"status": observed.status, "end": observed.end, "peaks": peaks, "cpu": cpu,
            "streaming_seconds": streaming_seconds,
            "received_latency_ms": received_latency_ms}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90, help="frames to render (30 fps)")
    parser.add_argument("--samples-per-frame", type=int, default=10_000)
    parser.add_argument("--recording", type=Path, help="use this 640x480 recording instead")
    parser.add_argument("--max-points", type=int, help="capture's point cap per frame")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)

    with tempfile.TemporaryDirectory(prefix="bench-pipeline-") as directory:
        workdir = Path(directory)
        recording = args.recording
        if recording is None:
            recording = workdir / "tabletop_640.mcap"
            started = time.perf_counter()
            render_recording(recording, args.frames)
            print(f"rendered {args.frames} frames 640x480 in {time.perf_counter() - started:.1f} s")

        from gngdt_io.mcap_reader import read_frames

        first = next(iter(read_frames(recording)))
        vectorised_ms, loop_ms = deprojection_baseline(first)
        print(f"deprojection 640x480: vectorised {vectorised_ms:.1f} ms, "
              f"Python loop {loop_ms:.0f} ms ({loop_ms / vectorised_ms:.0f}x)")

        capture_options = [] if args.max_points is None else ["--max-points",
                                                               str(args.max_points)]
        print(f"pipeline: capture {' '.join(capture_options) or '(full clouds)'}, "
              f"learner {args.samples_per_frame} steps/frame, logger to .rrd")
        result = run_pipeline(recording, args.samples_per_frame, workdir, capture_options)
        status, end = result["status"], result["end"]
        received = np.array(result["received_latency_ms"])
        print(f"frames sent {end.frames_sent if end else '?'}, learned {status.frames_used}, "
              f"dropped {status.frames_dropped}, malformed {status.malformed_messages}")
        print(f"learning: {status.steps / max(status.frames_used, 1):,.0f} steps/frame, "
              f"{status.steps_per_second:,.0f} steps/s, {status.nodes} nodes")
        print(f"latency capture->topology published: p50 {status.latency_p50_ms:.1f} ms, "
              f"p99 {status.latency_p99_ms:.1f} ms (target p99 < 100 ms)")
        if received.size:
            print(f"latency capture->topology received by a subscriber: "
                  f"p50 {np.percentile(received, 50):.1f} ms, "
                  f"p99 {np.percentile(received, 99):.1f} ms")
        print("peak RSS: " + ", ".join(f"{name} {mb:.0f} MB"
                                       for name, mb in result["peaks"].items())
              + " (target learner < 500 MB)")
        stream_seconds = result["streaming_seconds"]
        print(f"CPU seconds per service incl. start-up, stream {stream_seconds:.1f} s: "
              + ", ".join(f"{name} {seconds:.1f}" for name, seconds in result["cpu"].items()))
        real_time = end is not None and status.frames_dropped == 0 \
            and status.frames_used == end.frames_sent
        print(f"real time at 30 fps with {args.samples_per_frame} steps/frame: "
              f"{'yes' if real_time else 'no'}")

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
