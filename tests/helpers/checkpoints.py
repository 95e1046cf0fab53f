"""Learner checkpoints for the tests: a small trained network saved as a learner saves it."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def trained_checkpoint(path: Path, camera: str = "camera", samples: int = 500) -> None:
    """``path``: the checkpoint of camera ``camera``'s network after ``samples`` learning steps
    on as many random points (seeded)."""
    from gngdt.core import GNGDT
    from gngdt.io.checkpoints import save_checkpoint

    rng = np.random.default_rng(0)
    model = GNGDT(random_state=0).partial_fit(
        rng.random((samples, 3), dtype=np.float32),
        rng.integers(0, 256, (samples, 3), np.uint8), n_steps=samples)
    save_checkpoint(path, model.get_state(), {"camera": camera, "counters": {}})
