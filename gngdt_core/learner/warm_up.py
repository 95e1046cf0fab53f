"""Compile the numba kernels before the first frame, one group at a time, saying how far it got.

numba compiles a kernel on its first call and, with ``cache=True``, writes each one to its disk
cache as soon as that kernel is compiled: the first run on a machine pays the compilation (15-40 s
on 2 cores, most of it the learning loop), later runs load the cache in well under a second, and
a run stopped midway keeps every kernel it finished. Running the groups here, before any frame,
keeps compilation out of the first frame's latency and lets a supervisor (`gngdt run`) see
progress instead of silence.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # light module: the kernels load when a warm-up runs
    from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig
    from gngdt.core.learner.frame_segmenter import FrameSegmenter

#: progress(done, total, what): called before each group, and once at the end (done == total)
Progress = Callable[[int, int, str], None]
#: how each step is logged (`logged_progress`); `gngdt run` looks for it in a service's log
PROGRESS_PHRASE = "compiling kernels"


def logged_progress(logger: logging.Logger) -> Progress:
    """A `Progress` that logs each step at INFO: ``compiling kernels 2/4: nearest nodes``."""

    def progress(done: int, total: int, what: str) -> None:
        if done < total:
            logger.info("%s %d/%d: %s", PROGRESS_PHRASE, done + 1, total, what)

    return progress


def sample_frame(count: int = 500, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random points in front of a camera: positions (N, 3) float32 metres (z from 1 to 2),
    colors (N, 3) uint8, and a camera pose (4, 4) slightly off the origin; the dtypes of a
    real frame, so the kernels compiled are the ones real frames use."""
    rng = np.random.default_rng(seed)
    positions = rng.random((count, 3), dtype=np.float32)
    positions[:, 2] += 1.0
    colors = rng.integers(0, 256, (count, 3), dtype=np.uint8)
    pose = np.eye(4)
    pose[:3, 3] = 0.1
    return positions, colors, pose


def warm_up_learner(config: LearnerConfig, progress: Progress | None = None) -> FrameLearner:
    """Run every kernel the learner's per-frame policy uses once on random points; returns the
    throw-away learner (its messages can be warmed up with it)."""
    from gngdt.core.learner.frame_learner import FrameLearner

    positions, colors, pose = sample_frame()
    # a map in a fixed frame, as posed or tracked clouds build it, without its long first frame
    quick = replace(config.options, first_frame_steps=config.options.samples_per_frame)
    learner = FrameLearner("warm-up", replace(config, options=quick))
    groups: list[tuple[str, Callable[[], object]]] = [
        # twice: the second frame carves the rehearsal memory the first one filled
        ("learning loop", lambda: [learner.learn(positions, colors, "world", pose)
                                   for _ in range(2)]),
        ("nearest nodes", lambda: learner.quantization_error(positions, colors)),
        ("normals and segmentation", learner.learned_frame),
        ("sensor view", lambda: learner.measure_ghosts(positions, pose)),
        # a reference and a comparison: loads scipy's k-d tree now
        ("pose checks", lambda: [learner.poses.check(positions, pose) for _ in range(2)]),
    ]
    if config.options.track:
        groups.append(("camera tracking", lambda: warm_up_tracking(config.tracker)))
    run_groups(groups, progress)
    return learner


def warm_up_tracking(params: object = None) -> None:
    """Align a small organized frame to a map of it once (`gngdt.core.odometry.map_odometry`'s
    kernels)."""
    from gngdt.core.gas.model import GNGDT
    from gngdt.core.odometry.map_odometry import MapOdometry
    from gngdt.core.odometry.map_surface import MapSurface
    from gngdt.core.sensor.depth import organize

    points, colors = sample_organized_frame()
    valid = np.isfinite(points[..., 2])
    model = GNGDT(max_nodes=200, lambda_=50, random_state=0)
    model.partial_fit(points[valid], colors[valid], n_steps=5_000, camera_pose=np.eye(4))
    odometry = MapOdometry(params, strides=(2,), iterations=(2,), gates_m=(0.1,), min_points=6)
    odometry.reset(np.eye(4)).track(points, colors, MapSurface.from_model(model))
    # a decoded cloud's points and colours are strided views of its packed records
    records = np.zeros(int(valid.sum()), dtype=[("xyz", "<f4", (3,)), ("rgb", "u1", (3,))])
    records["xyz"], records["rgb"] = points[valid], colors[valid]
    height, width = points.shape[:2]
    organize(records["xyz"], records["rgb"], width, height, width, width, width / 2,
             height / 2, 2)


def run_groups(groups: list[tuple[str, Callable[[], object]]],
               progress: Progress | None = None) -> None:
    """Call each group's function in turn, reporting progress before each and at the end."""
    for done, (what, call) in enumerate(groups):
        if progress is not None:
            progress(done, len(groups), what)
        call()
    if progress is not None:
        progress(len(groups), len(groups), "done")


def sample_organized_frame(height: int = 60, width: int = 80
                           ) -> tuple[np.ndarray, np.ndarray]:
    """A small organized frame as a depth camera gives it: points (H, W, 3) float32 metres of a
    table 1 m away with a box on it (NaN in one corner: no depth), colors (H, W, 3) uint8."""
    rows, columns = np.mgrid[0:height, 0:width].astype(np.float32)
    depth = np.full((height, width), 1.0, dtype=np.float32) + rows / height * 0.3
    box = (slice(height // 3, 2 * height // 3), slice(width // 3, 2 * width // 3))
    depth[box] -= 0.1
    points = np.stack([(columns - width / 2) / width * depth, (rows - height / 2) / width * depth,
                       depth], axis=-1)
    points[:5, :5] = np.nan
    colors = np.full((height, width, 3), 120, dtype=np.uint8)
    colors[box] = (200, 40, 40)
    return points, colors


def warm_up_segmenter(segmenter: FrameSegmenter, progress: Progress | None = None) -> None:
    """Run every kernel a frame segmenter uses once, on a small frame (``segmenter`` is used up:
    pass one made for the purpose)."""
    points, colors = sample_organized_frame()
    run_groups([("learning, segmentation and pixel labels",
                 lambda: segmenter.segment_frame(points, colors)),
                ("streamed frames", lambda: segmenter.segment_frame(points, colors))], progress)
