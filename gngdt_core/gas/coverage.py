"""How much surface a sensor has seen: the cubic cells, ``cell_m`` wide, that its points fell in
(in the model's frame), for a node budget that grows with the world (`GNGDT`'s
``resolution_m``).

A surface of area A crosses about A / cell_m^2 such cells (more where it is tilted against the
grid, up to sqrt(3) times, or where depth noise thickens it beyond a cell), so ``count`` is the
number of nodes that map it at one node per cell. A cell stays counted once seen. Pure
computation: a hash set of cell keys (`gngdt.core.kernels.coverage`).
"""

from __future__ import annotations

import numpy as np

from gngdt.core.kernels import coverage as CK

#: slots of a new table (a power of two)
INITIAL_SLOTS = 1 << 12
#: points of a batch marked, evenly spaced through it: a 640x480 frame has ~300,000, and a 10 cm
#: cell 3 m away still gets ~50 of 60,000 (marking all would cost ~10 ms a frame instead of ~2)
MAX_MARKED_POINTS = 60_000


class SurfaceCoverage:
    """The set of cells seen; ``count``: how many. ``keys`` (T,) int64 is the hash table."""

    def __init__(self, cell_m: float) -> None:
        if not cell_m > 0:
            raise ValueError(f"cell_m must be positive, got {cell_m!r}")
        self.cell_m = float(cell_m)
        self.keys = np.full(INITIAL_SLOTS, CK.EMPTY, dtype=np.int64)
        self.count = 0

    def add(self, points: np.ndarray, pose: np.ndarray | None = None) -> int:
        """Mark the cells of ``points`` (M, 3) metres (at most ``MAX_MARKED_POINTS`` of them,
        evenly spaced), mapped by ``pose`` (4, 4) into the model's frame (None: they are in it);
        non-finite rows are skipped. Returns the cells newly seen."""
        stride = max(1, -(-len(points) // MAX_MARKED_POINTS))
        # one kernel for every caller: contiguous float32 (a strided or float64 cloud is copied)
        points = np.ascontiguousarray(points[::stride], dtype=np.float32)
        if points.shape[1] == 2:  # 2-D data: squares of the plane
            points = np.column_stack([points, np.zeros(len(points), dtype=np.float32)])
        pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
        rotation = np.ascontiguousarray(pose[:3, :3])
        translation = np.ascontiguousarray(pose[:3, 3])
        before, row = self.count, 0
        while row < len(points):
            self.count, row = CK.mark_cells(points, rotation, translation, 1.0 / self.cell_m,
                                            self.keys, self.count, len(self.keys) // 2, row)
            if row < len(points):
                self._grow()
        return self.count - before

    def _grow(self) -> None:
        keys = np.full(2 * len(self.keys), CK.EMPTY, dtype=np.int64)
        CK.rehash(self.keys, keys)
        self.keys = keys

    def cells(self) -> np.ndarray:
        """(count,) int64 keys of the cells seen, sorted."""
        return np.sort(self.keys[self.keys != CK.EMPTY])

    def centres(self) -> np.ndarray:
        """(count, 3) float64 centres of the cells seen, metres."""
        return CK.cell_centres(self.cells(), self.cell_m)

    def restore(self, cells: np.ndarray) -> None:
        """Set the cells seen to ``cells`` (K,) int64 keys (`cells`); ValueError if they are
        not distinct valid keys."""
        cells = np.asarray(cells)
        if cells.ndim != 1 or cells.dtype.kind not in "iu" or (cells < 0).any():
            raise ValueError("coverage cells must be a 1-D array of non-negative cell keys")
        if np.unique(cells).size != cells.size:
            raise ValueError("coverage cells must be distinct")
        slots = INITIAL_SLOTS
        while slots < 2 * cells.size + 2:
            slots *= 2
        table = np.full(slots, CK.EMPTY, dtype=np.int64)
        CK.rehash(cells.astype(np.int64), table)
        self.keys, self.count = table, int(cells.size)
