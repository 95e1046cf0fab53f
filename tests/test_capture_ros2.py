"""A capture process replays a RealSense-style ROS 2 bag whose colour and depth stamps differ."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import pytest
from test_recording_io import make_frames, write_ros_bag

from schemas.packing import decode_stream_end, msg_to_cloud
from services.capture import CloudOptions

FRAMES = 6
DEPTH_SKEW_NS = 3_000_000  # aligned depth stamped 3 ms after colour, as real drivers do


def replay(bag: Path, router_endpoint: str, spawn: Callable, *options: str) -> tuple[list, list]:
    """Run `gngdt capture BAG --fast OPTIONS`; the clouds and end-of-stream messages it sent."""
    from services.zenoh_session import client_config, open_config

    session = open_config(client_config([router_endpoint]))
    clouds: list = []
    ends: list = []
    session.declare_subscriber(
        "gngdt/camera/points", lambda sample: clouds.append(msg_to_cloud(sample.payload.to_bytes()))
    )
    session.declare_subscriber(
        "gngdt/camera/eos", lambda sample: ends.append(decode_stream_end(sample.payload.to_bytes()))
    )
    try:
        capture = spawn("capture", str(bag), "--fast", "--zenoh-connect", router_endpoint, *options)
        assert capture.wait(60) == 0, Path(capture.log_path).read_text()
        deadline = time.monotonic() + 10
        while not ends and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        session.close()
    return clouds, ends


@pytest.mark.timeout(120)
def test_unsynchronised_ros2_bag_is_replayed_frame_by_frame(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    frames = make_frames(FRAMES)
    bag = tmp_path / "realsense.mcap"
    write_ros_bag(bag, frames, color_encoding="rgb8", depth_encoding="16UC1",
                  depth_skew_ns=DEPTH_SKEW_NS)

    clouds, ends = replay(bag, router_endpoint, spawn)

    assert len(ends) == 1 and ends[0].frames_sent == FRAMES
    assert len(clouds) == FRAMES
    in_range = CloudOptions()  # capture's default depth range, metres
    valid_depth = [
        int(((frame.depth >= in_range.min_depth_m * 1000)
             & (frame.depth <= in_range.max_depth_m * 1000)).sum())
        for frame in frames
    ]
    assert [len(positions) for positions, _ in clouds] == valid_depth


@pytest.mark.timeout(120)
def test_a_skew_below_the_bags_pairs_nothing_and_says_so(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    bag = tmp_path / "realsense.mcap"
    write_ros_bag(bag, make_frames(FRAMES), color_encoding="rgb8", depth_encoding="16UC1",
                  depth_skew_ns=DEPTH_SKEW_NS)

    clouds, ends = replay(bag, router_endpoint, spawn, "--max-skew-ms", "1")

    assert clouds == []
    assert len(ends) == 1 and ends[0].frames_sent == 0
