"""Camera geometry every layer shares: pinhole intrinsics and rigid transforms.

A rigid transform is a (4, 4) float64 matrix ``[[R, t], [0, 1]]`` mapping points of one frame
into another: ``p_target = R p_source + t`` (metres). Quaternions are (x, y, z, w). As tf2 does,
a quaternion whose squared norm is more than ``QUATERNION_TOLERANCE`` away from 1 is refused (a
sign of a wrong field order, not rounding); one within it is normalised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MAX_FIELD_OF_VIEW_DEG",
    "MIN_FIELD_OF_VIEW_DEG",
    "PRINCIPAL_POINT_MARGIN",
    "QUATERNION_TOLERANCE",
    "CameraIntrinsics",
    "TransformError",
    "apply_pose",
    "checked_translation",
    "matrix_to_pose",
    "pose_to_matrix",
    "quaternion_to_rotation",
    "quaternions_to_rotations",
    "rigid_inverse",
    "rotation_to_quaternion",
    "slerp",
    "unit_quaternion",
]

#: largest | |q|^2 - 1 | accepted (tf2's own bound); anything closer to 1 is normalised
QUATERNION_TOLERANCE = 0.01
#: field of view (degrees, per image axis) a pinhole calibration may claim: a D435's colour
#: camera sees 69 x 42, a wide-angle one ~120; a pinhole model cannot reach 180, and under a
#: degree is a telescope, not a depth camera
MIN_FIELD_OF_VIEW_DEG = 1.0
MAX_FIELD_OF_VIEW_DEG = 170.0
#: how far outside the image the principal point may be, as a fraction of its width/height
#: (a real camera's is near the centre; a cropped image's can be near an edge)
PRINCIPAL_POINT_MARGIN = 0.5


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a colour-registered depth camera (pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    #: plumb_bob coefficients k1, k2, p1, p2, k3 (informational; depth is not undistorted)
    distortion: tuple[float, ...] = ()

    def problem(self, image_size: tuple[int, int] | None = None) -> str:
        """Why this cannot be a pinhole camera's calibration, or "" when it can: sizes positive
        (and equal to ``image_size``, (width, height), when given), every value finite,
        focal lengths giving a field of view within [``MIN_FIELD_OF_VIEW_DEG``,
        ``MAX_FIELD_OF_VIEW_DEG``] per axis, the principal point within
        ``PRINCIPAL_POINT_MARGIN`` of the image. Values read from a file or a message are
        judged here before anything is deprojected with them."""
        if self.width <= 0 or self.height <= 0:
            return f"image size {self.width}x{self.height} is empty"
        if image_size is not None and tuple(image_size) != (self.width, self.height):
            return (f"calibration is for {self.width}x{self.height}, the images are "
                    f"{image_size[0]}x{image_size[1]}")
        values = (self.fx, self.fy, self.cx, self.cy, *self.distortion)
        if not all(math.isfinite(value) for value in values):
            return (f"fx, fy, cx, cy and the distortion must be finite numbers (fx={self.fx}, "
                    f"fy={self.fy}, cx={self.cx}, cy={self.cy})")
        for axis, focal, size in (("x", self.fx, self.width), ("y", self.fy, self.height)):
            if focal <= 0:
                return f"f{axis}={focal:g} must be positive"
            view_deg = math.degrees(2.0 * math.atan(size / (2.0 * focal)))
            if not MIN_FIELD_OF_VIEW_DEG <= view_deg <= MAX_FIELD_OF_VIEW_DEG:
                return (f"f{axis}={focal:g} px over {size} px is a field of view of "
                        f"{view_deg:.3g} degrees; a camera's is {MIN_FIELD_OF_VIEW_DEG:g}-"
                        f"{MAX_FIELD_OF_VIEW_DEG:g}")
        for axis, centre, size in (("x", self.cx, self.width), ("y", self.cy, self.height)):
            margin = PRINCIPAL_POINT_MARGIN * size
            if not -margin <= centre <= size + margin:
                return (f"principal point c{axis}={centre:g} px is far outside the image "
                        f"(0-{size} px)")
        return ""

    def matrix(self) -> np.ndarray:
        """(3, 3) float64 camera matrix K."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )


class TransformError(ValueError):
    """A transform is invalid or cannot be looked up; the message names the frames."""


def unit_quaternion(quaternion: object, what: str) -> np.ndarray:
    """(4,) float64 unit quaternion (x, y, z, w); ``TransformError`` naming ``what`` when it is
    not finite or not within ``QUATERNION_TOLERANCE`` of unit length."""
    q = np.asarray(quaternion, dtype=np.float64).reshape(-1)
    if q.shape != (4,) or not np.isfinite(q).all():
        raise TransformError(f"{what}: rotation must be 4 finite numbers (x, y, z, w), got {q}")
    norm2 = float(q @ q)
    if abs(norm2 - 1.0) > QUATERNION_TOLERANCE:
        raise TransformError(
            f"{what}: rotation quaternion (x, y, z, w) = {np.round(q, 4).tolist()} has norm "
            f"{np.sqrt(norm2):.4f}, not 1 (is the order x, y, z, w?)"
        )
    return q / np.sqrt(norm2)


def checked_translation(translation: object, what: str) -> np.ndarray:
    """(3,) float64 translation; ``TransformError`` naming ``what`` unless 3 finite numbers."""
    t = np.asarray(translation, dtype=np.float64).reshape(-1)
    if t.shape != (3,) or not np.isfinite(t).all():
        raise TransformError(f"{what}: translation must be 3 finite numbers, got {t}")
    return t


# Quaternion arithmetic is written out here rather than taken from scipy.spatial.transform:
# importing scipy.spatial costs ~1 s, which capture and logger would pay at start-up only to
# turn a few quaternions into matrices (tests check these against scipy).
def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """(3, 3) float64 rotation of a unit quaternion (x, y, z, w)."""
    return quaternions_to_rotations(np.asarray(q, dtype=np.float64)[None])[0]


def quaternions_to_rotations(q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) float64 rotations of (N, 4) unit quaternions (x, y, z, w)."""
    x, y, z, w = (q[:, i] for i in range(4))
    return np.stack([
        np.stack([1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)], -1),
        np.stack([2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)], -1),
        np.stack([2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)], -1),
    ], axis=1)


def rotation_to_quaternion(r: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion (x, y, z, w), w >= 0, of a (3, 3) rotation (Shepperd's method: the
    largest of the four candidates' divisors keeps it exact near every rotation)."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0.0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def slerp(q0: np.ndarray, q1: np.ndarray, fraction: float) -> np.ndarray:
    """Spherical-linear interpolation between unit quaternions, along the shorter arc."""
    dot = float(q0 @ q1)
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: linear, renormalised (the arc formula loses precision)
        q = q0 + fraction * (q1 - q0)
        return q / np.linalg.norm(q)
    angle = np.arccos(dot)
    return (np.sin((1.0 - fraction) * angle) * q0 + np.sin(fraction * angle) * q1) / np.sin(angle)


def pose_to_matrix(translation: object, quaternion: object, what: str = "pose") -> np.ndarray:
    """(4, 4) float64 rigid transform from a translation (3,) and a quaternion (x, y, z, w)."""
    t = checked_translation(translation, what)
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_to_rotation(unit_quaternion(quaternion, what))
    matrix[:3, 3] = t
    return matrix


def matrix_to_pose(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation (3,) and unit quaternion (x, y, z, w), w >= 0, of a (4, 4) rigid transform."""
    matrix = np.asarray(matrix, dtype=np.float64)
    return matrix[:3, 3].copy(), rotation_to_quaternion(matrix[:3, :3])


def rigid_inverse(matrix: np.ndarray) -> np.ndarray:
    """(4, 4) float64 inverse of a rigid transform (rotation and translation)."""
    matrix = np.asarray(matrix, dtype=np.float64)
    inverse = np.eye(4)
    rotation_t = matrix[:3, :3].T
    inverse[:3, :3] = rotation_t
    inverse[:3, 3] = -rotation_t @ matrix[:3, 3]
    return inverse


def apply_pose(
    points: np.ndarray, pose: np.ndarray, dtype: np.typing.DTypeLike = np.float64
) -> np.ndarray:
    """(N, 3) ``points`` mapped by the (4, 4) rigid transform ``pose`` (e.g. camera-to-world):
    ``R p + t`` for every row, computed and returned in ``dtype`` (float64 by default; float32
    casts the points and the pose to float32 first, for display)."""
    points = np.asarray(points, dtype=dtype)
    pose = np.asarray(pose)
    return points @ pose[:3, :3].T.astype(dtype, copy=False) + pose[:3, 3].astype(dtype, copy=False)
