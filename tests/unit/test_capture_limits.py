"""Recordings that cost time or memory out of proportion: a jump in the stamps, oversized frames
and chunks, frames that never get a calibration. The capture bounds each and says so."""

from __future__ import annotations

import time


def test_the_replay_clock_keeps_the_recorded_spacing_below_the_cap() -> None:
    import threading

    from gngdt.services.replay_clock import ReplayClock

    clock = ReplayClock(rate=2.0, max_gap_s=0.3)
    stop = threading.Event()
    started = time.monotonic()
    for stamp_s in (0.0, 0.2, 0.4, 100.0, 100.2):  # 0.1 s apart at 2x, one gap of 49.8 s
        clock.wait_for(round(stamp_s * 1e9), stop)
    elapsed = time.monotonic() - started
    assert 0.55 <= elapsed < 5.0  # 0.1 + 0.1 + 0.3 (capped) + 0.1


def test_a_cloud_never_exceeds_what_a_learner_accepts_and_a_message_holds() -> None:
    import numpy as np

    from gngdt.io.frame import CameraIntrinsics, Frame
    from gngdt.schemas.clouds import CLOUD_POINT_STRIDE, MAX_CLOUD_POINTS
    from gngdt.services.capture import CloudOptions, FrameToCloud
    from gngdt.services.plumbing.session import MAX_MESSAGE_BYTES

    assert MAX_CLOUD_POINTS * CLOUD_POINT_STRIDE < MAX_MESSAGE_BYTES
    height, width = 1500, 2000  # 3 million valid pixels
    frame = Frame(0, 1, np.zeros((height, width, 3), np.uint8),
                  np.full((height, width), 1000, np.uint16),
                  CameraIntrinsics(width, height, 1000.0, 1000.0, width / 2, height / 2))
    positions, colors = FrameToCloud(CloudOptions())(frame)
    assert len(positions) == len(colors) == MAX_CLOUD_POINTS
