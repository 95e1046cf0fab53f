"""Kernels of the rehearsal memory (`gngdt.core.gas.rehearsal`). Pure functions over arrays."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def drop_marked(positions, colors, drop, n):
    """Drop the rows ``i < n`` of ``positions`` and ``colors`` (cap, 3) each where ``drop[i]``
    is set, in place, the others moved up in their order; returns how many are left."""
    kept = 0
    for i in range(n):
        if drop[i]:
            continue
        if kept != i:
            for a in range(3):
                positions[kept, a] = positions[i, a]
                colors[kept, a] = colors[i, a]
        kept += 1
    return kept
