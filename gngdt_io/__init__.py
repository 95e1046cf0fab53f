"""gngdt's I/O library: where frames come from and where results go.

Frames (`frame`), recordings in MCAP (`mcap_reader`, `mcap_writer`; gngdt's own layout and ROS 2
bags; the reader's parts: `mcap_limits`, `mcap_decoding`, `frame_assembly`, `mcap_poses`),
folders of RGB-D images (`images`), pose files (`pose_files`) and the transform tree that
interpolates poses (`tf_tree`), depth deprojection (`deproject`), the virtual Kinect (`synth`),
frame sources behind one interface (`sources`), outputs behind another (`outputs`), checkpoint
files (`checkpoints`) and output folders written all at once (`staged_directory`).

Imports only `gngdt.core` and `schemas` of gngdt's own packages (ARCHITECTURE.md).
"""
