"""The virtual Kinect: analytic scenes (`scenes`) of solid primitives (`primitives`) seen along
camera paths, with objects that move (`motion`), ray-cast into RGB-D frames with sensor-like
depth (`render`)."""
