"""Virtual Kinect frames of scenes that move, as the forgetting and rehearsal tests learn them:
160x120 frames deprojected with their labels, the network's size and the learner's forgetting."""

from __future__ import annotations

import numpy as np

from gngdt.io.deproject import Deprojector
from gngdt.io.synth.render import render_scene

#: small but realistic: 160x120 frames, a 300-node budget reached after 15 frames
WIDTH, HEIGHT = 160, 120
STEPS = 10_000
PARAMS = {"max_nodes": 300, "lambda_": 500, "random_state": 0}
#: the learner's forgetting profile (gngdt.services.learner.LEARNER_MODEL_DEFAULTS)
FORGETTING = {"utility_k": 1000.0}


def frames_of(scene: str, count: int, fps: float):
    """(camera-frame points, colours, pose, labels per point, segment names) per frame."""
    from gngdt.eval.recording_eval import deproject_labels

    deproject = Deprojector()
    for frame in render_scene(scene, count, width=WIDTH, height=HEIGHT, fps=fps):
        points, colors = deproject(frame.depth, frame.color, frame.intrinsics)
        labels = deproject_labels(deproject, frame.depth, frame.labels, frame.intrinsics)
        yield points, colors, frame.pose.matrix, labels, frame.extras["segments"]


def to_world(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame ``points`` placed in the world by the (4, 4) camera ``pose``."""
    return points.astype(np.float64) @ pose[:3, :3].T + pose[:3, 3]
