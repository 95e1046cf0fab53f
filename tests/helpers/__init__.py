"""The tests' shared helpers, imported as ``from helpers.X import ...`` (pytest puts tests/ on
the path); test modules never import each other, and fixtures stay in conftest.py files.

- ``processes``: logs of started processes, waiting for them, their sockets and children
  (/proc), commands wrapped to measure their peak memory or limit their file sizes.
- ``pipeline``: a test's side of running services on zenoh: the learner's statuses watched;
  clouds, images and ends of stream published; posed clouds and frame stamps.
- ``summaries``: `gngdt run`'s summary read back as numbers.
- ``rrd``: what a rerun recording holds (entities, metric scalars, rows), and what `gngdt run`
  must write.
- ``checkpoints``: a small trained learner checkpoint.
- ``recordings``: small recordings of random frames in gngdt's MCAP layout.
- ``raw_recordings``: MCAP files written message by message, so that they can be wrong.
- ``ros2_bags``: ROS 2 bags (sensor_msgs Image, CameraInfo) as a RealSense driver records them.
- ``synthetic``: the virtual Kinect's small recordings, and rendered frames' ground truth.
- ``forgetting_scenes``: moving scenes' frames and the networks the forgetting tests learn.
- ``segmentation_scenes``: small constructed networks (tables, boxes, walls) to segment.
- ``image_folders``: the real RGB-D samples in ../shared and `gngdt record` run in-process.
- ``realsense``: the bundled RealSense bags; skip (or, in CI, fail) without pyrealsense2.
- ``ros2_sdk``: zenoh-ros2-sdk, the robot side of the ROS 2 tests.
- ``ros2_oracle``: a script run by the real rclpy in its own venv (never imported).
- ``foxglove_client``: a minimal Foxglove WebSocket client.
"""
