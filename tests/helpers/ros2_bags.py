"""ROS 2 bags (MCAP, CDR) as a RealSense driver records them: sensor_msgs Image and CameraInfo
with their message definitions, written by mcap-ros2's writer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer

from gngdt.io.frame import Frame
from helpers.recordings import HEIGHT, INTRINSICS, WIDTH

#: the message definitions a ROS 2 bag carries (mcap-ros2 parses them to encode)
HEADER_MSGDEF = """
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
IMAGE_MSGDEF = (
    """std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data"""
    + HEADER_MSGDEF
)
CAMERA_INFO_MSGDEF = (
    """std_msgs/Header header
uint32 height
uint32 width
string distortion_model
float64[] d
float64[9] k
float64[9] r
float64[12] p
uint32 binning_x
uint32 binning_y
sensor_msgs/RegionOfInterest roi"""
    + HEADER_MSGDEF
    + """================================================================================
MSG: sensor_msgs/RegionOfInterest
uint32 x_offset
uint32 y_offset
uint32 height
uint32 width
bool do_rectify
"""
)


def ros_header(stamp_ns: int) -> dict:
    """A std_msgs/Header stamped ``stamp_ns``, in the colour camera's optical frame."""
    seconds, nanoseconds = divmod(stamp_ns, 1_000_000_000)
    return {"stamp": {"sec": seconds, "nanosec": nanoseconds}, "frame_id": "camera_color_optical"}


def ros_image(stamp_ns: int, pixels: np.ndarray, encoding: str, big_endian: bool = False) -> dict:
    """A sensor_msgs/Image of ``pixels`` ((H, W) or (H, W, C)) in ``encoding``."""
    height, width = pixels.shape[:2]
    wire = pixels.astype(pixels.dtype.newbyteorder(">" if big_endian else "<"))
    return {
        "header": ros_header(stamp_ns),
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": int(big_endian),
        "step": wire.nbytes // height,
        "data": wire.tobytes(),
    }


def write_ros_bag(
    path: Path,
    frames: list[Frame],
    *,
    color_encoding: str,
    depth_encoding: str,
    depth_skew_ns: int = 0,
    big_endian_depth: bool = False,
    camera_info: bool = True,
) -> None:
    """A RealSense-style bag: colour, aligned depth and (unless not ``camera_info``) camera_info
    with header stamps."""
    with open(path, "wb") as stream:
        writer = Ros2Writer(stream)
        image_schema = writer.register_msgdef("sensor_msgs/msg/Image", IMAGE_MSGDEF)
        info_schema = writer.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO_MSGDEF)
        for frame in frames:
            stamp = frame.timestamp_ns
            color = frame.color[..., ::-1] if color_encoding == "bgr8" else frame.color
            if depth_encoding == "32FC1":
                depth = np.where(frame.depth > 0, frame.depth / 1000.0, np.nan).astype(np.float32)
            else:
                depth = frame.depth
            writer.write_message(
                "/camera/color/image_raw",
                image_schema,
                ros_image(stamp, color, color_encoding),
                log_time=stamp + 10,
            )
            if camera_info:
                k = INTRINSICS.matrix().ravel().tolist()
                writer.write_message(
                    "/camera/color/camera_info",
                    info_schema,
                    {
                        "header": ros_header(stamp),
                        "height": HEIGHT,
                        "width": WIDTH,
                        "distortion_model": "plumb_bob",
                        "d": [0.1, 0.0, 0.0, 0.0, 0.0],
                        "k": k,
                        "r": np.eye(3).ravel().tolist(),
                        "p": [*k[:3], 0, *k[3:6], 0, *k[6:], 0],
                        "binning_x": 0,
                        "binning_y": 0,
                        "roi": {
                            "x_offset": 0,
                            "y_offset": 0,
                            "height": 0,
                            "width": 0,
                            "do_rectify": False,
                        },
                    },
                    log_time=stamp + 20,
                )
            writer.write_message(
                "/camera/aligned_depth_to_color/image_raw",
                image_schema,
                ros_image(stamp + depth_skew_ns, depth, depth_encoding, big_endian_depth),
                log_time=stamp + 30,
            )
        writer.finish()
