"""Capture's clouds deprojected straight into their wire buffer (`FrameToCloud.to_wire`): byte
for byte the cloud `cloud_to_wire` makes of the deprojected points, with the same draws of the
point cap, so `gngdt eval recording` (which deprojects into arrays) learns what capture sends."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.io.deproject import CloudOptions, FrameToCloud
from gngdt.io.frame import CameraIntrinsics, Frame
from gngdt.schemas.clouds import cloud_to_wire


def frame(seed: int) -> Frame:
    rng = np.random.default_rng(seed)
    depth = rng.integers(0, 4000, (48, 64), dtype=np.uint16)
    depth[rng.random(depth.shape) < 0.2] = 0  # holes
    color = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    return Frame(seed, 1, color, depth, CameraIntrinsics(64, 48, 60.0, 61.0, 31.5, 23.5))


@pytest.mark.parametrize("options", [CloudOptions(), CloudOptions(max_points=500),
                                     CloudOptions(min_depth_m=0.5, max_depth_m=3.0,
                                                  veil_ratio=0.05, max_points=700)])
def test_the_wire_cloud_is_the_deprojected_cloud_byte_for_byte(options: CloudOptions) -> None:
    direct, arrays = FrameToCloud(options, seed=3), FrameToCloud(options, seed=3)
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 3.0)
    for seed in range(3):  # consecutive frames: the cap's draws stay in step
        wire, count = direct.to_wire(frame(seed), timestamp_ns=5, frame_id="world", pose=pose)
        positions, colors = arrays(frame(seed))
        assert count == len(positions) > 0
        assert bytes(wire) == bytes(cloud_to_wire(positions, colors, timestamp_ns=5,
                                                  frame_id="world", pose=pose))
