"""Rehearsal (``replay_share``): a memory of earlier batches, kept current by what the sensor sees
through, and a network that learns the world seen so far from it."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.forgetting_scenes import FORGETTING, PARAMS, STEPS, frames_of, to_world
from scipy.spatial import cKDTree

from gngdt.core import GNGDT
from gngdt.core.gas.rehearsal import SampleMemory
from gngdt.core.sensor.view import SensorView

#: the learner's rehearsal (gngdt.services.learner.LEARNER_MODEL_DEFAULTS)
REHEARSAL = {"replay_share": 0.3}


def wall(z: float, size: int, rng: np.random.Generator, half_width: float = 1.0) -> np.ndarray:
    """(size, 3) points of a wall facing the camera at depth ``z`` (camera frame)."""
    xy = rng.uniform(-half_width, half_width, (size, 2)) * z
    return np.column_stack([xy, np.full(size, z)])


def test_the_memory_is_a_uniform_sample_of_every_batch_offered():
    memory, rng = SampleMemory(2_000), np.random.default_rng(0)
    for batch in range(10):  # 1,000 samples each; the batch number rides in the colour
        points = rng.random((1_000, 3))
        memory.offer(points, np.full((1_000, 3), float(batch)), rng)
    assert memory.count == 2_000 and memory.offered == 10_000
    shares = np.bincount(memory.colors[:, 0].astype(int), minlength=10) / memory.count
    assert np.all(np.abs(shares - 0.1) < 0.03), shares  # binomial std 0.0067


def test_the_memory_drops_what_the_sensor_saw_through_and_keeps_the_rest():
    """A box 1.5 m away in front of a wall at 3 m is remembered; the next view shows the wall
    alone: the box's samples go; the wall's, those behind it and those out of view stay."""
    rng = np.random.default_rng(1)
    box = wall(1.5, 500, rng, half_width=0.1)
    on_wall, behind = wall(3.0, 500, rng), wall(4.0, 500, rng)
    aside = box + np.array([10.0, 0.0, 0.0])  # far off the image
    remembered = np.concatenate([box, on_wall, behind, aside])
    memory = SampleMemory(len(remembered))
    memory.offer(remembered, None, rng)
    view = SensorView.of(wall(3.0, 20_000, rng))
    assert memory.carve(view, np.eye(4), margin=0.05) == len(box)
    kept = memory.positions
    assert len(kept) == 1_500 and cKDTree(kept).query(box)[0].min() > 0.1
    # seen from a pose: the same wall, camera 1 m to the right in the world
    pose = np.eye(4)
    pose[0, 3] = 1.0
    memory = SampleMemory(len(remembered))
    memory.offer(remembered + pose[:3, 3], None, rng)
    camera_from_world = np.linalg.inv(pose)
    assert memory.carve(view, camera_from_world, margin=0.05) == len(box)


def test_rehearsal_learns_the_world_seen_so_far():
    """The walking camera passes the crate, the table and the bin, and back: a network that
    learns only the current frame fits the view, and what left it keeps the nodes its last view
    placed; rehearsing earlier frames fits everything seen (error 0.80-0.83 of frame-only
    learning over seeds 0-3)."""
    frames = list(frames_of("tabletop_walk", 49, fps=6.0))  # 8 s: out and back
    params = {**PARAMS, "max_nodes": 200}
    models = {"frame only": GNGDT(**params, **FORGETTING),
              "rehearsal": GNGDT(**params, **FORGETTING, **REHEARSAL)}
    for points, colors, pose, _, _ in frames:
        for model in models.values():
            model.partial_fit(points, colors, n_steps=STEPS, camera_pose=pose)
    seen = np.concatenate([to_world(points[::7], pose) for points, _, pose, _, _ in frames])
    errors = {name: float(np.sqrt(np.mean(cKDTree(model.positions_).query(seen)[0] ** 2)))
              for name, model in models.items()}
    assert errors["rehearsal"] < 0.9 * errors["frame only"], errors
    rehearsing = models["rehearsal"]
    assert rehearsing.n_steps_ == models["frame only"].n_steps_ == 49 * STEPS
    assert 0 < rehearsing._memory.count <= rehearsing.replay_points


def camera_at(x: float) -> np.ndarray:
    """(4, 4) camera-to-world pose: the camera ``x`` metres to the right, looking along z."""
    pose = np.eye(4)
    pose[0, 3] = x
    return pose


def test_rehearsal_continues_exactly_from_a_checkpoint_and_is_off_by_default():
    rng = np.random.default_rng(2)
    frames = [(wall(2.0, 3_000, rng), rng.uniform(0, 255, (3_000, 3)), camera_at(0.2 * k))
              for k in range(4)]
    model = GNGDT(max_nodes=100, random_state=0, **FORGETTING, **REHEARSAL, replay_points=5_000)
    for points, colors, pose in frames[:2]:
        model.partial_fit(points, colors, n_steps=4_000, camera_pose=pose)
    restored = GNGDT.from_state(model.get_state())
    for points, colors, pose in frames[2:]:
        model.partial_fit(points, colors, n_steps=4_000, camera_pose=pose)
        restored.partial_fit(points, colors, n_steps=4_000, camera_pose=pose)
    assert model._memory.count > 0
    assert np.array_equal(model.positions_, restored.positions_)
    assert np.array_equal(model._memory.positions, restored._memory.positions)
    state = model.get_state()
    state["memory_positions"] = np.zeros((6_000, 3))
    with pytest.raises(ValueError, match="replay_points"):
        GNGDT.from_state(state)
    del state["memory_colors"]
    with pytest.raises(ValueError, match="memory_colors"):
        GNGDT.from_state(state)
    # off (the paper's default), or without poses (no fixed frame to remember in): the same
    # network as before rehearsal existed
    points, colors, pose = frames[1]
    plain = GNGDT(max_nodes=100, random_state=0).fit(points, colors, 6_000, camera_pose=pose)
    zero = GNGDT(max_nodes=100, random_state=0, replay_share=0.0).fit(
        points, colors, 6_000, camera_pose=pose)
    assert np.array_equal(plain.positions_, zero.positions_) and plain._memory is None
    unposed = GNGDT(max_nodes=100, random_state=0, **REHEARSAL)
    plain = GNGDT(max_nodes=100, random_state=0)
    for points, colors, _ in frames:
        unposed.partial_fit(points, colors, n_steps=4_000)
        plain.partial_fit(points, colors, n_steps=4_000)
    assert unposed._memory.count == 0
    assert np.array_equal(plain.positions_, unposed.positions_)


def test_rehearsal_parameters_are_validated():
    for bad in ({"replay_share": 1.0}, {"replay_share": -0.1}, {"replay_points": 0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            GNGDT(**bad).check_params()
