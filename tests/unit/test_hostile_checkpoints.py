"""Checkpoints whose arrays are finite but hold nothing a learner makes (issue 38): colours at
1e300 (loaded and learned from before, with overflow warnings), normals five units long, a
negative error, a camera or a tracker 1e18 m away. Every array is checked before use; the file
is refused, naming the array. Each file is written with a valid digest, as anyone who may write
the checkpoint could."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gngdt.core import GNGDT
from gngdt.core.learner.frame_learner import LearnerConfig, LearnerOptions
from gngdt.io.checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from gngdt.services.learner import checkpoints


@pytest.fixture(scope="module")
def learned_state() -> dict[str, np.ndarray]:
    """A learner-profile network (forgetting and rehearsal) after three posed frames of 8-bit
    colours."""
    rng = np.random.default_rng(0)
    model = GNGDT(max_nodes=60, lambda_=100, utility_k=1000.0, replay_share=0.3,
                  random_state=0)
    for x in (0.0, 0.1, 0.2):
        pose = np.eye(4)
        pose[0, 3] = x
        model.partial_fit(rng.uniform([-0.5, -0.4, 2.0], [0.5, 0.4, 2.0], (2000, 3)),
                          rng.integers(0, 256, (2000, 3)), n_steps=3000, camera_pose=pose)
    return model.get_state()


def resume(path: Path, state: dict, config: LearnerConfig | None = None):
    save_checkpoint(path, state, {"camera": "camera", "counters": {}})
    return checkpoints.resume(path, "camera", config or LearnerConfig())


def changed(state: dict, key: str, change) -> dict:
    state = {name: value.copy() for name, value in state.items()}
    state[key] = change(state[key])
    return state


def first_set(value: float):
    def change(array: np.ndarray) -> np.ndarray:
        array.reshape(-1)[0] = value
        return array
    return change


def test_a_good_checkpoint_resumes(tmp_path: Path, learned_state) -> None:
    assert resume(tmp_path / "good.npz", learned_state).model.n_nodes_ == 60


@pytest.mark.parametrize(("key", "value", "said"), [
    ("memory_colors", 1e300, "remembered colours lie outside 8-bit RGB"),
    ("memory_colors", -5.0, "remembered colours lie outside 8-bit RGB"),
    ("col", 1e300, "node colours lie outside 8-bit RGB"),
    ("nor", 5.0, "longer than a unit normal"),
    ("err", -1.0, r"\['err'\] must be non-negative"),
])
def test_an_array_beyond_what_a_learner_makes_is_refused(tmp_path: Path, learned_state,
                                                         key: str, value: float,
                                                         said: str) -> None:
    state = changed(learned_state, key, first_set(value))
    with pytest.raises(CheckpointError, match=said):
        resume(tmp_path / "crafted.npz", state)


def test_a_camera_pose_beyond_the_workspace_is_refused(tmp_path: Path, learned_state) -> None:
    state = changed(learned_state, "camera_pose", lambda pose: np.where(
        np.arange(16).reshape(4, 4) == 3, 1e18, pose))
    with pytest.raises(CheckpointError, match="camera poses lie beyond the workspace"):
        resume(tmp_path / "far_camera.npz", state)


def tracked_checkpoint(path: Path) -> dict[str, np.ndarray]:
    """A tracking learner's checkpoint (after one frame), its state as saved."""
    from gngdt.core.learner.frame_learner import FrameLearner

    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(
        track=True, samples_per_frame=2000, first_frame_steps=5000)))
    rng = np.random.default_rng(1)
    wall = np.column_stack([rng.uniform(-1, 1, 4000), rng.uniform(-0.7, 0.7, 4000),
                            np.full(4000, 2.0)]).astype(np.float32)
    learner.learn(wall, rng.integers(0, 256, (4000, 3)).astype(np.uint8), stamp_ns=1)
    assert checkpoints.save(learner, path)
    state, _ = load_checkpoint(path)
    assert "tracker_pose" in state
    return state


@pytest.mark.parametrize("key", ["tracker_pose", "tracker_plane_points"])
def test_a_tracker_beyond_the_workspace_is_refused(tmp_path: Path, key: str) -> None:
    state = tracked_checkpoint(tmp_path / "tracked.npz")
    config = LearnerConfig(options=LearnerOptions(track=True))
    assert checkpoints.resume(tmp_path / "tracked.npz", "camera", config).tracking is not None
    if key == "tracker_plane_points" and state[key].size == 0:
        state[key] = np.full((1, 2, 3), 1e18)
        state["tracker_plane_ids"] = np.array([0])
        state["tracker_plane_counts"] = np.ones((1, 2))
        state["tracker_plane_spread"] = np.zeros((1, 2))
    else:
        state = changed(state, key, first_set(1e18) if key != "tracker_pose" else (
            lambda pose: np.where(np.arange(16).reshape(4, 4) == 3, 1e18, pose)))
    with pytest.raises(CheckpointError, match="beyond the workspace"):
        resume(tmp_path / "crafted.npz", state, config)
