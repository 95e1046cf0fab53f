"""Camera tracking: each frame's pose found by aligning it to the learned map
(`map_odometry`), as the learner runs it (`camera_tracking`), the map as the tracker reads it
(`map_surface`, `node_planes`), and checks of camera poses (`pose_checks`)."""
