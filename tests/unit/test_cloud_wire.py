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


def test_the_wire_cloud_of_a_large_frame_holds_no_image_sized_arrays() -> None:
    """A flooded ROS 2 bridge deprojects frame after frame: beyond the cloud's own buffer, the
    point cap's draw (8 bytes a point) and its blocks of random numbers, nothing the size of
    the image is allocated (was: its depths in metres, every kept pixel's index, a random
    number per kept pixel and two ray-slope maps: 59 MB in all here, now 33 MB)."""
    import tracemalloc

    height, width = 1080, 1920
    rng = np.random.default_rng(0)
    depth = rng.integers(500, 4000, (height, width), dtype=np.uint16)
    color = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    camera = CameraIntrinsics(width, height, 1500.0, 1500.0, width / 2, height / 2)
    to_cloud = FrameToCloud(CloudOptions(max_points=1_500_000))
    to_cloud.warm_up()
    tracemalloc.start()
    try:
        wire, count = to_cloud.to_wire(Frame(0, 1, color, depth, camera), timestamp_ns=5,
                                       frame_id="camera", pose=None)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert count == 1_500_000
    assert peak < len(wire) + 8 * count + 16 * 2**20
