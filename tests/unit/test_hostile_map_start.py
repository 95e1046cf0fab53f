"""A tracked map is not started from noise (issue 38): before, the first of a recording's random
depth frames (`gngdt run noise.mcap --track`) became an 11,279-node map the tracker then aligned
everything to. A cloud whose depth image holds no smooth surfaces is not learned, counted as
lost by the tracker, and the next cloud may start the map; read back, the map holds only it."""

from __future__ import annotations

import numpy as np

from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig, LearnerOptions
from gngdt.core.learner.results import Outcome
from gngdt.core.sensor.geometry import CameraIntrinsics

CAMERA = CameraIntrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)


def cloud(depth_mm: np.ndarray) -> np.ndarray:
    """(N, 3) float32 metres: the depth image's pixels deprojected with ``CAMERA``."""
    rows, cols = np.nonzero(depth_mm)
    z = depth_mm[rows, cols] / 1000.0
    return np.column_stack([(cols - CAMERA.cx) / CAMERA.fx * z,
                            (rows - CAMERA.cy) / CAMERA.fy * z, z]).astype(np.float32)


def colours(count: int) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (count, 3), dtype=np.uint8)


def test_noise_starts_no_map_and_a_scene_after_it_does() -> None:
    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(
        track=True, samples_per_frame=2000, first_frame_steps=5000)))
    rng = np.random.default_rng(1)
    for index in range(3):
        noise = cloud(rng.integers(500, 5000, (120, 160)).astype(np.uint16))
        result = learner.learn(noise, colours(len(noise)), camera=CAMERA,
                               stamp_ns=index * 33_000_000)
        assert result.outcome is Outcome.LOST_TRACKING
        assert "no smooth surfaces" in result.problem
        assert learner.model is None or learner.model.n_nodes_ == 0  # nothing learned
    assert learner.counters.frames_lost_tracking == 3
    wall = cloud(np.tile(np.linspace(1500, 1700, 160), (120, 1)).astype(np.uint16))
    assert learner.learn(wall, colours(len(wall)), camera=CAMERA,
                         stamp_ns=99_000_000).outcome is Outcome.LEARNED
    nodes = learner.model.positions_
    assert len(nodes) > 2 and nodes[:, 2].min() > 1.4 and nodes[:, 2].max() < 1.8


def test_a_sparse_or_uncalibrated_cloud_is_not_judged() -> None:
    """Without intrinsics (or with too few neighbouring pixels) nothing can be said: it starts
    the map as before."""
    from gngdt.core.learner.frame_learner import implausible_start

    rng = np.random.default_rng(2)
    noise = cloud(rng.integers(500, 5000, (120, 160)).astype(np.uint16))
    assert implausible_start(noise, None) == ""
    assert implausible_start(noise[::50], CAMERA) == ""
    assert "no smooth surfaces" in implausible_start(noise, CAMERA)
