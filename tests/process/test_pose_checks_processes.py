"""`gngdt run` on a recording whose poses contradict its depth (issue 24.1): the learner counts
and skips those frames, the summary says why, and the run exits non-zero."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from gngdt.core.sensor.geometry import matrix_to_pose, pose_to_matrix
from gngdt.io.frame import CameraPose

REPO_ROOT = Path(__file__).resolve().parents[2]


def walk_recording(path: Path, misread=None) -> Path:
    """30 frames of the virtual walk (160x120) with their poses, or ``misread`` ones."""
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    with RecordingWriter(path) as writer:
        for frame in render_scene("tabletop_walk", 30, width=160, height=120):
            if misread is not None:
                frame = replace(frame, pose=CameraPose(misread(frame.pose.matrix), "world"))
            writer.write_frame(frame)
    return path


def written_w_first(pose):
    translation, (x, y, z, w) = matrix_to_pose(pose)
    return pose_to_matrix(translation, [w, x, y, z])


def run(recording: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(recording), "--rate", "2",
         "--samples-per-frame", "2000", "--save", str(tmp_path / "run.rrd")],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=240)


@pytest.mark.timeout(300)
def test_a_run_whose_poses_contradict_their_depth_says_why_and_fails(tmp_path: Path) -> None:
    completed = run(walk_recording(tmp_path / "wxyz.mcap", written_w_first), tmp_path)
    assert completed.returncode == 3, completed.stdout + completed.stderr  # the learner's no
    assert "poses rejected:" in completed.stdout and "contradicts the depth" in completed.stdout
    assert "most frames were not learned" in completed.stderr
    assert "Traceback" not in completed.stdout + completed.stderr


@pytest.mark.timeout(300)
def test_the_same_walk_with_its_poses_runs_clean(tmp_path: Path) -> None:
    completed = run(walk_recording(tmp_path / "walk.mcap"), tmp_path)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "poses rejected" not in completed.stdout
