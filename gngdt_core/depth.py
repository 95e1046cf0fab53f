"""Depth images: which pixels to trust."""

from __future__ import annotations

import numpy as np


def veil_pixels(depth: np.ndarray, ratio: float) -> np.ndarray:
    """(H, W) bool: pixels whose depth jumps from a 4-neighbour's by more than ``ratio`` of the
    nearer depth — the mixed foreground/background measurements along depth edges ("veil"
    points), which would otherwise bridge an object and what lies behind it.

    depth: (H, W) float or integer depth, any unit; 0 or NaN = no measurement (never a veil).
    """
    from gngdt_core.kernels import segmentation as SK  # numba: loaded when first used

    veil = np.empty(depth.shape, dtype=bool)
    if depth.dtype not in (np.float32, np.float64):
        depth = depth.astype(np.float32)
    SK.veil_pixels(depth, float(ratio), veil)
    return veil
