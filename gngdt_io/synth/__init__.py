"""The virtual Kinect: analytic scenes (`scenes`) ray-cast into RGB-D frames with sensor-like
depth (`render`)."""
