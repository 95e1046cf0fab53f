"""Camera poses from files, for ``gngdt record images --poses``.

Every pose is camera-to-world (the camera's pose in the fixed frame ``world``), as TUM RGB-D,
7-Scenes, Redwood and most RGB-D data sets ship them. Accepted layouts:

- a **TUM trajectory** file: ``timestamp tx ty tz qx qy qz qw`` per line (``#`` comments, commas
  also separate numbers); each frame's pose is interpolated at the frame's stamp
  (:class:`~gngdt.io.tf_tree.TransformTree`), and a frame outside the trajectory's
  span is an error;
- a file with ``tx ty tz qx qy qz qw`` per line, no timestamp: one pose per frame, in order;
- a **folder** of per-frame files (``pose/NNNNNN.txt``, taken in name order), each holding a 4x4
  camera-to-world matrix (16 numbers, row by row) or one ``tx ty tz qx qy qz qw`` line.

Quaternions are (x, y, z, w); one whose norm is off by more than tf2's tolerance is an error (a
sign of a different field order), nearly-unit ones are normalised. Matrices must be rigid.
A file or folder with fewer poses than frames is an error; with more, a warning. Files are read
as a stream, line by line: at most ``MAX_POSES`` (1,000,000) poses and ``MAX_LINE_CHARS`` a
line; every number must be finite and every stamp fit a 64-bit count of nanoseconds.
"""

from __future__ import annotations

import logging
import re
from array import array
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from gngdt.core.odometry.pose_checks import PoseLimits
from gngdt.core.sensor.geometry import (
    QUATERNION_TOLERANCE,
    TransformError,
    matrix_to_pose,
    pose_to_matrix,
    quaternions_to_rotations,
)
from gngdt.io.errors import RecordingError
from gngdt.io.frame import DEFAULT_FIXED_FRAME, CameraPose, Frame
from gngdt.io.tf_tree import TransformTree

__all__ = ["PoseFile", "attach_poses", "load_poses"]

logger = logging.getLogger(__name__)

#: a trajectory's first/last pose may serve a frame this far outside its span (TUM's
#: associate.py pairs stamps up to 20 ms apart)
TRAJECTORY_TOLERANCE_NS = 20_000_000
#: largest deviation of a pose matrix's rotation from orthonormal, and of its last row (the
#: learner's own tolerance, `PoseLimits.rotation_tolerance`)
MATRIX_TOLERANCE = PoseLimits().rotation_tolerance
#: most poses read from a file or folder (~128 MB of matrices; 2.8 hours of a 100 Hz
#: trajectory), and the longest line of a pose file
MAX_POSES = 1_000_000
MAX_LINE_CHARS = 4096
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
    """The numbers on one line, exactly (a TUM timestamp has more digits than a float keeps);
    each must be finite."""
    try:
        numbers = [Decimal(token) for token in _SEPARATORS.split(text.strip()) if token]
    except InvalidOperation as error:
        raise RecordingError(where, None, f"not a list of numbers: {text.strip()!r}") from error
    if not all(number.is_finite() for number in numbers):
        raise RecordingError(where, None, f"not finite numbers: {text.strip()!r}")
    return numbers


def _stamp_ns(seconds: Decimal, where: str) -> int:
    """A trajectory stamp (seconds) as nanoseconds; it must fit a signed 64-bit stamp."""
    nanoseconds = int(seconds * 1_000_000_000)
    if not 0 <= nanoseconds < 2**63:
        raise RecordingError(where, None, f"timestamp {seconds} s is outside 0 .. 2**63 ns")
    return nanoseconds


def _pose_from_seven(values: list, where: str) -> np.ndarray:
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


def _rows(path: Path) -> Iterator[tuple[str, list[Decimal]]]:
    """(where, numbers) of every line of a pose file holding numbers, read as a stream: at most
    ``MAX_LINE_CHARS`` a line and ``MAX_POSES`` such lines."""
    count = 0
    try:
        with open(path, encoding="utf-8") as file:
            for number, line in enumerate(iter(lambda: file.readline(MAX_LINE_CHARS + 1), ""),
                                          start=1):
                where = f"{path}:{number}"
                if len(line) > MAX_LINE_CHARS:
                    raise RecordingError(where, None, f"a line longer than {MAX_LINE_CHARS} "
                                         "characters; not a pose file")
                if not line.strip() or line.lstrip().startswith("#"):
                    continue
                count += 1
                if count > MAX_POSES:
                    raise RecordingError(path, None, f"more than {MAX_POSES:,} poses (the "
                                         "limit); split the trajectory or thin it out")
                yield where, _numbers(line, where)
    except (OSError, UnicodeDecodeError) as error:
        raise RecordingError(path, None, f"cannot read poses: {error}") from error


def _read_pose_file(path: Path) -> PoseFile:
    values = array("d")  # tx ty tz qx qy qz qw of each pose, compactly
    stamps = array("q")
    lines = array("q")
    width = None
    matrix_values: list[Decimal] = []
    for where, numbers in _rows(path):
        if width is None:
            width = len(numbers)
        if width in (16, 4):  # a single 4x4 matrix, on one line or four
            matrix_values += numbers
            if len(matrix_values) > 16 or len(numbers) != width:
                raise RecordingError(where, None, "a 4x4 matrix file holds 16 numbers")
            continue
        if len(numbers) != width or width not in (7, 8):
            raise RecordingError(
                where, None,
                f"expected 8 numbers (timestamp tx ty tz qx qy qz qw) or 7 (tx ty tz qx qy qz "
                f"qw) on every line, got {len(numbers)}",
            )
        if width == 8:
            stamps.append(_stamp_ns(numbers[0], where))
        values.extend(float(number) for number in numbers[-7:])
        lines.append(int(where.rsplit(":", 1)[1]))
    if width is None:
        raise RecordingError(path, None, "no poses in the file")
    if width in (16, 4):
        if len(matrix_values) != 16:
            raise RecordingError(path, None, "a 4x4 matrix file holds 16 numbers")
        return PoseFile(path, _rigid_matrix(matrix_values, str(path))[None])
    matrices = _poses_from_rows(np.frombuffer(values, dtype=np.float64).reshape(-1, 7), path,
                                np.frombuffer(lines, dtype=np.int64))
    if width == 7:
        return PoseFile(path, matrices)
    return PoseFile(path, matrices, np.frombuffer(stamps, dtype=np.int64).copy())


def _poses_from_rows(rows: np.ndarray, path: Path, lines: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses of (N, 7) rows tx ty tz qx qy qz qw; the first row whose quaternion is
    not unit is an error naming its line (as `_pose_from_seven` words it)."""
    quaternions = rows[:, 3:]
    norms = np.sqrt(np.einsum("ij,ij->i", quaternions, quaternions))
    bad = np.flatnonzero(np.abs(norms * norms - 1.0) > QUATERNION_TOLERANCE)
    if bad.size:
        row = int(bad[0])
        _pose_from_seven(list(rows[row]),
                         f"{path}:{int(lines[row])}")
    matrices = np.zeros((len(rows), 4, 4))
    matrices[:, :3, :3] = quaternions_to_rotations(quaternions / norms[:, None])
    matrices[:, :3, 3] = rows[:, :3]
    matrices[:, 3, 3] = 1.0
    return matrices


def _natural_key(path: Path) -> tuple:
    return tuple(int(part) if part.isdigit() else part
                 for part in re.split(r"(\d+)", path.name))


def load_poses(path: str | Path) -> PoseFile:
    """Read a pose file or folder (see the module docstring); ``RecordingError`` naming the file
    and line for anything unreadable."""
    path = Path(path)
    if path.is_dir():
        files = sorted((p for p in path.iterdir() if p.suffix == ".txt" and p.is_file()),
                       key=_natural_key)
        if not files:
            raise RecordingError(path, None, "no .txt pose files in the folder")
        if len(files) > MAX_POSES:
            raise RecordingError(path, None, f"{len(files):,} pose files, more than the "
                                 f"{MAX_POSES:,} read")
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
