"""Normals on real Kinect frames: how stale the paper's stored normals get, what refreshing
costs, and how far apart neighbouring normals on one plane are (the basis of the sensor
profile's ``normal_angle_deg``).

    python benchmarks/bench_normals.py [--frames-per-set 5] [--steps 200000]

Reads ../shared/data/labelled (each frame's largest plane, fitted by RANSAC on its points, is
the reference surface). Prints the angle between stored and fresh (eq. 16) normals some steps
after a full refresh (p50/p99, share above 5 degrees: what a refresh every that many steps
bounds), the learning speed with refreshes, then the angle between neighbouring fresh normals on
the plane (p50/p90/p95/p99) and the share of the plane's position edges a normal threshold
keeps.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from gngdt.core import GNGDT
from gngdt.core.clustering import POS
from gngdt.io.images import iter_image_frames

LABELLED = Path(__file__).resolve().parents[2] / "shared" / "data" / "labelled"
PROFILE = {"max_nodes": 4000, "lambda_": 50}


def frame_points(frame) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) float32 metres and (N, 3) uint8 colours of the frame's valid depth pixels."""
    intr = frame.intrinsics
    depth = frame.depth.astype(np.float32) / 1000.0
    u = (np.arange(intr.width) - intr.cx) / intr.fx
    v = (np.arange(intr.height) - intr.cy) / intr.fy
    points = np.stack([u[None, :] * depth, v[:, None] * depth, depth], axis=-1).reshape(-1, 3)
    return points[points[:, 2] > 0], frame.color.reshape(-1, 3)[depth.reshape(-1) > 0]


def dominant_plane(points: np.ndarray, rng: np.random.Generator,
                   tolerance: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC plane (unit normal, a point on it) of the largest planar surface."""
    sample = points[rng.choice(len(points), min(len(points), 5000), replace=False)]
    best = (-1, None)
    for _ in range(300):
        a, b, c = sample[rng.choice(len(sample), 3, replace=False)]
        normal = np.cross(b - a, c - a)
        if np.linalg.norm(normal) < 1e-9:
            continue
        normal /= np.linalg.norm(normal)
        inliers = np.count_nonzero(np.abs((sample - a) @ normal) < tolerance)
        if inliers > best[0]:
            best = (inliers, (normal, a))
    return best[1]


def angles(normals: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    cosine = np.abs(np.einsum("ij,ij->i", normals[first], normals[second]))
    return np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames-per-set", type=int, default=5)
    parser.add_argument("--steps", type=int, default=200_000)
    args = parser.parse_args()
    if not LABELLED.is_dir():
        raise SystemExit(f"real frames not found at {LABELLED} (the repository's sibling "
                         "../shared)")
    rng = np.random.default_rng(0)
    frames = []
    for folder in ("mosd_learn", "ycbv_0000"):
        for index, frame in enumerate(iter_image_frames(LABELLED / folder, "redwood")):
            if index >= args.frames_per_set:
                break
            frames.append((folder, *frame_points(frame)))
    print(f"{len(frames)} real frames, {args.steps} steps each, profile {PROFILE}")
    print("steps since a full refresh | stored vs fresh normal: p50 / p99 deg, share > 5 deg")
    plane_angles = []
    for since in (1000, 5000, 20_000, args.steps):
        stale = []
        for _, points, colors in frames:
            model = GNGDT(**PROFILE, random_state=0)
            model.partial_fit(points, colors, n_steps=args.steps - since)
            model.refresh_normals()
            model.partial_fit(points, colors, n_steps=since)  # the paper: winners only
            stored, fresh = model.normals_, model.fresh_normals()
            defined = (np.linalg.norm(stored, axis=1) > 0) & (np.linalg.norm(fresh, axis=1) > 0)
            index = np.flatnonzero(defined)
            stale.append(angles(np.vstack([stored, fresh]), index, index + len(stored)))
            if since == args.steps:
                normal, origin = dominant_plane(points, rng)
                on_plane = np.abs((model.positions_ - origin) @ normal) < 0.005
                edges = model.edges(POS)
                keep = on_plane[edges[:, 0]] & on_plane[edges[:, 1]]
                plane_angles.append(angles(fresh, edges[keep, 0], edges[keep, 1]))
        stale_all = np.concatenate(stale)
        label = f"{since:,}" if since < args.steps else f"{since:,} (never: the paper)"
        print(f"{label:>26} | {np.percentile(stale_all, 50):.2f} / "
              f"{np.percentile(stale_all, 99):.2f}, {np.mean(stale_all > 5):.1%}")
    print("cost of refreshing (steps/s, same frames):")
    for refresh in (None, 5000, 1000):
        rates = []
        for _, points, colors in frames:
            model = GNGDT(**PROFILE, normal_refresh_steps=refresh, random_state=0)
            started = time.perf_counter()
            model.partial_fit(points, colors, n_steps=args.steps)
            rates.append(args.steps / (time.perf_counter() - started))
        print(f"  every {refresh or 'never (paper)'}: {np.median(rates):,.0f} steps/s")
    neighbours = np.concatenate(plane_angles)
    print(f"neighbouring fresh normals on the dominant plane ({neighbours.size} edges): "
          f"p50 {np.percentile(neighbours, 50):.1f}, p90 {np.percentile(neighbours, 90):.1f}, "
          f"p95 {np.percentile(neighbours, 95):.1f}, p99 {np.percentile(neighbours, 99):.1f} deg")
    for threshold in (1.1, 2.0, 4.0, 6.0, 8.0, 10.0, 15.0):
        kept = np.mean(neighbours < threshold)
        print(f"  normal edge kept below {threshold:4.1f} deg: {kept:.1%} of the plane's edges")


if __name__ == "__main__":
    main()
