"""A learner among hostile or confused neighbours: impossible stamps, a second learner on its
camera, a checkpoint shared or made for another camera, debris of a killed checkpoint write."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.checkpoints import trained_checkpoint


def test_stale_temporaries_of_one_checkpoint_only_are_removed(tmp_path: Path) -> None:
    from gngdt.io.checkpoints import remove_stale_temporaries

    (tmp_path / ".a.npz.123.tmp").touch()
    (tmp_path / ".b.npz.123.tmp").touch()
    (tmp_path / "a.npz").touch()
    removed = remove_stale_temporaries(tmp_path / "a.npz")
    assert [path.name for path in removed] == [".a.npz.123.tmp"]
    assert sorted(path.name for path in tmp_path.iterdir()) == [".b.npz.123.tmp", "a.npz"]


def test_a_camera_mismatch_is_a_checkpoint_error(tmp_path: Path) -> None:
    from gngdt.core.learner.frame_learner import LearnerConfig
    from gngdt.io.checkpoints import CheckpointError
    from gngdt.services.learner import checkpoints

    path = tmp_path / "left.npz"
    trained_checkpoint(path, camera="left")
    assert checkpoints.resume(path, "left", LearnerConfig()).camera == "left"
    with pytest.raises(CheckpointError, match="--cam left"):
        checkpoints.resume(path, "camera", LearnerConfig())


def test_counters_beyond_64_bits_in_a_checkpoint_are_refused(tmp_path: Path) -> None:
    from gngdt.core import GNGDT
    from gngdt.core.learner.frame_learner import LearnerConfig
    from gngdt.io.checkpoints import CheckpointError, save_checkpoint
    from gngdt.services.learner import checkpoints

    path = tmp_path / "overflowed.npz"
    model = GNGDT(random_state=0)
    save_checkpoint(path, model.get_state(),
                    {"camera": "camera", "counters": {"frames_dropped": 2**64 + 5}})
    with pytest.raises(CheckpointError, match="frames_dropped"):
        checkpoints.resume(path, "camera", LearnerConfig())
