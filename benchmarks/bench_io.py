"""Recording and wire I/O speed: frame read+decode, point-cloud packing, synthetic rendering.

Run: ``python benchmarks/bench_io.py``. Targets: read+decode one 640x480 frame (colour + depth)
< 10 ms; pack a 300k-point cloud into a foxglove PointCloud and back < 10 ms; render one
synthetic frame < 200 ms. Prints figures; the cloud is compared with a per-point Python loop.
"""

from __future__ import annotations

import struct
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gngdt.io.frame import CameraIntrinsics, Frame
from gngdt.io.mcap.reader import read_frames
from gngdt.io.mcap.writer import RecordingWriter
from gngdt.schemas.clouds import cloud_to_msg, msg_to_cloud

WIDTH, HEIGHT, FRAMES, POINTS = 640, 480, 30, 300_000


def best_of(function: Callable[[], object], repeats: int = 5) -> float:
    """Fastest of ``repeats`` calls, in seconds."""
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return min(times)


def realistic_frame(index: int, rng: np.random.Generator) -> Frame:
    """Smooth colour and depth with noise, so compression behaves as on camera images."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    color = np.stack([(cols * 255 // WIDTH), (rows * 255 // HEIGHT), np.full_like(rows, 90)], -1)
    color = np.clip(color + rng.integers(-8, 9, color.shape), 0, 255).astype(np.uint8)
    depth = (800 + rows * 3 + rng.integers(-5, 6, rows.shape)).astype(np.uint16)
    depth[rng.random(depth.shape) < 0.15] = 0
    intrinsics = CameraIntrinsics(WIDTH, HEIGHT, 525.0, 525.0, 319.5, 239.5)
    return Frame(index, 1_700_000_000_000_000_000 + index * 33_333_333, color, depth, intrinsics)


def bench_read(directory: Path) -> None:
    rng = np.random.default_rng(0)
    frames = [realistic_frame(i, rng) for i in range(FRAMES)]
    for compression in ("zstd", "lz4", "none"):
        for color_format in ("raw", "jpeg"):
            path = directory / f"{compression}-{color_format}.mcap"
            started = time.perf_counter()
            with RecordingWriter(path, compression=compression, color_format=color_format) as w:
                for frame in frames:
                    w.write_frame(frame)
            write_ms = (time.perf_counter() - started) * 1e3 / FRAMES
            read_s = best_of(lambda path=path: sum(1 for _ in read_frames(path)), repeats=3)
            print(
                f"read+decode 640x480 frame  {compression:>4} {color_format:>4}: "
                f"{read_s * 1e3 / FRAMES:6.2f} ms/frame (target < 10)   write {write_ms:6.2f} "
                f"ms/frame   {path.stat().st_size / FRAMES / 1e6:.2f} MB/frame"
            )


def naive_pack(positions: np.ndarray, colors: np.ndarray) -> bytes:
    """Baseline: one struct.pack per point."""
    point = struct.Struct("<fffBBB")
    return b"".join(
        point.pack(*position, *color)
        for position, color in zip(positions.tolist(), colors.tolist(), strict=True)
    )


def bench_cloud() -> None:
    rng = np.random.default_rng(1)
    positions = rng.normal(size=(POINTS, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (POINTS, 3), dtype=np.uint8)

    def round_trip(copy: bool) -> None:
        payload = cloud_to_msg(positions, colors, timestamp_ns=0).SerializeToString()
        msg_to_cloud(payload, copy=copy)

    pack_s = best_of(lambda: cloud_to_msg(positions, colors, timestamp_ns=0), repeats=20)
    total_s = best_of(lambda: round_trip(copy=False), repeats=20)
    total_copy_s = best_of(lambda: round_trip(copy=True), repeats=20)
    sample = 10_000
    naive_s = best_of(lambda: naive_pack(positions[:sample], colors[:sample]), repeats=3)
    naive_scaled_ms = naive_s * POINTS / sample * 1e3
    print(f"pack {POINTS} points -> PointCloud: {pack_s * 1e3:6.2f} ms")
    print(f"pack + serialize + parse + unpack to views (learner, logger): "
          f"{total_s * 1e3:6.2f} ms (target < 10)")
    print(f"pack + serialize + parse + unpack to copies:                  "
          f"{total_copy_s * 1e3:6.2f} ms")
    print(
        f"naive per-point struct.pack ({sample} points, scaled to {POINTS}): "
        f"{naive_scaled_ms:7.1f} ms  -> {naive_scaled_ms / (pack_s * 1e3):.0f}x slower than pack"
    )


def bench_synth() -> None:
    try:
        from gngdt.io.synth.render import SCENES, render_scene
    except ImportError:
        print("synth: not available")
        return
    for scene in sorted(SCENES):
        started = time.perf_counter()
        frames = list(render_scene(scene, 5, width=WIDTH, height=HEIGHT, seed=0))
        per_frame_ms = (time.perf_counter() - started) * 1e3 / len(frames)
        print(f"synth {scene}: {per_frame_ms:6.1f} ms/frame 640x480 (target < 200)")


def main() -> int:
    with tempfile.TemporaryDirectory() as directory:
        bench_read(Path(directory))
    bench_cloud()
    bench_synth()
    return 0


if __name__ == "__main__":
    sys.exit(main())
