"""CPU per frame of the learner's work alone, beside another installation's, in one process each.

    python benchmarks/bench_learner_frame.py RECORDING.mcap [--skip 30] [--frames 60]
        [--repeat 3] [--baseline /path/to/old/.venv/bin/python]
    python benchmarks/bench_learner_frame.py recordings/tabletop.mcap --skip 10 --frames 40

What `gngdt learn` does with each cloud of a file replay, without zenoh and without the other
processes (steadier than `bench_run_cpu.py` on a busy machine): the capture's cloud (the run's
50,000-point cap) decoded as the learner decodes it, learned with 10,000 steps, and every 3rd
frame published (segmentation, cluster ids, objects, ghost share, quantization error) and its
topology, objects and status messages encoded. The first ``--skip`` frames grow the network
untimed; the next ``--frames`` are timed (process CPU time). With ``--baseline`` another
installation's Python runs the same script on the same frames, the two alternating, and the
ratio of each pair is printed.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

PUBLISH_EVERY = 3
STEPS = 10_000


def clouds(recording: Path, count: int) -> list[bytes]:
    """The first ``count`` clouds of ``recording`` as the capture of `gngdt run` sends them."""
    from gngdt.io.deproject import RUN_POINT_CAP, CloudOptions, FrameToCloud
    from gngdt.io.mcap.reader import read_frames

    to_cloud = FrameToCloud(CloudOptions(max_points=RUN_POINT_CAP))
    wires = []
    for index, frame in enumerate(read_frames(recording)):
        if index == count:
            break
        pose = frame.pose
        wire, _ = to_cloud.to_wire(frame, timestamp_ns=index + 1,
                                   frame_id="camera" if pose is None else pose.frame_id,
                                   pose=None if pose is None else pose.matrix)
        wires.append(bytes(wire))
    return wires


def learner_ms_per_frame(recording: Path, skip: int, frames: int) -> tuple[float, int]:
    """CPU ms per timed frame of this installation's learner, and its node count at the end."""
    from gngdt.core.learner.frame_learner import FrameLearner
    from gngdt.schemas.wire import FrameStamp
    from gngdt.services.learner import add_arguments, profile_from_args
    from gngdt.services.learner.messages import (
        decode_points,
        objects_message,
        status_message,
        topology_message,
    )

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    learner = FrameLearner("camera", profile_from_args(parser.parse_args([])).config)
    wires = clouds(recording, skip + frames)

    def take(index: int, wire: bytes) -> None:
        stamp = FrameStamp(index, time.time_ns())
        cloud = decode_points(wire, stamp.to_attachment())
        learner.learn(cloud.positions, cloud.colors, cloud.frame_id, cloud.pose, cloud.sensor_ns,
                      steps=STEPS)
        if index % PUBLISH_EVERY == 0:
            published = learner.publication(cloud.positions, cloud.colors)
            for message in (topology_message(published, stamp), objects_message(published, stamp),
                            status_message(published.figures, stamp, 0.0, (0.0, 0.0), published)):
                message.SerializeToString()

    for index, wire in enumerate(wires[:skip]):
        take(index, wire)
    started = time.process_time()
    for index, wire in enumerate(wires[skip:], skip):
        take(index, wire)
    timed = len(wires) - skip
    return 1000 * (time.process_time() - started) / max(timed, 1), int(learner.model.n_nodes_)


def run_build(python: str, args: argparse.Namespace) -> tuple[float, int]:
    """`learner_ms_per_frame` under another installation's ``python``."""
    done = subprocess.run([python, __file__, str(args.recording), "--skip", str(args.skip),
                           "--frames", str(args.frames), "--child"],
                          capture_output=True, text=True, check=True)
    milliseconds, nodes = done.stdout.split()
    return float(milliseconds), int(nodes)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path, help="a 640x480 MCAP recording")
    parser.add_argument("--skip", type=int, default=30, help="frames learned before timing")
    parser.add_argument("--frames", type=int, default=60, help="frames timed")
    parser.add_argument("--repeat", type=int, default=3, help="runs (pairs with --baseline)")
    parser.add_argument("--baseline", help="another installation's python executable")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(*learner_ms_per_frame(args.recording, args.skip, args.frames))
        return 0
    builds = {"this": sys.executable, **({"baseline": args.baseline} if args.baseline else {})}
    figures: dict[str, list[float]] = {build: [] for build in builds}
    print(f"learner alone, {args.recording.name}: frames {args.skip}-{args.skip + args.frames} "
          f"timed, {STEPS:,} steps a frame, published every {PUBLISH_EVERY}", flush=True)
    for repeat in range(args.repeat):
        for build, python in builds.items():
            milliseconds, nodes = run_build(python, args)
            figures[build].append(milliseconds)
            print(f"  run {repeat + 1} {build}: {milliseconds:.1f} ms CPU a frame, {nodes} nodes",
                  flush=True)
    for build, values in figures.items():
        print(f"{build}: median {statistics.median(values):.1f} ms CPU a frame")
    if args.baseline:
        ratios = [this / base for this, base in zip(figures["this"], figures["baseline"],
                                                    strict=True)]
        print("this / baseline: " + ", ".join(f"{ratio:.2f}" for ratio in ratios))
    return 0


if __name__ == "__main__":
    sys.exit(main())
