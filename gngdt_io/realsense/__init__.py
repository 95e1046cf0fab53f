"""Intel RealSense through ``pyrealsense2`` (the optional extra ``[realsense]``): the SDK's import
(`sdk`), its recordings on disk (`files`: rosbag2 ``.db3``, legacy ROS 1 ``.bag``) and the aligned
RGB-D stream of a device or a recording (`stream`). `gngdt.io.sources.realsense` makes it a frame
source; `gngdt.io.synth.realsense` writes test recordings with the SDK's own recorder.
"""
