"""Decorators shared by the kernels."""

from __future__ import annotations

from numba import njit

# helpers of the per-step loop: inlined into their callers at the numba IR level
inlined = njit(cache=True, inline="always")
