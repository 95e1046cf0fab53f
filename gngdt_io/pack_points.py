"""Kept pixels of a depth frame deprojected straight into a PointCloud's packed points (x, y, z
float32 and red, green, blue uint8, 15 bytes a point): one compiled pass instead of deprojecting
into arrays, then copying them field by field into the wire buffer."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def pack_pixels(z, slope_x, slope_y, rgb, valid, out):
    """Point k of ``out`` (uint8, 15 * len(valid)) from pixel ``valid[k]``: ``(slope_x * z,
    slope_y * z, z)`` float32 little-endian, then its colour ``rgb`` (H*W, 3) uint8. z, slope_x,
    slope_y: (H*W,) float32, as `Deprojector` computes them (same float32 products)."""
    word = np.empty(3, dtype=np.float32)
    word_bytes = word.view(np.uint8)
    for k in range(valid.shape[0]):
        i = valid[k]
        depth = z[i]
        word[0] = slope_x[i] * depth
        word[1] = slope_y[i] * depth
        word[2] = depth
        o = 15 * k
        for b in range(12):
            out[o + b] = word_bytes[b]
        out[o + 12] = rgb[i, 0]
        out[o + 13] = rgb[i, 1]
        out[o + 14] = rgb[i, 2]


@njit(cache=True)
def kept_pixels(depth, min_depth, max_depth):
    """`Deprojector._depth_metres` in one pass: (H*W,) float32 depth in metres of the flat
    ``depth`` (millimetres, uint16 or float with NaN) and the flat indices of the pixels within
    [min_depth, max_depth] (compared in float32, as NumPy compares the float32 depths)."""
    z = np.empty(depth.shape[0], dtype=np.float32)
    valid = np.empty(depth.shape[0], dtype=np.int64)
    lo = np.float32(min_depth)
    hi = np.float32(max_depth)
    scale = np.float32(0.001)
    count = 0
    for i in range(depth.shape[0]):
        metres = np.float32(depth[i]) * scale
        z[i] = metres
        if metres >= lo and metres <= hi:  # NaN compares False
            valid[count] = i
            count += 1
    return z, valid[:count]
