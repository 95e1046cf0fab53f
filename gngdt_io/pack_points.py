"""Kept pixels of a depth frame deprojected straight into a PointCloud's packed points (x, y, z
float32 and red, green, blue uint8, 15 bytes a point): compiled passes over the depth image
instead of deprojecting into arrays, then copying them field by field into the wire buffer.
Without the GIL: the ROS 2 bridge's zenoh thread takes it to queue the next image meanwhile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def count_kept(depth, min_depth, max_depth):
    """How many pixels of the (H, W) ``depth`` `kept_pixels` keeps (nothing allocated)."""
    lo = np.float32(min_depth)
    hi = np.float32(max_depth)
    scale = np.float32(0.001)
    count = 0
    for row in range(depth.shape[0]):
        for col in range(depth.shape[1]):
            metres = np.float32(depth[row, col]) * scale
            if metres >= lo and metres <= hi:  # NaN compares False
                count += 1
    return count


@njit(cache=True, nogil=True)
def pack_kept(depth, min_depth, max_depth, slope_u, slope_v, rgb, ranks, every, out):
    """The pixels of the (H, W) ``depth`` that `kept_pixels` keeps, each packed into ``out``
    (uint8, 15 bytes a point) as ``(slope_u[col] * z, slope_v[row] * z, z)`` float32
    little-endian, then its colour ``rgb`` (H*W, 3) uint8: ``every`` one, else only the kept
    pixels whose rank among the kept is in ``ranks`` (sorted). The float32 products of
    `Deprojector` (its ray map is ``slope_u`` and ``slope_v`` broadcast), without the (H*W,)
    depths, indices and slopes it holds; returns the points written."""
    lo = np.float32(min_depth)
    hi = np.float32(max_depth)
    scale = np.float32(0.001)
    word = np.empty(3, dtype=np.float32)
    word_bytes = word.view(np.uint8)
    width = depth.shape[1]
    wanted = ranks.shape[0]
    rank = 0  # of the next kept pixel
    k = 0  # points written
    for row in range(depth.shape[0]):
        if not every and k == wanted:
            break
        for col in range(width):
            metres = np.float32(depth[row, col]) * scale
            if not (metres >= lo and metres <= hi):  # NaN compares False
                continue
            if every or (k < wanted and ranks[k] == rank):
                word[0] = slope_u[col] * metres
                word[1] = slope_v[row] * metres
                word[2] = metres
                o = 15 * k
                for b in range(12):
                    out[o + b] = word_bytes[b]
                i = row * width + col
                out[o + 12] = rgb[i, 0]
                out[o + 13] = rgb[i, 1]
                out[o + 14] = rgb[i, 2]
                k += 1
            rank += 1
    return k


@njit(cache=True, nogil=True)
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
