"""Input validation and the random sampling order shared by the fast learner and the reference."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

# learning steps handed to the kernel per call (bounds the memory of the order array)
MAX_CHUNK_STEPS = 1 << 20


def as_samples(
    positions: object, colors: object | None
) -> tuple[np.ndarray, np.ndarray | None, int]:
    """Validate a batch and drop rows with NaN/inf.

    positions: (N, D) numeric, D in {2, 3}; colors: (N, 3) numeric or None.
    Returns (positions (M, D) float64, colors (M, 3) float64 or None, number of dropped rows).
    """
    pos = _as_float_matrix(positions, "positions")
    if pos.shape[1] not in (2, 3):
        raise ValueError(f"positions must have 2 or 3 columns, got shape {pos.shape}")
    valid = np.isfinite(pos).all(axis=1)
    col = None
    if colors is not None:
        col = _as_float_matrix(colors, "colors")
        if col.shape != (pos.shape[0], 3):
            raise ValueError(
                f"colors must have shape ({pos.shape[0]}, 3) to match positions, got {col.shape}"
            )
        valid &= np.isfinite(col).all(axis=1)
    n_invalid = int(valid.size - np.count_nonzero(valid))
    if n_invalid:
        pos = pos[valid]
        col = col[valid] if col is not None else None
    return np.ascontiguousarray(pos), (np.ascontiguousarray(col) if col is not None else None), (
        n_invalid
    )


def _as_float_matrix(values: object, name: str) -> np.ndarray:
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
    return np.asarray(array, dtype=np.float64)


def initial_indices(rng: np.random.Generator, n_samples: int) -> np.ndarray:
    """Step 0: the two samples that seed the two initial nodes (distinct when possible)."""
    return rng.choice(n_samples, size=2, replace=n_samples < 2)


def sample_orders(rng: np.random.Generator, n_samples: int, n_steps: int) -> Iterator[np.ndarray]:
    """Step 1: sample indices in random order, fresh permutations while steps remain.

    Yields int64 chunks of at most ``MAX_CHUNK_STEPS`` (at least one permutation) steps.
    """
    remaining = n_steps
    perms_per_chunk = max(1, MAX_CHUNK_STEPS // max(n_samples, 1))
    while remaining > 0:
        n_perms = min(perms_per_chunk, -(-remaining // n_samples))
        order = np.concatenate([rng.permutation(n_samples) for _ in range(n_perms)])
        order = order[:remaining]
        remaining -= order.size
        yield order
