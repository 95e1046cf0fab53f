"""A live camera posed on every frame (issue 33): ``--track --realtime`` at the recorded 30 fps,
capture + learner + logger running, quiet and beside busy processes.

Renders (or takes) a walk with true poses (``tabletop_walk``, 640x480), replays it as a live
camera would send it (``capture --realtime --fixed-frame none``: the recording's own poses are
ignored, whole clouds, the learner takes the latest frame), a learner that tracks the camera
(``learn --track``) and a logger writing a .rrd, each a process on a router of its own. An
observer collects every pose the learner publishes (``gngdt/<cam>/tf``, by frame sequence) and
the learner's last status. Printed per run: frames sent, posed (share), learned, lost (by why)
and dropped before tracking; ATE RMSE of the posed frames against the true poses (after a rigid
Horn alignment, as TUM's evaluate_ate); CPU of each process per frame sent. Baseline in the
same run: the frames the learner learned (before the tracker thread, only those were posed).

    python benchmarks/bench_live_tracking.py [--frames 300] [--busy 0,2] [--recording X]
"""

from __future__ import annotations

import argparse
import itertools
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
from bench_tracking import ate, rpe
from pipeline_runs import TRANSPORTS, BenchPipeline, CpuWindow, load_average
from procstat import busy_processes

from gngdt.schemas.wire import DEFAULT_CAMERA, LEARNER, LOGGER_ALIVE, alive_key, topic


def render_walk(path: Path, frames: int) -> Path:
    subprocess.run([sys.executable, "-m", "gngdt.services.cli", "record", "synth", "--scene",
                    "tabletop_walk", "--frames", str(frames), "--out", str(path),
                    "--log-level", "WARNING"], check=True)
    return path


def true_poses(recording: Path) -> list[np.ndarray]:
    from gngdt.io.mcap.reader import read_frames

    return [frame.pose.matrix for frame in read_frames(recording, fixed_frame="auto")]


class PoseWatch:
    """Every camera pose the learner publishes, by frame sequence."""

    def __init__(self, session) -> None:
        self.lock = threading.Lock()
        self.poses: dict[int, np.ndarray] = {}
        self.subscriber = session.declare_subscriber(topic(DEFAULT_CAMERA, "tf"), self._on_tf)

    def _on_tf(self, sample) -> None:
        from gngdt.schemas.clouds import transform_to_pose
        from gngdt.schemas.wire import FrameStamp

        stamp = FrameStamp.from_attachment(sample.attachment.to_bytes())
        _, _, matrix = transform_to_pose(sample.payload.to_bytes())
        with self.lock:
            self.poses[stamp.sequence] = matrix


def run_once(recording: Path, workdir: Path, truth: list[np.ndarray], busy_count: int) -> None:
    load = load_average()
    bench = BenchPipeline(workdir, TRANSPORTS["shm"])
    try:
        watch = PoseWatch(bench.observer.session)
        bench.start("learn", ["--exit-on-eos", "--track"], "learner")
        bench.start("log", ["--save", str(workdir / "live.rrd")], "logger")
        bench.wait(lambda: bench.observer.has_alive(alive_key(DEFAULT_CAMERA, LEARNER),
                                                    LOGGER_ALIVE), 300, "learner and logger")
        with busy_processes(busy_count):
            capture = bench.start("capture", [str(recording), "--realtime", "--fixed-frame",
                                              "none", "--max-points", "0"])
            window = bench.stream([capture], [DEFAULT_CAMERA], exit_s=180.0)
        seen = bench.observer.camera("gngdt/camera")
        with bench.observer.lock, watch.lock:
            status, end, poses = seen.status, seen.end, dict(watch.poses)
        watch.subscriber.undeclare()
    finally:
        bench.close()
    report(status, end, poses, truth, window, busy_count, load)


def report(status, end, poses: dict[int, np.ndarray], truth: list[np.ndarray],
           window: CpuWindow, busy_count: int, load: float) -> None:
    sent = end.frames_sent
    sequences = sorted(sequence for sequence in poses if sequence < len(truth))
    error = ate([poses[s] for s in sequences], [truth[s] for s in sequences])[0] \
        if len(sequences) >= 3 else float("nan")
    worst = worst_step(poses, truth, sequences)
    lost = ", ".join(f"{reason} {count}" for reason, count in
                     sorted(status.frames_lost_by_reason.items())) or "none"
    per_frame = ", ".join(f"{name} {percent * window.seconds * 10 / max(sent, 1):.1f}"
                          for name, percent in window.percent().items())
    print(f"busy {busy_count} (load {load:.1f}): {sent} sent, posed {len(poses)} "
          f"({len(poses) / max(sent, 1):.1%}; status {status.frames_posed}), learned "
          f"{status.frames_used} ({status.frames_used / max(sent, 1):.1%}: the frames the "
          f"learner alone would have posed), lost {status.frames_lost_tracking} ({lost}), "
          f"dropped before tracking {status.frames_dropped}; ATE {error * 1000:.1f} mm over "
          f"{len(sequences)} posed frames ({worst}); CPU ms per frame sent: {per_frame}",
          flush=True)


def worst_step(poses: dict[int, np.ndarray], truth: list[np.ndarray],
               sequences: list[int]) -> str:
    """The worst error of the camera's motion between two posed frames in a row, and where (a
    wrong lock shows as one large step, a slow drift as none)."""
    if len(sequences) < 2:
        return "no steps"
    errors = [rpe([poses[a], poses[b]], [truth[a], truth[b]])["t_max"]
              for a, b in itertools.pairwise(sequences)]
    worst = int(np.argmax(errors))
    return (f"worst step error {errors[worst] * 1000:.1f} mm, frames {sequences[worst]} -> "
            f"{sequences[worst + 1]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--recording", type=Path, help="a walk with true poses (default: render)")
    parser.add_argument("--busy", default="0,2", help="busy processes beside each run")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-live-") as temp:
        workdir = Path(temp)
        recording = args.recording or render_walk(workdir / "walk.mcap", args.frames)
        truth = true_poses(recording)
        for index, count in enumerate(int(value) for value in args.busy.split(",")):
            run_once(recording, workdir / f"run{index}", truth, count)


if __name__ == "__main__":
    main()
