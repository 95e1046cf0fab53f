"""Kernels of the input checks (`gngdt.core.gas.sampling`): whether a batch holds a NaN or inf.
Pure functions over arrays."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def sum_is_finite(array):
    """Whether the sum of every element of ``array`` (N, D) float, any layout, is finite: it is
    when every element is, and a NaN or inf anywhere makes it NaN or inf. One pass over the
    rows in place (a decoded cloud's points are a strided view), no temporary array; only a
    float overflow makes a finite batch fail it."""
    total = 0.0
    for row in range(array.shape[0]):
        for column in range(array.shape[1]):
            total += array[row, column]
    return np.isfinite(total)
