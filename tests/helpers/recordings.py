"""Small recordings of random frames in gngdt's own MCAP layout: 64x48 pixels, known
intrinsics and stamps (what the reader must give back)."""

from __future__ import annotations

import numpy as np

from gngdt.io.frame import CameraIntrinsics, Frame

#: the frames' size (pixels), calibration and stamps (30 Hz)
WIDTH, HEIGHT = 64, 48
START_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333
INTRINSICS = CameraIntrinsics(WIDTH, HEIGHT, 60.0, 61.0, 31.5, 23.5)


def make_frames(count: int, *, labels: bool = False, seed: int = 0) -> list[Frame]:
    """``count`` frames of random colour and depth (and labels), 30 Hz from ``START_NS``."""
    rng = np.random.default_rng(seed)
    return [
        Frame(
            index=index,
            timestamp_ns=START_NS + index * PERIOD_NS,
            color=rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8),
            depth=rng.integers(0, 8000, (HEIGHT, WIDTH), dtype=np.uint16),
            intrinsics=INTRINSICS,
            labels=rng.integers(0, 5, (HEIGHT, WIDTH), dtype=np.uint16) if labels else None,
        )
        for index in range(count)
    ]
