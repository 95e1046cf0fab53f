"""gngdt across two hosts (network namespaces joined by a veth pair, as root): what crosses the
link and how fast, per placement of the services; recovery after host B's router restarts and
after the link is down for 5 s; a late joiner's query across hosts.

    python benchmarks/bench_two_hosts.py [--seconds 10] [--max-points 50000] [--recording X]

One camera (a 640x480 synthetic tabletop replayed in a loop at 30 fps) on host A; a `gngdt
router` on each host, B's linked to A's by its configuration file. Placements:

1. learner and logger on B: every stream the logger takes (images, clouds) crosses the link;
2. learner on B, no logger: the clouds cross;
3. learner on A, B only subscribes to topologies and objects: only those cross.

Per placement: MB/s over the link each way (the veth's byte counters: payloads, zenoh and
TCP/IP headers), topologies received on B per second, capture -> topology latency on B
(p50/p99). For placement 1 also the bytes of each topic per frame (a subscriber to ``gngdt/**``
on B), and the recovery figures. The veth is a memory copy: a real network adds its latency and
caps the bandwidth. Not a test: it prints figures (the test is tests/process/test_two_hosts.py).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from two_hosts import Deployment, TwoHosts, link_bytes, unavailable

PLACEMENTS = [
    ("learner + logger on B", "B", "B"),
    ("learner on B", "B", None),
    ("learner on A, B takes topology + objects", "A", None),
]


def render(path: Path, frames: int) -> None:
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    with RecordingWriter(path, compression="lz4") as writer:
        for frame in render_scene("tabletop", frames, width=640, height=480):
            writer.write_frame(frame)


def fresh(setup: Deployment, count: int, timeout_s: float = 120.0) -> float:
    """Wait for ``count`` topologies of frames captured from now on; seconds to the first."""
    since = time.time_ns()
    setup.wait(lambda: len(setup.topologies_captured_after(since)) >= count, timeout_s,
               "fresh topologies")
    return (setup.topologies_captured_after(since)[0]["received_ns"] - since) / 1e9


def steady(setup: Deployment, seconds: float) -> dict[str, float]:
    """Link MB/s each way, topologies/s and latency on B over ``seconds`` of streaming."""
    fresh(setup, 5)
    sent0, received0 = link_bytes(setup.hosts)
    started = time.time_ns()
    time.sleep(seconds)
    ended = time.time_ns()
    sent1, received1 = link_bytes(setup.hosts)
    window = [r for r in setup.records() if started <= r["capture_ns"] < ended]
    latency = [(r["received_ns"] - r["capture_ns"]) / 1e6 for r in window]
    # capture numbers every frame it sends: the span of the sequences learned is what it sent
    frames = window[-1]["sequence"] - window[0]["sequence"] + 1 if len(window) > 1 else 0
    return {"a_to_b_mb_s": (sent1 - sent0) / seconds / 1e6,
            "b_to_a_mb_s": (received1 - received0) / seconds / 1e6,
            "captured_per_s": frames / seconds,
            "a_to_b_kb_per_frame": (sent1 - sent0) / max(frames, 1) / 1e3,
            "topologies_per_s": len(window) / seconds,
            "p50_ms": float(np.percentile(latency, 50)) if latency else float("nan"),
            "p99_ms": float(np.percentile(latency, 99)) if latency else float("nan")}


def per_topic(setup: Deployment, workdir: Path, seconds: float) -> dict[str, list[float]]:
    """Samples/s and bytes per sample of each topic, seen by a subscriber on host B."""
    out = workdir / "count.json"
    probe = setup.probe("B", "count", out)
    setup.wait(lambda: "READY" in Path(probe.log_path).read_text(), 60, "the counter")
    time.sleep(seconds)
    from two_hosts import stop

    stop(probe)
    totals = json.loads(out.read_text())
    return {key: [samples / seconds, size / max(samples, 1)]
            for key, (samples, size) in sorted(totals.items())}


def recovery(setup: Deployment) -> dict[str, float]:
    """Router B killed and restarted after 1 s; the link down 5 s; a late joiner on A."""
    figures = {}
    fresh(setup, 3)
    setup.kill_router("B")
    time.sleep(1.0)
    restarted = time.time_ns()
    setup.start_router("B")
    setup.wait(lambda: setup.topologies_captured_after(restarted), 120, "recovery")
    figures["router_b_restart_s"] = (setup.topologies_captured_after(restarted)[0]["received_ns"]
                                     - restarted) / 1e9
    fresh(setup, 3)
    down = time.time_ns()
    setup.hosts.link(up=False)
    time.sleep(5.0)
    setup.hosts.link(up=True)
    up = time.time_ns()
    figures["link_down_5s_fresh_after_up_s"] = fresh_after(setup, up)
    stale = [r for r in setup.records() if r["received_ns"] > up and r["capture_ns"] < up]
    figures["stale_topologies_after_up"] = len(stale)
    figures["stale_max_age_s"] = max(((r["received_ns"] - r["capture_ns"]) / 1e9
                                      for r in stale), default=0.0)
    figures["received_while_down"] = len([r for r in setup.records()
                                          if down + 1e9 < r["received_ns"] < up])
    answer = setup.query("A")
    figures["late_joiner_replies"] = answer["replies"]
    figures["late_joiner_open_ms"] = answer["open_ms"]
    figures["late_joiner_get_ms"] = answer["get_ms"]
    return figures


def fresh_after(setup: Deployment, up_ns: int) -> float:
    setup.wait(lambda: setup.topologies_captured_after(up_ns), 120, "fresh topologies")
    return (setup.topologies_captured_after(up_ns)[0]["received_ns"] - up_ns) / 1e9


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="steady window per placement")
    parser.add_argument("--max-points", type=int, default=50_000,
                        help="capture's point cap (default 50000, as `gngdt run`; 0: full clouds)")
    parser.add_argument("--recording", type=Path, help="a 640x480 recording (default: rendered)")
    args = parser.parse_args()
    reason = unavailable()
    if reason is not None:
        print(f"cannot make two hosts here: {reason}")
        return 1
    with tempfile.TemporaryDirectory(prefix="bench-two-hosts-") as directory:
        workdir = Path(directory)
        recording = args.recording
        if recording is None:
            recording = workdir / "tabletop_640.mcap"
            render(recording, 60)
        capture_options = ("--max-points", str(args.max_points))
        rows, topics, figures = [], {}, {}
        with TwoHosts(workdir) as hosts:
            for index, (name, learner_on, logger_on) in enumerate(PLACEMENTS):
                setup = Deployment(hosts, workdir / f"p{index}", recording, capture_options,
                                   learner_on, logger_on)
                setup.workdir.mkdir()
                try:
                    setup.start()
                    rows.append((name, steady(setup, args.seconds)))
                    if index == 0:
                        topics = per_topic(setup, setup.workdir, args.seconds)
                        figures = recovery(setup)
                finally:
                    hosts.a.stop_processes()
                    hosts.b.stop_processes()
        report(rows, topics, figures, args)
    return 0


def report(rows, topics, figures, args) -> None:
    cap = f"clouds capped at {args.max_points:,} points" if args.max_points else "full clouds"
    print(f"one 640x480 camera at 30 fps on host A, {cap}; {args.seconds:g} s per placement")
    print(f"{'placement':42s} {'A->B MB/s':>9s} {'B->A MB/s':>9s} {'fps':>5s} "
          f"{'kB/frame':>8s} {'@30fps':>7s} {'topo/s':>6s} {'p50 ms':>7s} {'p99 ms':>7s}")
    for name, row in rows:
        print(f"{name:42s} {row['a_to_b_mb_s']:9.2f} {row['b_to_a_mb_s']:9.2f} "
              f"{row['captured_per_s']:5.1f} {row['a_to_b_kb_per_frame']:8.0f} "
              f"{row['a_to_b_kb_per_frame'] * 30 / 1e3:7.1f} "
              f"{row['topologies_per_s']:6.1f} {row['p50_ms']:7.1f} {row['p99_ms']:7.1f}")
    print("(fps: frames capture sent; kB/frame: A->B bytes per frame sent; @30fps: MB/s A->B at "
          "30 frames/s; p50/p99: capture -> topology received on B)")
    print("topics seen on B (placement 1): samples/s, kB per sample, MB/s")
    for key, (rate, size) in topics.items():
        print(f"  {key:32s} {rate:6.1f} {size / 1e3:9.1f} {rate * size / 1e6:7.2f}")
    print("recovery (placement 1): " + ", ".join(
        f"{key} {value:.2f}" if isinstance(value, float) else f"{key} {value}"
        for key, value in figures.items()))


if __name__ == "__main__":
    sys.exit(main())
