"""A capture process replays a RealSense-style ROS 2 bag whose colour and depth stamps differ."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.recordings import make_frames
from helpers.ros2_bags import write_ros_bag

from gngdt.services.capture import CloudOptions

FRAMES = 6
DEPTH_SKEW_NS = 3_000_000  # aligned depth stamped 3 ms after colour, as real drivers do


def realsense_bag(path: Path) -> Path:
    write_ros_bag(path, make_frames(FRAMES), color_encoding="rgb8", depth_encoding="16UC1",
                  depth_skew_ns=DEPTH_SKEW_NS)
    return path


@pytest.mark.timeout(120)
def test_unsynchronised_ros2_bag_is_replayed_frame_by_frame(
    run_capture: Callable, tmp_path: Path
) -> None:
    output = run_capture(realsense_bag(tmp_path / "realsense.mcap"))

    assert len(output.ends) == 1 and output.ends[0].frames_sent == FRAMES
    in_range = CloudOptions()  # capture's default depth range, metres
    valid_depth = [
        int(((frame.depth >= in_range.min_depth_m * 1000)
             & (frame.depth <= in_range.max_depth_m * 1000)).sum())
        for frame in make_frames(FRAMES)
    ]
    assert [len(positions) for positions, _ in output.clouds] == valid_depth


@pytest.mark.timeout(120)
def test_a_skew_below_the_bags_pairs_nothing_and_says_so(
    run_capture: Callable, tmp_path: Path
) -> None:
    output = run_capture(realsense_bag(tmp_path / "realsense.mcap"), "--max-skew-ms", "1",
                         exit_code=2)  # not a single frame: the capture failed

    assert output.clouds == []
    assert len(output.ends) == 1 and output.ends[0].frames_sent == 0
    assert "realsense.mcap" in output.log
