"""Input validation (batches, step counts, camera poses) and the random sampling order shared
by the fast learner and the reference."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from gngdt.core.kernels.finite import sum_is_finite

# learning steps handed to the kernel per call (bounds the memory of the order array)
MAX_CHUNK_STEPS = 1 << 20
#: largest deviation of a camera pose's rotation from orthonormal (and of its last row)
POSE_TOLERANCE = 1e-6
#: float types `finite_rows` screens with its kernel (numba has no float16)
_SCREENED = (np.dtype(np.float32), np.dtype(np.float64))


def check_batch(
    positions: object, colors: object | None
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int]:
    """Validate a batch without converting or copying it, and find its NaN/inf rows.

    positions: (N, D) numeric, D in {2, 3}; colors: (N, 3) numeric or None.
    Returns (positions, colors) as numeric arrays of their own dtype, the indices (M,) int64 of
    the finite rows (None when every row is finite) and the number of rows dropped.
    """
    pos = _as_numeric_matrix(positions, "positions")
    if pos.shape[1] not in (2, 3):
        raise ValueError(f"positions must have 2 or 3 columns, got shape {pos.shape}")
    col = None
    if colors is not None:
        col = _as_numeric_matrix(colors, "colors")
        if col.shape != (pos.shape[0], 3):
            raise ValueError(
                f"colors must have shape ({pos.shape[0]}, 3) to match positions, got {col.shape}"
            )
    finite = finite_rows(pos)
    if col is not None:
        finite_colors = finite_rows(col)
        finite = finite_colors if finite is None else (
            finite if finite_colors is None else finite & finite_colors
        )
    if finite is None:
        return pos, col, None, 0
    n_invalid = int(finite.size - np.count_nonzero(finite))
    return pos, col, (np.flatnonzero(finite) if n_invalid else None), n_invalid


def finite_rows(array: np.ndarray) -> np.ndarray | None:
    """(N,) bool mask of the rows of ``array`` (N, D) without NaN/inf, or None when all are.

    Screens the sum of every element first (`gngdt.core.kernels.finite.sum_is_finite`, one pass
    over a strided view, a quarter of the cost of an element-wise test): a NaN or inf anywhere
    makes it non-finite, so a finite sum proves every element finite. Only a float overflow in
    the sum (float64) sends a finite batch to the exact per-row test, as does any float type
    but float32 and float64. Integer arrays are always finite.
    """
    if not np.issubdtype(array.dtype, np.inexact):
        return None
    if array.dtype in _SCREENED and sum_is_finite(array):
        return None
    finite = np.isfinite(array).all(axis=1)
    return None if finite.all() else finite


def gather(
    positions: np.ndarray, colors: np.ndarray | None, rows: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Rows ``rows`` (all when None) of a checked batch as contiguous float64 arrays."""
    def take(array: np.ndarray) -> np.ndarray:
        chosen = array if rows is None else array[rows]
        return np.ascontiguousarray(chosen, dtype=np.float64)

    return take(positions), (take(colors) if colors is not None else None)


def as_samples(
    positions: object, colors: object | None
) -> tuple[np.ndarray, np.ndarray | None, int]:
    """Validate a batch and drop rows with NaN/inf.

    Returns (positions (M, D) float64, colors (M, 3) float64 or None, number of dropped rows).
    """
    pos, col, finite_rows, n_invalid = check_batch(positions, colors)
    pos, col = gather(pos, col, finite_rows)
    return pos, col, n_invalid


def batch_rows(finite_rows: np.ndarray | None, indices: np.ndarray) -> np.ndarray:
    """Batch rows of ``indices`` into the finite rows (all rows are finite when None)."""
    return indices if finite_rows is None else finite_rows[indices]


def check_n_steps(n_steps: object) -> None:
    """ValueError unless ``n_steps`` is None or a non-negative integer (not a bool)."""
    if n_steps is not None:
        if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)):
            raise ValueError(f"n_steps must be an integer or None, got {n_steps!r}")
        if n_steps < 0:
            raise ValueError(f"n_steps must be >= 0, got {n_steps}")


def checked_pose(camera_pose: object, dim: int) -> np.ndarray | None:
    """(4, 4) float64 rigid camera-to-world transform, or None (also for the identity);
    ValueError otherwise. ``dim``: the batch's position columns (a pose needs 3)."""
    if camera_pose is None:
        return None
    pose = np.asarray(camera_pose, dtype=np.float64)
    if dim != 3:
        raise ValueError(f"camera_pose needs 3-D positions, got {dim}-D")
    if pose.shape != (4, 4) or not np.isfinite(pose).all():
        raise ValueError(f"camera_pose must be a finite (4, 4) matrix, got {pose.shape}")
    rotation = pose[:3, :3]
    if (np.abs(rotation @ rotation.T - np.eye(3)).max() > POSE_TOLERANCE
            or np.abs(pose[3] - (0.0, 0.0, 0.0, 1.0)).max() > POSE_TOLERANCE
            or np.linalg.det(rotation) < 0):
        raise ValueError("camera_pose must be rigid: an orthonormal rotation with det +1 and "
                         "a last row of (0, 0, 0, 1)")
    return None if np.array_equal(pose, np.eye(4)) else pose


def to_model_frame(camera_samples: np.ndarray, camera_pose: np.ndarray | None) -> np.ndarray:
    """Samples (M, 3) float64 in the model's frame: the pose applied, when there is one."""
    if camera_pose is None:
        return camera_samples
    return camera_samples @ camera_pose[:3, :3].T + camera_pose[:3, 3]


def _as_numeric_matrix(values: object, name: str) -> np.ndarray:
    try:
        array = np.asarray(values)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not an array: {exc}") from exc
    if array.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array (N, columns), got shape {array.shape}")
    if not (np.issubdtype(array.dtype, np.number) or array.dtype == np.bool_):
        raise ValueError(f"{name} must be numeric, got dtype {array.dtype}")
    if np.iscomplexobj(array):
        raise ValueError(f"{name} must be real, got dtype {array.dtype}")
    return array


def initial_indices(rng: np.random.Generator, n_samples: int) -> np.ndarray:
    """Step 0: the two samples that seed the two initial nodes (distinct when possible)."""
    return rng.choice(n_samples, size=2, replace=n_samples < 2)


def sample_orders(rng: np.random.Generator, n_samples: int, n_steps: int) -> Iterator[np.ndarray]:
    """Step 1: indices of the samples to learn, in random order.

    Up to one pass (``n_steps <= n_samples``): a random subset without replacement, drawn
    without permuting the whole batch (a 300k-point frame learned for 10k steps costs 10k
    draws, not a 300k permutation). Beyond: fresh permutations while steps remain.
    Yields int64 chunks of at most ``MAX_CHUNK_STEPS`` (at least one permutation) steps.
    """
    if n_steps <= n_samples:
        yield rng.choice(n_samples, size=n_steps, replace=False)
        return
    remaining = n_steps
    perms_per_chunk = max(1, MAX_CHUNK_STEPS // max(n_samples, 1))
    while remaining > 0:
        n_perms = min(perms_per_chunk, -(-remaining // n_samples))
        order = np.concatenate([rng.permutation(n_samples) for _ in range(n_perms)])
        order = order[:remaining]
        remaining -= order.size
        yield order
