"""CPU per frame of a whole `gngdt run`, per process, beside an earlier release in the same run.

    python benchmarks/bench_run_cpu.py [--frames 300] [--short 30] [--max-points 0]
        [--repeat 3] [--recording X.mcap]
        [--baseline /path/to/old/.venv/bin/gngdt --baseline-args "--rate 0.15"]
    python benchmarks/bench_run_cpu.py --max-points 0        # full 640x480 clouds
    python benchmarks/bench_run_cpu.py                       # clouds capped as `gngdt run` does
    python benchmarks/bench_run_cpu.py --max-points 10000 50000 0 --publish-every 0.3 --repeat 2

Renders (or takes) a 640x480 recording of ``--frames`` frames and writes its first ``--short``
frames beside it, then runs `gngdt run` on each (10,000 steps a frame, a .rrd written, every
process of the run measured from /proc while it runs and, whole, from the operating system's
account of the finished run). CPU per frame is the difference of the two runs over the frames
between them: the start-up (imports, kernels loaded, router) is the same in both and cancels.
With ``--baseline`` another installation's `gngdt` (an earlier release) runs the same files in
turn, pair by pair; ``--baseline-args`` makes it learn every frame if it replays in real time
(e.g. ``--rate 0.15``). Each run's frames learned are printed: a figure is only comparable when
both learned every frame. Values of ``--max-points``, ``--samples-per-frame`` and
``--publish-every`` are measured one at a time (the rest as `gngdt run` has them), ending with
the curve: CPU a frame of each process against each.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from bench_pipeline import render_recording
from procstat import cpu_seconds

SERVICES = ("capture", "learn", "log", "router", "ros2")
#: options of `gngdt run` the curve may vary, one at a time
VARIED = ("--max-points", "--samples-per-frame", "--publish-every")
LEARNED = re.compile(r"frames learned:\s+(\d+) of (\d+)")


@dataclass
class RunCpu:
    """One `gngdt run`: CPU seconds of each process (``run``: the run itself, its router and
    what the samples missed), the whole tree's, and the frames learned / sent."""

    per_process: dict[str, float] = field(default_factory=dict)
    total: float = 0.0
    learned: int = 0
    sent: int = 0


def service_name(pid: int) -> str | None:
    """Which gngdt service a process is (the subcommand on its command line), None otherwise."""
    try:
        words = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return None
    return next((word for word in words if word in SERVICES), None)


def descendants(pid: int) -> list[int]:
    """Every live process below ``pid`` (Linux: /proc/<pid>/task/*/children)."""
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*"):
            try:
                children = [int(child) for child in (task / "children").read_text().split()]
            except OSError:
                continue
            found.extend(children)
            todo.extend(children)
    return found


def run_once(command: list[str]) -> RunCpu:
    """Run ``command`` (a `gngdt run`) to its end, sampling its services' CPU every 50 ms."""
    with tempfile.TemporaryFile() as output:
        process = subprocess.Popen(command, stdout=output, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL)
        seen: dict[int, tuple[str, float]] = {}
        while True:
            for pid in descendants(process.pid):
                name = seen[pid][0] if pid in seen else service_name(pid)
                if name is not None:
                    seconds = cpu_seconds(pid)
                    if seconds > 0:
                        seen[pid] = (name, seconds)
            finished, status, usage = os.wait4(process.pid, os.WNOHANG)
            if finished:
                break
            time.sleep(0.05)
        output.seek(0)
        text = output.read().decode(errors="replace")
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{shlex.join(command)} failed:\n{text[-3000:]}")
    result = RunCpu(total=usage.ru_utime + usage.ru_stime)
    for name, seconds in seen.values():
        result.per_process[name] = result.per_process.get(name, 0.0) + seconds
    result.per_process["run"] = result.total - sum(result.per_process.values())
    learned = LEARNED.findall(text)
    result.learned, result.sent = (int(learned[-1][0]), int(learned[-1][1])) if learned else (0, 0)
    return result


def per_frame_ms(long: RunCpu, short: RunCpu) -> dict[str, float]:
    """CPU ms per frame sent of each process and in all, from a long and a short run."""
    frames = max(long.sent - short.sent, 1)
    names = sorted(set(long.per_process) | set(short.per_process))
    figures = {name: (long.per_process.get(name, 0.0) - short.per_process.get(name, 0.0))
               * 1e3 / frames for name in names}
    figures["all"] = (long.total - short.total) * 1e3 / frames
    return figures


def shorten(recording: Path, frames: int, out: Path) -> None:
    """The first ``frames`` frames of ``recording`` into ``out``."""
    from itertools import islice

    from gngdt.io.mcap.reader import read_frames
    from gngdt.io.mcap.writer import RecordingWriter

    with RecordingWriter(out, compression="lz4") as writer:
        for frame in islice(read_frames(recording), frames):
            writer.write_frame(frame)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--frames", type=int, default=300,
                        help="frames of the long run (rendered; default 300)")
    parser.add_argument("--short", type=int, default=30, help="frames of the short run")
    parser.add_argument("--recording", type=Path, help="a 640x480 recording instead of a render")
    parser.add_argument("--max-points", type=int, nargs="+", metavar="N",
                        help="capture's point cap (0: full clouds; default: gngdt run's own); "
                        "several give the curve of CPU a frame against cloud size")
    parser.add_argument("--samples-per-frame", type=int, nargs="+", metavar="STEPS",
                        help="learning steps a frame (default: gngdt run's own, 10,000); "
                        "several give the curve against them")
    parser.add_argument("--publish-every", type=float, nargs="+", metavar="SECONDS",
                        help="the learner's publication period (default: gngdt run's own, "
                        "0.1 s of the stream's clock)")
    parser.add_argument("--repeat", type=int, default=3, help="pairs of runs (default 3)")
    parser.add_argument("--baseline", help="another installation's gngdt executable")
    parser.add_argument("--baseline-args", default="",
                        help="extra arguments for the baseline's run (e.g. '--rate 0.15')")
    args = parser.parse_args()
    this = str(Path(sys.executable).with_name("gngdt"))
    builds = {"this": (this, [])}
    if args.baseline:
        builds["baseline"] = (args.baseline, shlex.split(args.baseline_args))
    settings = [(f"{flag[2:]} {value}", [flag, str(value)])
                for flag in VARIED for value in (getattr(args, flag[2:].replace("-", "_")) or [])]
    settings = settings or [("gngdt run's defaults", [])]

    with tempfile.TemporaryDirectory(prefix="bench-run-cpu-") as directory:
        workdir = Path(directory)
        long = args.recording
        if long is None:
            long = workdir / "long.mcap"
            print(f"rendering {args.frames} frames 640x480 ...", flush=True)
            render_recording(long, args.frames)
        short = workdir / "short.mcap"
        shorten(long, args.short, short)
        curve = []
        for label, options in settings:
            print(f"\ngngdt run, {long.name} and its first {args.short} frames, {label}, "
                  f"{args.repeat} pairs, builds: {', '.join(builds)}", flush=True)
            frames = measure(builds, options, long, short, workdir, args.repeat)
            curve.append((label, print_table(frames)))
        if len(curve) > 1:
            print_curve(curve)
    return 0


def measure(builds: dict[str, tuple[str, list[str]]], options: list[str], long: Path,
            short: Path, workdir: Path, repeat: int) -> dict[str, list[dict[str, float]]]:
    """CPU ms per frame of each process, each build, each of ``repeat`` pairs of runs."""
    frames: dict[str, list[dict[str, float]]] = {build: [] for build in builds}
    for pair in range(repeat):
        for build, (executable, extra) in builds.items():
            runs = {}
            for label, path in (("long", long), ("short", short)):
                command = [executable, "run", str(path), *options, "--overwrite", "--save",
                           str(workdir / f"{build}.rrd"), *extra]
                runs[label] = run_once(command)
            figures = per_frame_ms(runs["long"], runs["short"])
            frames[build].append(figures)
            print(f"  pair {pair + 1} {build}: learned {runs['long'].learned} of "
                  f"{runs['long'].sent} and {runs['short'].learned} of {runs['short'].sent}; "
                  + ", ".join(f"{name} {ms:.1f}" for name, ms in figures.items())
                  + " ms/frame", flush=True)
    return frames


def process_names(rows: Iterable[dict[str, float]]) -> list[str]:
    """The processes named in ``rows`` (figures by process), sorted, "all" last."""
    return sorted({name for row in rows for name in row}, key=lambda name: (name == "all", name))


def print_table(frames: dict[str, list[dict[str, float]]]) -> dict[str, float]:
    """Print the median CPU ms per frame of each process, each build, and this build over the
    baseline; return this build's medians."""
    names = process_names(figures for runs in frames.values() for figures in runs)
    print(f"\nCPU ms per frame (median of pairs) {'':8s}" + "".join(f"{n:>9s}" for n in names))
    medians = {}
    for build, runs in frames.items():
        medians[build] = {name: statistics.median(f.get(name, 0.0) for f in runs)
                          for name in names}
        print(f"  {build:40s}" + "".join(f"{medians[build][n]:9.1f}" for n in names))
    if "baseline" in frames:
        ratios = [this["all"] / base["all"]
                  for this, base in zip(frames["this"], frames["baseline"], strict=True)]
        print(f"  this / baseline, all processes: {statistics.median(ratios):.2f} (pairs: "
              + ", ".join(f"{ratio:.2f}" for ratio in ratios) + ")")
    return medians["this"]


def print_curve(curve: list[tuple[str, dict[str, float]]]) -> None:
    """This build's median CPU ms per frame of each process, one row per setting."""
    names = process_names(medians for _, medians in curve)
    print("\nthe curve: CPU ms per frame (this build, median of pairs)")
    print(f"  {'':40s}" + "".join(f"{name:>9s}" for name in names))
    for label, medians in curve:
        print(f"  {label:40s}" + "".join(f"{medians.get(name, 0.0):9.1f}" for name in names))


if __name__ == "__main__":
    sys.exit(main())
