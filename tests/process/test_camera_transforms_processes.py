"""Camera transforms everywhere: with poses, capture publishes the camera's pose, and a run's
.rrd holds it for every frame (the frustum and images sit in the world) with the world's up
axis taken from the poses, stated beside it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gngdt.io.synth.render import render_scene

REPO_ROOT = Path(__file__).resolve().parents[2]
FRAMES = 12


@pytest.mark.timeout(300)
def test_the_rrd_holds_the_walking_camera_in_the_world(tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    rrd = tmp_path / "walk.rrd"
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", f"synth:tabletop_walk:{FRAMES}",
         "--save", str(rrd), "--rate", "0.5"],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=240)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    truth = {frame.index: frame.pose.matrix for frame in render_scene(
        "tabletop_walk", FRAMES, width=16, height=12)}  # the camera path does not depend on size
    poses: dict[int, np.ndarray] = {}
    world: dict[str, object] = {}
    entities = set()
    for chunk in RrdReader(str(rrd)).stream().collect().stream():
        entity, batch = str(chunk.entity_path), chunk.to_record_batch()
        entities.add(entity)
        names = batch.schema.names
        if entity == "/world/camera" and "Transform3D:translation" in names:
            for frame, translation, rotation in zip(
                    batch.column("frame").to_pylist(),
                    batch.column("Transform3D:translation").to_pylist(),
                    batch.column("Transform3D:mat3x3").to_pylist(), strict=True):
                pose = np.eye(4)
                # rerun stores a mat3x3 column-major
                pose[:3, :3] = np.reshape(rotation, (3, 3)).T
                pose[:3, 3] = np.ravel(translation)
                poses[frame] = pose
        elif entity == "/world":
            world.update({name: batch.column(name).to_pylist()[-1] for name in names})
    assert sorted(poses) == list(range(FRAMES)), "a camera pose for every frame"
    for frame, pose in poses.items():
        assert np.allclose(pose, truth[frame], atol=1e-5), frame
    # the frustum (pinhole) and the images under the moving camera
    assert {"/world/camera", "/world/camera/image/rgb", "/world/camera/image/depth"} <= entities
    assert np.ravel(world["up_axis"])[0] == "+Z"  # the scene's world is z up: its poses say so
    assert np.ravel(world["up_from"])[0] == "the camera poses"
