"""Small synthetic recordings for tests, rendered by the virtual Kinect, and the ground truth of
rendered frames (segments, world points)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gngdt.io.frame import Frame


def render_small_recording(directory: Path, scene: str, frames: int, poses: bool = True) -> Path:
    """``directory/<scene>_small.mcap``: ``frames`` 320x240 frames of a synthetic scene, with
    the camera's poses (a map in the world frame) or without (``poses=False``: a static camera,
    learned in its own frame)."""
    from dataclasses import replace

    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = directory / f"{scene}_small.mcap"
    with RecordingWriter(path) as writer:
        for frame in render_scene(scene, frames, width=320, height=240):
            writer.write_frame(frame if poses else replace(frame, pose=None))
    return path


def render_walk(directory: Path, frames: int, width: int, height: int,
                fps: float) -> tuple[Path, list]:
    """``directory/walk.mcap``: ``frames`` frames of the walking camera (``tabletop_walk``) with
    its poses, and the rendered frames."""
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = directory / "walk.mcap"
    rendered = list(render_scene("tabletop_walk", frames, width=width, height=height, fps=fps))
    with RecordingWriter(path) as writer:
        for frame in rendered:
            writer.write_frame(frame)
    return path, rendered


def world_points(frame: Frame, mask: np.ndarray) -> np.ndarray:
    """(M, 3) world points (metres) of the pixels in ``mask`` with valid depth, via the pose."""
    k = frame.intrinsics
    rows, columns = np.nonzero(mask & (frame.depth > 0))
    z = frame.depth[rows, columns] / 1000.0
    camera = np.column_stack([(columns - k.cx) / k.fx * z, (rows - k.cy) / k.fy * z, z])
    pose = frame.pose.matrix
    return camera @ pose[:3, :3].T + pose[:3, 3]


def segment_mask(frame: Frame, name: str) -> np.ndarray:
    """(H, W) bool: the pixels of ``frame``'s segment ``name`` (one must exist)."""
    ids = [i for i, segment in frame.extras["segments"].items() if segment == name]
    assert ids, f"no segment {name!r} in {sorted(frame.extras['segments'].values())}"
    return np.isin(frame.labels, ids)
