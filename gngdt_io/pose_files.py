"""Camera poses from files, for ``gngdt record images --poses``.

Every pose is camera-to-world (the camera's pose in the fixed frame ``world``), as TUM RGB-D,
7-Scenes, Redwood and most RGB-D data sets ship them. Accepted layouts:

- a **TUM trajectory** file: ``timestamp tx ty tz qx qy qz qw`` per line (``#`` comments, commas
  also separate numbers); each frame's pose is interpolated at the frame's stamp
  (:class:`~gngdt_io.tf_tree.TransformTree`), and a frame outside the trajectory's
  span is an error;
- a file with ``tx ty tz qx qy qz qw`` per line, no timestamp: one pose per frame, in order;
- a **folder** of per-frame files (``pose/NNNNNN.txt``, taken in name order), each holding a 4x4
  camera-to-world matrix (16 numbers, row by row) or one ``tx ty tz qx qy qz qw`` line.

Quaternions are (x, y, z, w); one whose norm is off by more than tf2's tolerance is an error (a
sign of a different field order), nearly-unit ones are normalised. Matrices must be rigid.
A file or folder with fewer poses than frames is an error; with more, a warning.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from gngdt_core.geometry import TransformError, matrix_to_pose, pose_to_matrix
from gngdt_io.errors import RecordingError
from gngdt_io.frame import DEFAULT_FIXED_FRAME, CameraPose, Frame
from gngdt_io.tf_tree import TransformTree

__all__ = ["PoseFile", "attach_poses", "load_poses"]

logger = logging.getLogger(__name__)

#: a trajectory's first/last pose may serve a frame this far outside its span (TUM's
#: associate.py pairs stamps up to 20 ms apart)
TRAJECTORY_TOLERANCE_NS = 20_000_000
#: largest deviation of a pose matrix's rotation from orthonormal, and of its last row
MATRIX_TOLERANCE = 1e-3
_SEPARATORS = re.compile(r"[\s,]+")


@dataclass
class PoseFile:
    """Poses read from ``path``: either a trajectory (``stamps_ns`` (N,) int64 with the matrices)
    or a sequence, one per frame (``stamps_ns`` None). ``matrices``: (N, 4, 4) float64."""

    path: Path
    matrices: np.ndarray
    stamps_ns: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.matrices)


def _numbers(text: str, where: str) -> list[Decimal]:
    """The numbers on one line, exactly (a TUM timestamp has more digits than a float keeps)."""
    try:
        return [Decimal(token) for token in _SEPARATORS.split(text.strip()) if token]
    except InvalidOperation as error:
        raise RecordingError(where, None, f"not a list of numbers: {text.strip()!r}") from error


def _pose_from_seven(values: list[Decimal], where: str) -> np.ndarray:
    numbers = [float(value) for value in values]
    try:
        return pose_to_matrix(numbers[:3], numbers[3:7], "pose")
    except TransformError as error:
        raise RecordingError(
            where, None, f"{error} (expected tx ty tz qx qy qz qw, TUM order)"
        ) from error


def _rigid_matrix(values: list[Decimal], where: str) -> np.ndarray:
    matrix = np.array([float(value) for value in values]).reshape(4, 4)
    rotation = matrix[:3, :3]
    if (
        not np.isfinite(matrix).all()
        or np.abs(matrix[3] - [0.0, 0.0, 0.0, 1.0]).max() > MATRIX_TOLERANCE
        or np.abs(rotation @ rotation.T - np.eye(3)).max() > MATRIX_TOLERANCE
        or np.linalg.det(rotation) < 0
    ):
        raise RecordingError(where, None, "not a rigid 4x4 camera-to-world matrix")
    matrix[3] = [0.0, 0.0, 0.0, 1.0]
    return matrix


def _read_pose_file(path: Path) -> PoseFile:
    rows: list[tuple[str, list[Decimal]]] = []
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise RecordingError(path, None, f"cannot read poses: {error}") from error
    for number, line in enumerate(lines, start=1):
        if line.strip() and not line.lstrip().startswith("#"):
            where = f"{path}:{number}"
            rows.append((where, _numbers(line, where)))
    if not rows:
        raise RecordingError(path, None, "no poses in the file")
    widths = {len(values) for _, values in rows}
    if widths == {16} or (widths == {4} and len(rows) == 4):  # a single 4x4 matrix
        return PoseFile(path, _rigid_matrix([v for _, row in rows for v in row], str(path))[None])
    width = len(rows[0][1])
    for where, values in rows:
        if len(values) != width or width not in (7, 8):
            raise RecordingError(
                where, None,
                f"expected 8 numbers (timestamp tx ty tz qx qy qz qw) or 7 (tx ty tz qx qy qz "
                f"qw) on every line, got {len(values)}",
            )
    timestamped = width == 8
    matrices = np.stack([_pose_from_seven(v[1:] if timestamped else v, w) for w, v in rows])
    if not timestamped:
        return PoseFile(path, matrices)
    stamps = np.array([int(v[0] * 1_000_000_000) for _, v in rows], dtype=np.int64)
    return PoseFile(path, matrices, stamps)


def _natural_key(path: Path) -> tuple:
    return tuple(int(part) if part.isdigit() else part
                 for part in re.split(r"(\d+)", path.name))


def load_poses(path: str | Path) -> PoseFile:
    """Read a pose file or folder (see the module docstring); ``RecordingError`` naming the file
    and line for anything unreadable."""
    path = Path(path)
    if path.is_dir():
        files = sorted((p for p in path.iterdir() if p.suffix == ".txt"), key=_natural_key)
        if not files:
            raise RecordingError(path, None, "no .txt pose files in the folder")
        poses = [_read_pose_file(file) for file in files]
        for file, pose in zip(files, poses, strict=True):
            if len(pose) != 1 or pose.stamps_ns is not None:
                raise RecordingError(
                    file, None, "a per-frame pose file holds one pose (a 4x4 matrix or "
                    "tx ty tz qx qy qz qw)")
        return PoseFile(path, np.concatenate([pose.matrices for pose in poses]))
    if not path.is_file():
        raise RecordingError(path, None, "no such pose file or folder")
    return _read_pose_file(path)


def attach_poses(frames: Iterable[Frame], poses: PoseFile, frame_count: int) -> Iterator[Frame]:
    """``frames`` with their pose in ``world``. ``frame_count`` (how many frames will come) is
    checked against a per-frame sequence at once, before any frame is read: fewer poses than
    frames is a ``RecordingError``, more a warning."""
    if poses.stamps_ns is None:
        if len(poses) < frame_count:
            raise RecordingError(
                poses.path, None,
                f"{len(poses)} poses for {frame_count} frames; a per-frame pose list needs one "
                f"pose per frame, in frame order")
        if len(poses) > frame_count:
            logger.warning("%s: %d poses for %d frames; the last %d are not used", poses.path,
                           len(poses), frame_count, len(poses) - frame_count)
        return (replace(frame, pose=CameraPose(matrix, DEFAULT_FIXED_FRAME))
                for frame, matrix in zip(frames, poses.matrices, strict=False))
    trajectory = TransformTree(max_extrapolation_ns=TRAJECTORY_TOLERANCE_NS)
    for stamp, matrix in zip(poses.stamps_ns, poses.matrices, strict=True):
        translation, rotation = matrix_to_pose(matrix)
        trajectory.add(DEFAULT_FIXED_FRAME, "camera", int(stamp), translation, rotation)
    return _interpolated(frames, trajectory, poses.path)


def _interpolated(frames: Iterable[Frame], trajectory: TransformTree, path: Path
                  ) -> Iterator[Frame]:
    for frame in frames:
        try:
            matrix = trajectory.lookup(DEFAULT_FIXED_FRAME, "camera", frame.timestamp_ns)
        except TransformError as error:
            raise RecordingError(path, frame.index, f"no pose for this frame: {error}") from error
        yield replace(frame, pose=CameraPose(matrix, DEFAULT_FIXED_FRAME))
