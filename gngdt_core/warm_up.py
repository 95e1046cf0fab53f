"""Compile the numba kernels before the first frame, one group at a time, saying how far it got.

numba compiles a kernel on its first call and, with ``cache=True``, writes each one to its disk
cache as soon as that kernel is compiled: the first run on a machine pays the compilation (15-40 s
on 2 cores, most of it the learning loop), later runs load the cache in well under a second, and
a run stopped midway keeps every kernel it finished. Running the groups here, before any frame,
keeps compilation out of the first frame's latency and lets a supervisor (`gngdt run`) see
progress instead of silence.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gngdt_core.frame_learner import FrameLearner, LearnerConfig

#: progress(done, total, what): called before each group, and once at the end (done == total)
Progress = Callable[[int, int, str], None]


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
    positions, colors, pose = sample_frame()
    learner = FrameLearner("warm-up", config)
    groups: list[tuple[str, Callable[[], object]]] = [
        ("learning loop", lambda: learner.learn(positions, colors, "world", pose)),
        ("nearest nodes", lambda: learner.quantization_error(positions, colors)),
        ("normals and segmentation", learner.learned_frame),
        ("sensor view", lambda: learner.measure_ghosts(positions, pose)),
    ]
    run_groups(groups, progress)
    return learner


def run_groups(groups: list[tuple[str, Callable[[], object]]],
               progress: Progress | None = None) -> None:
    """Call each group's function in turn, reporting progress before each and at the end."""
    for done, (what, call) in enumerate(groups):
        if progress is not None:
            progress(done, len(groups), what)
        call()
    if progress is not None:
        progress(len(groups), len(groups), "done")
