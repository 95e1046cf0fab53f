"""Many cameras on one host: 1, 2 and 4 synthetic 640x480 cameras at 30 fps, one learner each and
one logger for all, clients of one `gngdt router` process: frames learned and capture ->
topology latency per camera, CPU per process, so a user can size a machine.

    python benchmarks/bench_cameras.py [--cameras 1,2,4] [--frames 60] [--max-points 50000]
                                       [--samples-per-frame 10000] [--transport shm] [--no-logger]

Camera i replays a recording of its own scene (tabletop, tabletop_walk, tabletop_move, data2,
rendered once; recorded at 30 fps) as ``cam<i>``; every learner runs with its defaults and
``--exit-on-eos``; the logger writes one .rrd for all. Clouds are capped at 50,000 points as
`gngdt run` does (``--max-points 0``: full clouds). ``--transport`` as in
``pipeline_runs.TRANSPORTS`` (``shm``, gngdt's default; ``network``: shared memory off). Not a
test: it prints figures.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pipeline_runs import TRANSPORTS, BenchPipeline, load_average, percentiles

from gngdt.schemas.wire import LEARNER, LOGGER_ALIVE, alive_key

SCENES = ("tabletop", "tabletop_walk", "tabletop_move", "data2")


def render(path: Path, scene: str, frames: int) -> Path:
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    if not path.exists():
        with RecordingWriter(path, compression="lz4") as writer:
            for frame in render_scene(scene, frames, width=640, height=480):
                writer.write_frame(frame)
    return path


def run_cameras(count: int, recordings: list[Path], args: argparse.Namespace,
                workdir: Path) -> dict:
    """``count`` cameras through their learners (and a logger); what each camera got."""
    load = load_average()
    bench = BenchPipeline(workdir, TRANSPORTS[args.transport])
    cameras = [f"cam{index}" for index in range(count)]
    try:
        for camera in cameras:
            bench.start("learn", ["--cam", camera, "--exit-on-eos", "--samples-per-frame",
                                  str(args.samples_per_frame)], f"learner-{camera}")
        expected = [alive_key(camera, LEARNER) for camera in cameras]
        if not args.no_logger:
            bench.start("log", ["--save", str(workdir / "cameras.rrd")], "logger")
            expected.append(LOGGER_ALIVE)
        bench.wait(lambda: bench.observer.has_alive(*expected), 300, "learners and logger")
        captures = [bench.start("capture", [str(recordings[index % len(recordings)]),
                                            "--realtime", "--cam",
                                            camera, "--max-points", str(args.max_points)],
                                f"capture-{camera}")
                    for index, camera in enumerate(cameras)]
        window = bench.stream(captures, cameras, wait_s=120.0, exit_s=180.0)
        with bench.observer.lock:
            seen = {camera: bench.observer.cameras.get(camera) for camera in cameras}
    finally:
        bench.close()
    return {"count": count, "seen": seen, "cpu": window.percent(), "seconds": window.seconds,
            "load": load, "peaks": window.peaks}


def report(runs: list[dict], args: argparse.Namespace) -> None:
    cap = f"clouds capped at {args.max_points:,} points" if args.max_points else "full clouds"
    print(f"640x480 cameras at 30 fps, {cap}, {args.samples_per_frame:,} steps/frame, transport "
          f"{args.transport}, {'no logger' if args.no_logger else 'one logger for all'}")
    print(f"{'cams':>4s} {'load':>4s} {'camera':>6s} {'sent':>4s} {'learned':>7s} {'p50 ms':>7s} "
          f"{'p99 ms':>7s} {'rx p99':>7s}")
    for run in runs:
        for camera, seen in run["seen"].items():
            status, end = seen.status if seen else None, seen.end if seen else None
            _, received99 = percentiles(seen.received_latency_ms if seen else [])
            print(f"{run['count']:4d} {run['load']:4.1f} {camera:>6s} "
                  f"{end.frames_sent if end else '?':>4} "
                  f"{status.frames_used if status else 0:7d} "
                  f"{status.latency_p50_ms if status else float('nan'):7.1f} "
                  f"{status.latency_p99_ms if status else float('nan'):7.1f} {received99:7.1f}")
    print("CPU % of one core while the captures stream (per process; the machine has "
          f"{_cores()} cores), and peak RSS MB:")
    for run in runs:
        cpu = run["cpu"]
        groups = {"capture": [], "learner": [], "logger": [], "router": []}
        for name, percent in cpu.items():
            groups[name.split("-")[0]].append(percent)
        text = ", ".join(f"{group} {np.mean(values):.0f} each" if len(values) > 1
                         else f"{group} {values[0]:.0f}"
                         for group, values in groups.items() if values)
        sent = sum(seen.end.frames_sent for seen in run["seen"].values() if seen and seen.end)
        per_frame = ", ".join(f"{group} {sum(values) * run['seconds'] * 10 / max(sent, 1):.1f}"
                              for group, values in groups.items() if values)
        peaks = ", ".join(f"{name} {mb:.0f}" for name, mb in run["peaks"].items())
        print(f"  {run['count']} camera(s), {run['seconds']:.1f} s: {text}; total "
              f"{sum(cpu.values()):.0f} %; CPU ms per frame sent: {per_frame}; RSS {peaks}")


def _cores() -> int:
    import os

    return os.cpu_count() or 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", default="1,2,4", help="camera counts to run (default 1,2,4)")
    parser.add_argument("--frames", type=int, default=60, help="frames per camera (30 fps)")
    parser.add_argument("--max-points", type=int, default=50_000,
                        help="capture's point cap (default 50000, as `gngdt run`; 0: full)")
    parser.add_argument("--samples-per-frame", type=int, default=10_000)
    parser.add_argument("--transport", choices=sorted(TRANSPORTS), default="shm")
    parser.add_argument("--no-logger", action="store_true", help="learners only")
    parser.add_argument("--recordings", type=Path, metavar="DIR",
                        help="keep the rendered recordings here (reused when present)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    counts = [int(value) for value in args.cameras.split(",")]
    with tempfile.TemporaryDirectory(prefix="bench-cameras-") as directory:
        workdir = Path(directory)
        folder = args.recordings or workdir
        folder.mkdir(parents=True, exist_ok=True)
        started = time.perf_counter()
        recordings = [render(folder / f"{scene}_640_{args.frames}.mcap", scene, args.frames)
                      for scene in SCENES[:max(counts)]]
        print(f"recordings ready in {time.perf_counter() - started:.0f} s")
        runs = [run_cameras(count, recordings, args, workdir / f"cams{count}")
                for count in counts]
        report(runs, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
