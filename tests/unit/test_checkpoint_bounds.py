"""Checkpoints validated before use (issue 24.1, 24.5): versions, dtypes, counters and the
rehearsal memory within bounds, a read-only folder a clear error. Each file here is written
with a valid digest, as anyone who may write the checkpoint could."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from gngdt.core import GNGDT
from gngdt.core.gas.rehearsal import MAX_OFFERED, SampleMemory
from gngdt.core.learner.frame_learner import LearnerConfig
from gngdt.io.checkpoints import CheckpointError, CheckpointLock, save_checkpoint
from gngdt.services.learner import checkpoints

#: a folder no process may create files in: sysfs refuses regular files, even to root
READ_ONLY = Path("/sys/fs")


@pytest.fixture(scope="module")
def learned_state() -> dict[str, np.ndarray]:
    """A learner-profile network (forgetting and rehearsal) after three posed frames."""
    rng = np.random.default_rng(0)
    model = GNGDT(max_nodes=60, lambda_=100, utility_k=1000.0, replay_share=0.3,
                  random_state=0)
    for x in (0.0, 0.1, 0.2):
        points = rng.uniform([-0.5, -0.4, 2.0], [0.5, 0.4, 2.0], (2000, 3))
        pose = np.eye(4)
        pose[0, 3] = x
        model.partial_fit(points, rng.integers(0, 256, (2000, 3)), n_steps=3000,
                          camera_pose=pose)
    state = model.get_state()
    assert len(state["memory_positions"]) > 0
    return state


def resume(tmp_path: Path, state: dict, counters: dict | None = None):
    path = tmp_path / "learner.npz"
    save_checkpoint(path, state, {"camera": "camera", "counters": counters or {}})
    return checkpoints.resume(path, "camera", LearnerConfig())


def test_a_good_checkpoint_resumes(tmp_path: Path, learned_state) -> None:
    assert resume(tmp_path, learned_state).model.n_nodes_ == 60


@pytest.mark.parametrize(("change", "message"), [
    ({"version": np.array(99)}, "state version 99"),
    ({"version": np.array("4")}, "'version'.* integer"),
    ({"memory_offered": np.array(2**63 - 10)}, "memory_offered"),
    ({"counters": "steps beyond"}, "beyond 2\\*\\*62"),
    ({"memory_positions": "1e18"}, "remembered samples lie beyond the workspace of 1000 m"),
    ({"pos": "1e18"}, "nodes lie beyond the workspace"),
    ({"memory_positions": "float16"}, "float32 or float64"),
    ({"pos": "float16"}, "float32 or float64"),
])
def test_a_checkpoint_out_of_bounds_is_refused(tmp_path: Path, learned_state, change: dict,
                                               message: str) -> None:
    state = dict(learned_state)
    for key, value in change.items():
        if isinstance(value, np.ndarray):
            state[key] = value
        elif value == "1e18":
            state[key] = state[key].copy()
            state[key][0] = 1e18
        elif value == "float16":
            state[key] = state[key].astype(np.float16)
        elif value == "steps beyond":
            state[key] = state[key].copy()
            state[key][1] = 2**62 + 1
    with pytest.raises(CheckpointError, match=message):
        resume(tmp_path, state)


@pytest.mark.parametrize("value", [2**63 - 10, float("inf"), float("nan")])
def test_learner_counters_near_their_end_or_not_finite_are_refused(
        tmp_path: Path, learned_state, value) -> None:
    with pytest.raises(CheckpointError, match=r"frames_used|learning_seconds"):
        resume(tmp_path, learned_state, {
            "frames_used" if isinstance(value, int) else "learning_seconds": value})


def test_the_memory_counter_saturates() -> None:
    memory = SampleMemory(4)
    memory.restore(np.zeros((4, 3)), np.zeros((4, 3)), MAX_OFFERED - 1)
    memory.offer(np.ones((10, 3)), None, np.random.default_rng(0))
    assert memory.offered == MAX_OFFERED


def test_a_checkpoint_in_a_read_only_folder_is_a_clear_error(caplog) -> None:
    from gngdt.services.learner import add_arguments, main

    with pytest.raises(CheckpointError, match=r"cannot be written.*writable folder"):
        CheckpointLock(READ_ONLY / "gngdt" / "learner.npz").acquire()
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    # refused before any session is opened: no router needed
    assert main(parser.parse_args(["--checkpoint", str(READ_ONLY / "learner.npz")])) == 2
    assert "cannot be written" in caplog.text
